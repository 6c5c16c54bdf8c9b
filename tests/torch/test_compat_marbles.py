"""smg_torch.compat.marbles_isometry and marbles_global_rigid against plain-torch implementations of
Dynamic Gaussian Marbles' isometry losses written here from a reading of
coltonstearns/dynamic-gaussian-marbles src/models/gaussians.py (commit 1c72f94):

- GaussianModel._compute_adjacent_isometry_helper (lines 574-599): the masked subsets of the
  current and the adjacent frame's means, the cached edges gathered from both (point_idxs then
  knn_idxs), the source lengths detached and their mean taken as a Python float (line 581) before
  the dropout mask keeps the edges of valid points (lines 590-592), |d − s| / A or (d − s)² / A²
  (lines 595-598);
- GaussianModel._compute_global_rigid_loss (lines 773-805): the L1 mean of the differences of the
  template's and the transformed pairs' lengths (lines 797-803), the template detached by its
  caller compute_instance_isometry_loss (line 770).

Values and gradients in float64 and float32, self edges (frnn's table includes the point itself),
dropout, use_l2, a zero-length edge, a pair of one point twice, bad arguments, CUDA (skipped
without a device)."""
import pytest
import torch

import smg_torch as smg
from smg_torch.compat import frnn_knn, marbles_global_rigid, marbles_isometry

cuda = pytest.mark.skipif(not (torch.cuda.is_available() and smg.has_cuda),
                          reason="no CUDA device or smg_torch built without CUDA")


def isometry_torch(xyz, src_xyz, point_idxs, knn_idxs, mask, use_l2, valid_mask=None):
    """The helper as read: xyz and src_xyz [N, 3], mask [N] bool, the edges into xyz[mask]."""
    src_subset = src_xyz[mask].clone()
    all_idxs = torch.cat([point_idxs, knn_idxs])
    src_gathered = torch.gather(src_subset, 0, torch.stack([all_idxs] * 3, dim=-1)).reshape(2, -1, 3)
    src_dists = torch.norm(src_gathered[0] - src_gathered[1], dim=-1).detach().clone()
    avg = src_dists.mean().detach().item()
    subset = xyz[mask].clone()
    gathered = torch.gather(subset, 0, torch.stack([all_idxs] * 3, dim=-1)).reshape(2, -1, 3)
    dists = torch.norm(gathered[0] - gathered[1], dim=-1)
    diffs = dists - src_dists
    if valid_mask is not None:
        diffs = diffs[torch.gather(valid_mask[mask], 0, point_idxs).reshape(-1)]
    return diffs ** 2 / avg ** 2 if use_l2 else torch.abs(diffs) / avg


def global_rigid_torch(xyz, transformed, idx1, idx2):
    orig = torch.norm(xyz.detach()[idx1] - xyz.detach()[idx2], dim=-1)
    new = torch.norm(transformed[idx1] - transformed[idx2], dim=-1)
    return torch.abs(orig - new).mean()


def cache_edges(x, K=24, r=0.3):
    """_cache_isometry_knn's sparse table: frnn's rows without their −1 slots, self included
    (point_idxs = arange(N).repeat_interleave(K)[mask], knn_idxs = idxs[mask])."""
    _, idx = frnn_knn(x, K, r)
    valid = idx[0] != -1
    point_idxs = torch.arange(x.shape[0]).repeat_interleave(K)[valid.flatten()]
    return point_idxs.int(), idx[0][valid].int()


