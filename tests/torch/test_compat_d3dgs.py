"""smg_torch.compat.d3dgs_losses against a plain-torch implementation of Dynamic 3D Gaussians'
rigidity, rotation and isometry losses written here from a reading of
JonathonLuiten/Dynamic3DGaussians (train.py get_loss, the block for timesteps after the first;
initialize_per_timestep, which stores prev_inv_rot_fg = the conjugate of the normalised
rotations and prev_offset from the previous means; initialize_post_first_timestep:
neighbor_weight = exp(−2000 d²), neighbor_dist = d; helpers.py weighted_l2_loss_v1/_v2,
quat_mult; external.py build_rotation, which normalises). Values and gradients in float64 and
float32, the gradient of the optimised unnorm_rotations through F.normalize, a still timestep,
zero weights, bad arguments and CUDA (skipped without a device). docs/compat.md quotes the
figures."""
import pytest
import torch
import torch.nn.functional as F

import smg_torch as smg
from smg_torch.compat import d3dgs_losses

cuda = pytest.mark.skipif(not (torch.cuda.is_available() and smg.has_cuda),
                          reason="no CUDA device or smg_torch built without CUDA")


# ---- the upstream expressions, in plain torch ----

def quat_mult(a, b):
    """Hamilton product of w x y z quaternions (helpers.py quat_mult)."""
    w1, x1, y1, z1 = a.unbind(-1)
    w2, x2, y2, z2 = b.unbind(-1)
    return torch.stack((w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2), -1)


def build_rotation(q):
    """external.py build_rotation: q normalised, then the rotation matrix [N, 3, 3]."""
    q = q / torch.sqrt((q * q).sum(-1))[:, None]
    r, x, y, z = q.unbind(-1)
    return torch.stack((torch.stack((1 - 2 * (y * y + z * z), 2 * (x * y - r * z), 2 * (x * z + r * y)), -1),
                        torch.stack((2 * (x * y + r * z), 1 - 2 * (x * x + z * z), 2 * (y * z - r * x)), -1),
                        torch.stack((2 * (x * z - r * y), 2 * (y * z + r * x), 1 - 2 * (x * x + y * y)), -1)), -2)


def l2_v1(x, y, w):
    return torch.sqrt(((x - y) ** 2) * w + 1e-20).mean()


def l2_v2(x, y, w):
    return torch.sqrt(((x - y) ** 2).sum(-1) * w + 1e-20).mean()


def d3dgs_torch(fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0):
    """(rigid, rot, iso) as get_loss computes them for t >= 1."""
    prev_inv = prev_rot.clone()
    prev_inv[:, 1:] = -1 * prev_inv[:, 1:]
    prev_offset = prev_pts[idx] - prev_pts[:, None]
    rel_rot = quat_mult(fg_rot, prev_inv)
    rot = build_rotation(rel_rot)
    curr_offset = fg_pts[idx] - fg_pts[:, None]
    in_prev = (rot.transpose(2, 1)[:, None] @ curr_offset[:, :, :, None]).squeeze(-1)
    rigid = l2_v2(in_prev, prev_offset, w)
    rot_loss = l2_v2(rel_rot[idx], rel_rot[:, None], w)
    mag = torch.sqrt((curr_offset ** 2).sum(-1) + 1e-20)
    iso = l2_v1(mag, d0, w)
    return rigid, rot_loss, iso


def knn(points, K):
    """The K nearest other points (o3d_knn: K + 1 results, the point itself dropped): (d², index)."""
    d2 = torch.cdist(points, points, compute_mode="donot_use_mm_for_euclid_dist") ** 2
    dist, idx = d2.topk(K + 1, dim=1, largest=False)
    return dist[:, 1:], idx[:, 1:]


def scene(N=300, K=20, seed=0, dtype=torch.float64, motion=0.02):
    """A first-timestep cloud (its KNN, weights and distances as initialize_post_first_timestep
    makes them), a previous timestep and the current one, each a small motion of the last."""
    g = torch.Generator().manual_seed(seed)
    init = torch.rand(N, 3, generator=g, dtype=torch.float64) * 0.3
    d2, idx = knn(init, K)
    w = torch.exp(-2000 * d2)
    d0 = torch.sqrt(d2)
    q0 = F.normalize(torch.randn(N, 4, generator=g, dtype=torch.float64), dim=-1)
    prev_pts = init + motion * torch.randn(N, 3, generator=g, dtype=torch.float64)
    prev_rot = F.normalize(q0 + 0.1 * torch.randn(N, 4, generator=g, dtype=torch.float64), dim=-1)
    unnorm = prev_rot + 0.1 * torch.randn(N, 4, generator=g, dtype=torch.float64)
    fg_pts = prev_pts + motion * torch.randn(N, 3, generator=g, dtype=torch.float64)
    cast = lambda t: t.to(dtype)  # noqa: E731
    return (cast(fg_pts), cast(unnorm), cast(prev_pts), cast(prev_rot), idx, cast(w), cast(d0))


