# smg_torch.knn_points (docs/math/graph.md (G15)) and the compat tables built on it
# (smg_torch.compat.open3d_knn, ckdtree_knn, frnn_knn): exact rows against a brute-force sort of
# every pair written here, ties and exact duplicates by index, radius / self / padding, the
# squared distances' gradient against torch.autograd, thread counts, bad arguments; the compat
# tables against the tools themselves where Debian has them (Open3D, scipy: skipped otherwise) and
# against plain-torch readings of frnn (its CPU code: frnn/csrc/grid/find_nbrs_cpu.cpp keeps
# sqdist <= r2 and pads dists and idxs with -1); CUDA against the CPU when a device is present.
import math

import pytest
import torch

import smg_torch
from smg_torch import compat


def brute(p, K, radius=None, include_self=True):
    """Every pair's d² (x, y, z summed in this order), rows sorted by (d², j) with a stable sort,
    the first K within radius² kept, -1 / inf padding."""
    N = p.shape[0]
    diff = p[None, :, :] - p[:, None, :]  # [i, j] = p_j − p_i
    d2 = diff[..., 0] * diff[..., 0] + diff[..., 1] * diff[..., 1] + diff[..., 2] * diff[..., 2]
    if radius is not None:
        r = torch.tensor(radius, dtype=p.dtype)
        d2 = torch.where(d2 <= r * r, d2, torch.full_like(d2, math.inf))
    if not include_self:
        d2.fill_diagonal_(math.inf)
    s, j = torch.sort(d2, dim=1, stable=True)
    s, j = s[:, :K], j[:, :K]
    if K > N:
        s = torch.cat([s, s.new_full((N, K - N), math.inf)], 1)
        j = torch.cat([j, j.new_full((N, K - N), -1)], 1)
    j = torch.where(torch.isinf(s), torch.full_like(j, -1), j)
    return s, j