def scene(N=300, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    src = torch.rand(N, 3, generator=g, dtype=torch.float64)
    xyz = src + 0.03 * torch.randn(N, 3, generator=g, dtype=torch.float64)
    mask = torch.rand(N, generator=g) < 0.7
    p, k = cache_edges(src[mask], K=12, r=0.25)
    return xyz.to(dtype), src.to(dtype), p, k, mask


def rel(a, b):
    return float((a.double() - b.double()).abs().max() / b.double().abs().max().clamp_min(1e-300))


def run_both(xyz, src, p, k, mask, use_l2, valid=None, dtype_ref=torch.float64):
    a = xyz.detach().clone().requires_grad_()
    b = xyz.detach().to(dtype_ref).clone().requires_grad_()
    ea = marbles_isometry(a, src, p, k, mask, use_l2=use_l2, valid_mask=valid)
    eb = isometry_torch(b, src.to(dtype_ref), p.long(), k.long(), mask, use_l2, valid)
    g = torch.linspace(0.5, 1.5, ea.shape[0], dtype=torch.float64)
    (ea * g.to(ea.dtype)).sum().backward()
    (eb * g.to(eb.dtype)).sum().backward()
    return ea, a.grad, eb, b.grad


@pytest.mark.parametrize("use_l2", [False, True])
@pytest.mark.parametrize("dropout", [False, True])
def test_isometry_float64(use_l2, dropout):
    xyz, src, p, k, mask = scene(seed=1)
    valid = (torch.rand(xyz.shape[0], generator=torch.Generator().manual_seed(9)) < 0.6) if dropout else None
    ea, ga, eb, gb = run_both(xyz, src, p, k, mask, use_l2, valid)
    assert ea.shape == eb.shape and ea.shape[0] > 100
    assert (p == k).any()  # self edges are in the table
    assert rel(ea, eb) <= 1e-12
    assert rel(ga, gb) <= 1e-12
    assert bool((ga[~mask] == 0).all())  # rows outside the mask get nothing


def test_isometry_float32_bitwise_values_and_close_gradients():
    xyz, src, p, k, mask = scene(seed=2, dtype=torch.float32)
    ea, ga, eb, gb = run_both(xyz, src, p, k, mask, False, dtype_ref=torch.float32)
    assert ea.dtype == torch.float32
    assert torch.equal(ea, eb)  # the same float32 expressions as upstream
    assert rel(ga, gb) <= 1e-6
    e64, _, _, _ = run_both(xyz, src, p, k, mask, False)
    assert rel(ea, e64) <= 1e-4


def test_isometry_zero_length_edge_and_self_edges_have_no_gradient():
    xyz, src, p, k, mask = scene(N=80, seed=3)
    rows = mask.nonzero().flatten()
    xyz[rows[4]] = xyz[rows[7]]  # coincident now: edge (4, 7) and (7, 4) have length 0 at xyz
    p = torch.cat([p, torch.tensor([4, 7, 5], dtype=p.dtype)])
    k = torch.cat([k, torch.tensor([7, 4, 5], dtype=k.dtype)])
    ea, ga, eb, gb = run_both(xyz, src, p, k, mask, False)
    assert rel(ea, eb) <= 1e-12 and rel(ga, gb) <= 1e-12
    assert torch.isfinite(ga).all()


def test_isometry_gradcheck():
    xyz, src, p, k, mask = scene(N=40, seed=4)
    x = xyz.detach().clone().requires_grad_()
    assert torch.autograd.gradcheck(lambda v: marbles_isometry(v, src, p, k, mask, use_l2=True), (x,), eps=1e-6,
                                    atol=1e-8, rtol=1e-6)


def test_isometry_no_edges_and_refusals():
    xyz, src, p, k, mask = scene(N=50, seed=5)
    x = xyz.clone().requires_grad_()
    e = marbles_isometry(x, src, p[:0], k[:0], mask)
    assert e.shape == (0,)
    e.sum().backward()
    assert bool((x.grad == 0).all())
    M = int(mask.sum())
    with pytest.raises(ValueError, match=rf"knn_idxs\[0\] = {M} is not a row of xyz\[mask\]"):
        marbles_isometry(xyz, src, p, torch.full_like(k, M), mask)
    with pytest.raises(ValueError, match=r"knn_idxs: expected shape \["):
        marbles_isometry(xyz, src, p, k[1:], mask)
    with pytest.raises(ValueError, match=r"mask: expected a bool tensor"):
        marbles_isometry(xyz, src, p, k, mask.int())
    bad = src.clone()
    bad[3, 1] = float("nan")
    with pytest.raises(ValueError, match=r"src_xyz\[3\] has a NaN"):
        marbles_isometry(xyz, bad, p, k, mask)
    with pytest.raises(ValueError, match=r"every cached edge has length 0"):
        marbles_isometry(xyz, src, p[p == k], k[p == k], mask)
    with pytest.raises(ValueError, match=r"src_xyz: dtype torch.float32 differs"):
        marbles_isometry(xyz, src.float(), p, k, mask)


def test_global_rigid_float64_float32_and_gradcheck():
    g = torch.Generator().manual_seed(6)
    N = 500
    xyz = torch.rand(N, 3, generator=g, dtype=torch.float64)
    t = xyz @ torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))[0] + 0.02 * torch.randn(
        N, 3, generator=g, dtype=torch.float64)
    i1, i2 = torch.randperm(N, generator=g)[:300], torch.randperm(N, generator=g)[:300]
    i2[:3] = i1[:3]  # a pair of one point twice: length 0 in both
    for dtype, tol in ((torch.float64, 1e-13), (torch.float32, 1e-6)):
        a = t.to(dtype).clone().requires_grad_()
        b = t.to(dtype).clone().requires_grad_()
        la = marbles_global_rigid(xyz.to(dtype), a, i1, i2.int())
        lb = global_rigid_torch(xyz.to(dtype), b, i1, i2)
        (2.5 * la).backward()
        (2.5 * lb).backward()
        assert la.dtype == dtype and abs(float(la) - float(lb)) <= tol * float(lb)
        assert rel(a.grad, b.grad) <= tol
    x = t[:40].clone().requires_grad_()
    assert torch.autograd.gradcheck(lambda v: marbles_global_rigid(xyz[:40], v, i1[i1 < 40], i1[i1 < 40].flip(0)),
                                    (x,), eps=1e-6, atol=1e-8, rtol=1e-6)


def test_global_rigid_holds_the_template_constant_and_refuses():
    xyz = torch.rand(20, 3, dtype=torch.float64, requires_grad=True)
    t = torch.rand(20, 3, dtype=torch.float64, requires_grad=True)
    i = torch.arange(10)
    marbles_global_rigid(xyz, t, i, i + 10).backward()
    assert xyz.grad is None and t.grad is not None
    with pytest.raises(ValueError, match=r"idx1: no pairs"):
        marbles_global_rigid(xyz, t, i[:0], i[:0])
    with pytest.raises(ValueError, match=r"idx2\[0\] = 20 is not a row of transformed_xyz"):
        marbles_global_rigid(xyz, t, i, i + 20)
    with pytest.raises(ValueError, match=r"xyz: expected shape \[20, 3\]"):
        marbles_global_rigid(xyz[:5], t, i, i)


@cuda
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_marbles_cuda(dtype):
    xyz, src, p, k, mask = scene(seed=7, dtype=dtype)
    cpu = marbles_isometry(xyz, src, p, k, mask)
    gpu = marbles_isometry(xyz.cuda(), src.cuda(), p.cuda(), k.cuda(), mask.cuda())
    assert rel(gpu.cpu(), cpu) <= (1e-5 if dtype == torch.float32 else 1e-12)
    i = torch.arange(xyz.shape[0])
    assert float(marbles_global_rigid(src.cuda(), xyz.cuda(), i.cuda(), i.flip(0).cuda())) == pytest.approx(
        float(marbles_global_rigid(src, xyz, i, i.flip(0))), rel=1e-5)