def _grads(fn, fg_pts, fg_rot, *rest, weights=(4.0, 4.0, 2.0)):
    """Losses and the gradients of D3DGS's weighted sum (rigid 4, rot 4, iso 2) w.r.t. fg_pts, fg_rot."""
    x, r = fg_pts.clone().requires_grad_(), fg_rot.clone().requires_grad_()
    losses = fn(x, r, *rest)
    sum(wt * l for wt, l in zip(weights, losses)).backward()
    return [float(v) for v in losses], x.grad, r.grad


def _rel(a, b):
    """Largest difference over the largest reference entry (the difference itself where the
    reference is all 0: a loss that does not reach that argument)."""
    m, d = float(b.abs().max()), float((a - b).abs().max())
    return d / m if m > 0 else d


def tangent(g, q):
    """The part of a gradient g [N, 4] at unit quaternions q orthogonal to q (the rotation's)."""
    return g - (g * q).sum(-1, keepdim=True) * q


# ---- tests ----

@pytest.mark.parametrize("seed", [0, 1])
def test_d3dgs_float64(seed):
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = scene(seed=seed)
    fg_rot = F.normalize(unnorm, dim=-1)
    e_s, gx_s, gq_s = _grads(d3dgs_losses, fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0)
    e_t, gx_t, gq_t = _grads(d3dgs_torch, fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0)
    for a, b in zip(e_s, e_t):
        assert b > 0 and abs(a - b) <= 1e-12 * b
    assert _rel(gx_s, gx_t) < 1e-10
    # fg_rot: the rotation's gradient (D3DGS's raw 4-vector rot loss also has a radial part).
    assert _rel(gq_s, tangent(gq_t, fg_rot)) < 1e-10
    assert float((gq_s * fg_rot).sum(-1).abs().max()) < 1e-12 * float(gq_s.abs().max())


def test_d3dgs_gradient_of_unnorm_rotations_equals_upstream():
    """Through F.normalize (what D3DGS optimises: params['unnorm_rotations']) both give the same."""
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = scene(seed=2)
    grads = []
    for fn in (d3dgs_losses, d3dgs_torch):
        u = unnorm.clone().requires_grad_()
        x = fg_pts.clone().requires_grad_()
        rigid, rot, iso = fn(x, F.normalize(u, dim=-1), prev_pts, prev_rot, idx, w, d0)
        (4 * rigid + 4 * rot + 2 * iso).backward()
        grads.append((x.grad, u.grad))
    assert _rel(grads[0][0], grads[1][0]) < 1e-10
    assert _rel(grads[0][1], grads[1][1]) < 1e-10


@pytest.mark.parametrize("weights", [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (-2.0, 3.0, 0.5)])
def test_d3dgs_each_loss_differentiable_alone(weights):
    """Each loss has its own gradient (a negative weight too: two backward passes)."""
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = scene(N=120, seed=3)
    fg_rot = F.normalize(unnorm, dim=-1)
    _, gx_s, gq_s = _grads(d3dgs_losses, fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0, weights=weights)
    _, gx_t, gq_t = _grads(d3dgs_torch, fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0, weights=weights)
    assert _rel(gx_s, gx_t) < 1e-10
    assert _rel(gq_s, tangent(gq_t, fg_rot)) < 1e-10


def test_d3dgs_gradcheck():
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = scene(N=30, K=6, seed=4, motion=0.05)
    fg_rot = F.normalize(unnorm, dim=-1)
    x, r = fg_pts.clone().requires_grad_(), fg_rot.clone().requires_grad_()
    # weights of order 1 (the scene's exp(−2000 d²) are tiny at this density)
    w1 = torch.rand(w.shape, generator=torch.Generator().manual_seed(5), dtype=torch.float64) + 0.1
    assert torch.autograd.gradcheck(lambda a, b: d3dgs_losses(a, b, prev_pts, prev_rot, idx, w1, d0), (x, r),
                                    eps=1e-6, atol=1e-7, rtol=1e-6)


def test_d3dgs_passes_side_by_side_equal_in_turn():
    """With 2 intra-op threads rigid's and rot's passes run side by side (compat._side_by_side);
    with 1 in turn: the losses and gradients are the same bits, float32 and float64."""
    before = torch.get_num_threads()
    try:
        for dtype in (torch.float32, torch.float64):
            fg_pts, unnorm, *rest = scene(N=500, seed=3, dtype=dtype)
            inputs = (fg_pts, F.normalize(unnorm, dim=-1), *rest)
            out = {}
            for threads in (1, 2):
                torch.set_num_threads(threads)
                out[threads] = _grads(d3dgs_losses, *inputs)
            assert smg.compat._SIDE_POOL is not None  # the two-thread run took the side-by-side path
            assert out[1][0] == out[2][0]
            assert torch.equal(out[1][1], out[2][1]) and torch.equal(out[1][2], out[2][2])
    finally:
        torch.set_num_threads(before)