def lattice(copies=3, side=5, dtype=torch.float64):
    g = torch.stack(torch.meshgrid(*[torch.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    return g.repeat(copies, 1).to(dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("K,radius,self_", [(1, None, True), (8, None, False), (20, 0.2, True), (12, 0.2, False)])
def test_rows_equal_a_sort_of_every_pair(dtype, K, radius, self_):
    p = (torch.rand(700, 3, dtype=torch.float64) * 2 - 1).to(dtype)
    d2, idx = smg_torch.knn_points(p, K, radius=radius, include_self=self_)
    rd2, ridx = brute(p, K, radius, self_)
    assert d2.dtype == dtype and idx.dtype == torch.int64 and d2.shape == (700, K)
    assert torch.equal(idx, ridx)
    assert torch.equal(d2, rd2)


@pytest.mark.parametrize("K", [3, 7, 30])
def test_ties_and_duplicates_by_index(K):
    p = lattice()  # 125 points, three copies each
    for radius in (None, 1.0, 0.0):
        d2, idx = smg_torch.knn_points(p, K, radius=radius)
        rd2, ridx = brute(p, K, radius)
        assert torch.equal(idx, ridx) and torch.equal(d2, rd2)
    d2, idx = smg_torch.knn_points(p, 3)
    base = torch.arange(375) % 125
    assert torch.equal(idx, torch.stack([base, base + 125, base + 250], 1))  # the copies, lower index first
    assert torch.equal(d2, torch.zeros_like(d2))


def test_radius_self_and_padding():
    p = torch.tensor([[0., 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 4]])
    d2, idx = smg_torch.knn_points(p, 6, radius=2.0)
    assert idx[0].tolist() == [0, 1, 2, -1, -1, -1]
    assert d2[0].tolist() == [0, 1, 4] + [math.inf] * 3  # d² = r² is kept (frnn's <=)
    d2, idx = smg_torch.knn_points(p, 2, include_self=False)
    assert idx[3].tolist() == [0, 1] and d2[3].tolist() == [16, 17]
    d2, idx = smg_torch.knn_points(p[:1], 2, include_self=False)
    assert idx.tolist() == [[-1, -1]] and d2.tolist() == [[math.inf, math.inf]]
    d2, idx = smg_torch.knn_points(p[:0], 4)
    assert d2.shape == (0, 4) and idx.shape == (0, 4)


def test_threads_give_the_same_rows():
    p = torch.rand(6000, 3, dtype=torch.float32)
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        one = smg_torch.knn_points(p, 10)
        torch.set_num_threads(2)
        two = smg_torch.knn_points(p, 10)
    finally:
        torch.set_num_threads(before)
    assert torch.equal(one[0], two[0]) and torch.equal(one[1], two[1])


def test_squared_distances_gradient():
    p = torch.rand(60, 3, requires_grad=True)
    d2, idx = smg_torch.knn_points(p, 5, radius=0.4)
    w = torch.rand_like(d2)
    (torch.where(idx >= 0, d2, d2.new_zeros(())) * w).sum().backward()
    # torch.autograd through the gathered differences of the same neighbours.
    q = p.detach().clone().requires_grad_(True)
    valid = idx >= 0
    diff = q[:, None, :] - q[idx.clamp(min=0)]
    ref = torch.where(valid, (diff * diff).sum(-1), diff.new_zeros(()))
    (ref * w).sum().backward()
    assert torch.allclose(p.grad, q.grad, rtol=1e-12, atol=1e-14)
    # Central differences (torch.autograd.gradcheck, double): no neighbour changes within eps here.
    x = torch.rand(30, 3, requires_grad=True)
    v = torch.rand(30, 4)
    assert torch.autograd.gradcheck(lambda y: (smg_torch.knn_points(y, 4, include_self=False)[0] * v).sum(), (x,),
                                    eps=1e-6, atol=1e-9, rtol=1e-7)


@pytest.mark.parametrize("bad,match", [
    (lambda p: smg_torch.knn_points(p.masked_fill(torch.arange(30).view(10, 3) == 7, math.nan), 2),
     r"points\[2, 1\] is nan"),
    (lambda p: smg_torch.knn_points(p[:, :2], 2), r"points: .*\[N, 3\]"),
    (lambda p: smg_torch.knn_points(p, 0), r"K: must be an integer in \[1"),
    (lambda p: smg_torch.knn_points(p, 2, radius=-1.0), r"radius: must be >= 0"),
    (lambda p: smg_torch.knn_points(p.to(torch.int32), 2), r"points: dtype must be float32 or float64"),
])
def test_bad_arguments(bad, match):
    with pytest.raises(ValueError, match=match):
        bad(torch.rand(10, 3))


# ---- compat tables ----

def test_open3d_knn_against_open3d():
    o3d = pytest.importorskip("open3d")
    import numpy as np
    pts = np.random.default_rng(3).random((500, 3)).astype(np.float32)  # D3DGS passes float32 point clouds
    sq, ind = compat.open3d_knn(pts, 20)
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.ascontiguousarray(pts, np.float64))
    tree = o3d.geometry.KDTreeFlann(pcd)
    ref_i, ref_d = [], []
    for q in pcd.points:  # D3DGS helpers.py o3d_knn, as read
        _, i, d = tree.search_knn_vector_3d(q, 21)
        ref_i.append(i[1:])
        ref_d.append(d[1:])
    ref_i, ref_d = np.array(ref_i), np.array(ref_d)
    assert sq.dtype == ref_d.dtype and ind.dtype == ref_i.dtype
    assert (ind == ref_i).all()
    assert np.allclose(sq, ref_d, rtol=1e-15, atol=0)


def test_ckdtree_knn_against_scipy():
    spatial = pytest.importorskip("scipy.spatial")
    import numpy as np
    data = np.random.default_rng(4).random((800, 3)).astype(np.float32)  # DreamScene4D's means, float32
    tree = spatial.cKDTree(data, leafsize=100)
    for k, bound in ((16, math.inf), (16, 0.08), (1, math.inf), (5, 0.05)):
        d, i = compat.ckdtree_knn(data, k, distance_upper_bound=bound)
        rd, ri = tree.query(data, k=k, distance_upper_bound=bound)
        assert d.shape == rd.shape and i.dtype == ri.dtype
        assert (i == ri).all()
        assert np.allclose(d, rd, rtol=1e-15, atol=0) and (np.isinf(d) == np.isinf(rd)).all()
    # The bound is strict, as cKDTree's: a neighbour exactly at it is left out.
    p = np.array([[0., 0, 0], [2, 0, 0]])
    d, i = compat.ckdtree_knn(p, 2, distance_upper_bound=2.0)
    assert i.tolist() == [[0, 2], [1, 2]] and math.isinf(d[0, 1])


def frnn_reading(p, K, r, seg=None):
    """frnn_grid_points(points[None], points[None], K=K, r=r) as its CPU code reads
    (find_nbrs_cpu.cpp: sqdist <= r2, r2 = r * r in float; the K smallest, sorted; idxs and
    dists -1 padded); with seg, Marbles' fourth coordinate seg * 2r appended first."""
    q = p if seg is None else torch.cat([p, (seg.to(p.dtype) * (2 * r))[:, None]], 1)
    diff = q[None] - q[:, None]
    d2 = (diff * diff).sum(-1)
    rr = torch.tensor(r, dtype=p.dtype) ** 2
    d2 = torch.where(d2 <= rr, d2, torch.full_like(d2, math.inf))
    s, j = torch.sort(d2, dim=1, stable=True)
    s, j = s[:, :K], j[:, :K]
    off = torch.isinf(s)
    return torch.where(off, -torch.ones_like(s), s)[None], torch.where(off, -torch.ones_like(j), j)[None]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_frnn_knn_against_the_reading(dtype):
    p = torch.rand(600, 3, dtype=torch.float64).to(dtype)
    d, i = compat.frnn_knn(p, 24, 0.15)
    rd, ri = frnn_reading(p, 24, 0.15)
    assert d.shape == (1, 600, 24) and torch.equal(i, ri)
    assert torch.allclose(d, rd, rtol=1e-6 if dtype == torch.float32 else 1e-15, atol=0)
    seg = torch.randint(0, 3, (600,))
    d, i = compat.frnn_knn(p, 24, 0.15, segments=seg)
    rd, ri = frnn_reading(p, 24, 0.15, seg)
    assert torch.equal(i, ri)
    assert torch.allclose(d, rd, rtol=1e-6 if dtype == torch.float32 else 1e-15, atol=0)
    valid = i[0] >= 0
    assert torch.equal(seg[i[0].clamp(min=0)][valid], seg[:, None].expand(-1, 24)[valid])  # segments kept apart


@pytest.mark.skipif(not (torch.cuda.is_available() and smg_torch.has_cuda), reason="needs a CUDA device")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_cuda_rows_equal_the_cpu(dtype):
    p = torch.rand(5000, 3, dtype=dtype)
    for K, radius in ((8, None), (24, 0.05), (40, None)):
        cd2, cidx = smg_torch.knn_points(p.cuda(), K, radius=radius)
        d2, idx = smg_torch.knn_points(p, K, radius=radius)
        assert torch.equal(cidx.cpu(), idx) and torch.equal(cd2.cpu(), d2)