def test_d3dgs_float32():
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = scene(seed=6)
    fg_rot = F.normalize(unnorm, dim=-1)
    e64, gx64, gq64 = _grads(d3dgs_torch, fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0)
    f32 = [t.float() if t.is_floating_point() else t for t in (fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0)]
    e32, gx32, gq32 = _grads(d3dgs_losses, *f32)
    for a, b in zip(e32, e64):
        assert abs(a - b) <= 1e-5 * b
    assert _rel(gx32.double(), gx64) < 1e-4
    assert _rel(gq32.double(), tangent(gq64, fg_rot)) < 1e-4


def test_d3dgs_still_timestep_and_zero_weights():
    """No motion since the previous timestep: rigid and rot are sqrt(1e-20) per term; smg's
    gradient is exactly 0 (both frames' offsets are rotated by the same R), torch's is rounding
    (its relative rotation f ⊗ f* renormalised is I only to the last bit); zero-weight neighbours
    add sqrt(1e-20) and no gradient in all three."""
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = scene(N=100, seed=7)
    w = w.clone()
    w[:, ::3] = 0.0
    e_s, gx_s, gq_s = _grads(d3dgs_losses, prev_pts, prev_rot, prev_pts, prev_rot, idx, w, d0, weights=(1.0, 0.0, 0.0))
    e_t, gx_t, _ = _grads(d3dgs_torch, prev_pts, prev_rot, prev_pts, prev_rot, idx, w, d0, weights=(1.0, 0.0, 0.0))
    assert e_s[0] == pytest.approx(1e-10, rel=1e-12) and e_t[0] == pytest.approx(1e-10, rel=1e-12)
    assert float(gx_t.abs().max()) < 1e-10
    assert float(gx_s.abs().max()) == 0.0 and float(gq_s.abs().max()) == 0.0
    assert e_s[1] == pytest.approx(1e-10, rel=1e-6)
    # moving, with every weight 0: each loss is exactly sqrt(1e-20), no gradient
    fg_rot = F.normalize(unnorm, dim=-1)
    e_s, gx_s, gq_s = _grads(d3dgs_losses, fg_pts, fg_rot, prev_pts, prev_rot, idx, torch.zeros_like(w), d0)
    assert e_s == pytest.approx([1e-10] * 3, rel=1e-12)
    assert float(gx_s.abs().max()) == 0.0 and float(gq_s.abs().max()) == 0.0


@pytest.mark.parametrize("change, match", [
    (lambda a: a.__setitem__(0, a[0][:, :2]), "fg_pts: expected shape"),
    (lambda a: a.__setitem__(1, a[1][:-1]), "fg_rot: expected shape"),
    (lambda a: a.__setitem__(3, a[3].float()), "prev_rot: dtype"),
    (lambda a: a.__setitem__(4, a[4][:, :0]), "neighbor_indices: expected shape"),
    (lambda a: a.__setitem__(4, a[4].double()), "neighbor_indices: dtype"),
    (lambda a: a.__setitem__(4, a[4].clone().fill_(-1)), r"neighbor_indices\[0, 0\] = -1 is not a node"),
    (lambda a: a.__setitem__(5, a[5][:, :3]), "neighbor_weight: expected shape"),
    (lambda a: a.__setitem__(6, a[6].float()), "neighbor_dist: dtype"),
    (lambda a: a.__setitem__(2, "x"), "prev_pts: expected a torch.Tensor"),
])
def test_d3dgs_refuses_bad_arguments(change, match):
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = scene(N=40, K=5, seed=8)
    args = [fg_pts, F.normalize(unnorm, dim=-1), prev_pts, prev_rot, idx, w, d0]
    change(args)
    with pytest.raises(ValueError, match=match):
        d3dgs_losses(*args)


@cuda
@pytest.mark.parametrize("dtype, tol_e, tol_g", [(torch.float64, 1e-12, 1e-10), (torch.float32, 1e-5, 1e-4)])
def test_d3dgs_cuda(dtype, tol_e, tol_g):
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = scene(N=500, seed=9)
    fg_rot = F.normalize(unnorm, dim=-1)
    cpu = [t.to(dtype) if t.is_floating_point() else t for t in (fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0)]
    e_c, gx_c, gq_c = _grads(d3dgs_losses, *cpu)
    e_g, gx_g, gq_g = _grads(d3dgs_losses, *[t.cuda() for t in cpu])
    assert gx_g.device.type == "cuda"
    for a, b in zip(e_g, e_c):
        assert abs(a - b) <= tol_e * b
    assert _rel(gx_g.cpu().double(), gx_c.double()) < tol_g
    assert _rel(gq_g.cpu().double(), gq_c.double()) < tol_g
