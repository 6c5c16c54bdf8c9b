"""smg_torch.compat.ds4d_losses against a plain-torch implementation of DreamScene4D's scale and
local rigidity losses written here from a reading of dreamscene4d/dreamscene4d gs_renderer_4d.py:
Renderer.render_flow (scale_change = scales_deform − scales, its neighbour differences,
sqrt((·)²·sum · nn_weights + 1e-20).mean(); curr_rotations_final = rotation_activation (F.normalize)
of the current deform rotations, its vector part negated in place; rel_rotmat =
build_rotation(quat_mult(rotations_final, curr_rotations_final_inv)); the current neighbour
displacements warped by rel_rotmatᵀ against the previous ones, the same root and mean) and
Renderer.precompute_nn (cKDTree.query(x, k=16): the point in column 0; nn_weights = exp(−10 d)).
Values and gradients of all six inputs in float64 and float32, the rigid-motion case in both
orders, self edges, zero weights, a zero-length edge, raw quaternions of norm ≠ 1, bad arguments,
CUDA (skipped without a device)."""
import math

import pytest
import torch
import torch.nn.functional as F

import smg_torch as smg
from smg_torch.compat import ds4d_losses
from test_compat_d3dgs import build_rotation, quat_mult

cuda = pytest.mark.skipif(not (torch.cuda.is_available() and smg.has_cuda),
                          reason="no CUDA device or smg_torch built without CUDA")


def ds4d_torch(pos_curr, pos_prev, rot_curr, rot_prev, sc_prev, sc_base, idx, w, order="upstream"):
    """(local_scale_loss, local_rigidity_loss) as render_flow computes them (order="d3dgs": the
    relative rotation composed as Dynamic 3D Gaussians does, q_curr ⊗ q_prev*)."""
    scale_change = sc_prev - sc_base
    d = scale_change[idx] - scale_change.unsqueeze(1)
    scale = torch.sqrt((d ** 2).sum(-1) * w + 1e-20).mean()
    curr = F.normalize(rot_curr)
    prev = F.normalize(rot_prev)
    curr_inv = curr.clone()
    curr_inv[:, 1:] = -1.0 * curr_inv[:, 1:]
    if order == "upstream":
        rel = quat_mult(prev, curr_inv)
    else:
        prev_inv = prev.clone()
        prev_inv[:, 1:] = -1.0 * prev_inv[:, 1:]
        rel = quat_mult(curr, prev_inv)
    prev_disp = pos_prev[idx] - pos_prev.unsqueeze(1)
    curr_disp = pos_curr[idx] - pos_curr.unsqueeze(1)
    warped = (build_rotation(rel).transpose(2, 1)[:, None] @ curr_disp[:, :, :, None]).squeeze(-1)
    rigidity = torch.sqrt(((prev_disp - warped) ** 2).sum(-1) * w + 1e-20).mean()
    return scale, rigidity


def knn16(x, K=16):
    """precompute_nn's table: K nearest with the point itself (cKDTree.query), weights exp(−10 d)."""
    d2, idx = smg.knn_points(x.detach().double(), K)
    return idx, torch.exp(-10.0 * d2.sqrt())


def scene(N=400, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    pos_prev = torch.rand(N, 3, generator=g, dtype=torch.float64) * 0.5
    pos_curr = pos_prev + 0.02 * torch.randn(N, 3, generator=g, dtype=torch.float64)
    rot_prev = torch.randn(N, 4, generator=g, dtype=torch.float64) * 0.3 + torch.tensor([2.0, 0, 0, 0], dtype=torch.float64)
    rot_curr = rot_prev + 0.05 * torch.randn(N, 4, generator=g, dtype=torch.float64)
    sc_base = torch.randn(N, 3, generator=g, dtype=torch.float64) - 4
    sc_prev = sc_base + 0.1 * torch.randn(N, 3, generator=g, dtype=torch.float64)
    idx, w = knn16(pos_prev)
    return [t.to(dtype) for t in (pos_curr, pos_prev, rot_curr, rot_prev, sc_prev, sc_base)] + [idx, w.to(dtype)]


def both(inputs, weights=(1.0, 0.7), order="upstream"):
    """Values and the gradients of all six inputs, smg's and the reading's."""
    a = [t.detach().clone().requires_grad_() for t in inputs[:6]]
    b = [t.detach().double().clone().requires_grad_() for t in inputs[:6]]
    ea = ds4d_losses(*a, *inputs[6:], order=order)
    eb = ds4d_torch(*b, inputs[6], inputs[7].double(), order=order)
    (weights[0] * ea[0] + weights[1] * ea[1]).backward()
    (weights[0] * eb[0] + weights[1] * eb[1]).backward()
    return ea, [t.grad for t in a], eb, [t.grad for t in b]


def rel(a, b):
    return float((a.double() - b.double()).abs().max() / b.double().abs().max().clamp_min(1e-300))


@pytest.mark.parametrize("order", ["upstream", "d3dgs"])
@pytest.mark.parametrize("seed", [0, 1])
def test_ds4d_float64(order, seed):
    ea, ga, eb, gb = both(scene(seed=seed), order=order)
    for x, y in zip(ea, eb):
        assert abs(float(x) - float(y)) <= 1e-9 * abs(float(y))
    for x, y in zip(ga, gb):
        assert rel(x, y) <= 1e-7


def test_ds4d_passes_side_by_side_equal_in_turn():
    """With 2 intra-op threads the rigidity and scale passes run side by side
    (compat._side_by_side); with 1 in turn: the losses and all six gradients are the same bits."""
    before = torch.get_num_threads()
    try:
        for dtype in (torch.float32, torch.float64):
            inputs = scene(seed=5, dtype=dtype)
            out = {}
            for threads in (1, 2):
                torch.set_num_threads(threads)
                ea, ga, _, _ = both(inputs)
                out[threads] = ([float(e) for e in ea], ga)
            assert smg.compat._SIDE_POOL is not None  # the two-thread run took the side-by-side path
            assert out[1][0] == out[2][0]
            assert all(torch.equal(a, b) for a, b in zip(out[1][1], out[2][1]))
    finally:
        torch.set_num_threads(before)


def test_ds4d_float32_against_the_float64_reading():
    ea, ga, eb, gb = both(scene(dtype=torch.float32, seed=3))
    assert ea[0].dtype == torch.float32 and ea[1].dtype == torch.float32
    for x, y in zip(ea, eb):
        assert abs(float(x) - float(y)) <= 1e-5 * abs(float(y))
    for x, y in zip(ga, gb):
        assert rel(x, y) <= 1e-4


def test_ds4d_a_rigid_motion_is_zero_only_in_d3dgs_order():
    """Points and Gaussians rotated together by R_Δ (and moved): D3DGS's composition sees no
    deformation (every root at its 1e-20 floor), DreamScene4D's as read sees ‖(R_Δ² − I) e‖."""
    pos_curr, pos_prev, rot_curr, rot_prev, sc_prev, sc_base, idx, w = scene(seed=5)
    axis = torch.tensor([0.3, -0.5, 0.8], dtype=torch.float64)
    axis = axis / axis.norm()
    half = 0.35
    dq = torch.cat([torch.tensor([math.cos(half)], dtype=torch.float64), math.sin(half) * axis])
    R = build_rotation(dq[None])[0]
    pos_curr = pos_prev @ R.T + torch.tensor([0.1, 0.2, -0.3], dtype=torch.float64)
    rot_curr = quat_mult(dq.expand_as(rot_prev), rot_prev) * 1.7  # raw: any norm, normalised upstream
    floor = 1e-10
    _, rigid_d3 = ds4d_losses(pos_curr, pos_prev, rot_curr, rot_prev, sc_prev, sc_base, idx, w, order="d3dgs")
    _, rigid_up = ds4d_losses(pos_curr, pos_prev, rot_curr, rot_prev, sc_prev, sc_base, idx, w)
    _, ref_up = ds4d_torch(pos_curr, pos_prev, rot_curr, rot_prev, sc_prev, sc_base, idx, w)
    assert float(rigid_d3) == pytest.approx(floor, rel=1e-3, abs=1e-12)
    assert float(rigid_up) > 1e-3 and float(rigid_up) == pytest.approx(float(ref_up), rel=1e-9)


def test_ds4d_self_edges_zero_weights_and_a_zero_length_edge():
    inputs = scene(N=120, seed=7)
    pos_curr, pos_prev = inputs[0], inputs[1]
    pos_prev[5] = pos_prev[9]  # a duplicate point: zero-length edges, a self edge possibly off column 0
    pos_curr[5] = pos_curr[9]
    idx, w = knn16(pos_prev)
    inputs[6], inputs[7] = idx, w
    assert bool((idx[:, 0] == torch.arange(120)).sum() >= 119)
    ea, ga, eb, gb = both(inputs)
    for x, y in zip(ea, eb):
        assert abs(float(x) - float(y)) <= 1e-9 * abs(float(y))
    for x, y in zip(ga, gb):
        assert rel(x, y) <= 1e-7
    zero = torch.zeros_like(w)
    s, r = ds4d_losses(*inputs[:6], idx, zero)
    assert float(s) == pytest.approx(1e-10, rel=1e-9) and float(r) == pytest.approx(1e-10, rel=1e-9)


def test_ds4d_gradcheck():
    inputs = scene(N=30, seed=11)
    idx, w = knn16(inputs[1], K=5)
    xs = [t.detach().clone().requires_grad_() for t in inputs[:6]]
    assert torch.autograd.gradcheck(lambda *v: sum(ds4d_losses(*v, idx, w)), tuple(xs), eps=1e-6, atol=1e-8,
                                    rtol=1e-6)


@pytest.mark.parametrize("change,match", [
    (lambda a: a.__setitem__(6, a[6].clone().index_fill_(1, torch.tensor([3]), 400)), r"nn_indices\[0, 3\] = 400 is not a point"),
    (lambda a: a.__setitem__(7, -a[7]), r"nn_weights\[0, 0\] = -1(\.0)? is negative"),
    (lambda a: a[0].__setitem__((2, 1), math.nan), r"pos_curr\[2\] has a NaN"),
    (lambda a: a[3].__setitem__(4, 0.0), r"rot_deform_prev\[4\] is the zero quaternion"),
    (lambda a: a.__setitem__(4, a[4][:10]), r"scales_deform_prev: expected shape \[400, 3\]"),
    (lambda a: a.__setitem__(5, a[5].float()), r"scales_base: dtype torch.float32 differs"),
])
def test_ds4d_refuses_bad_arguments(change, match):
    inputs = scene()
    change(inputs)
    with pytest.raises(ValueError, match=match):
        ds4d_losses(*inputs)
    with pytest.raises(ValueError, match=r"order: must be 'upstream'"):
        ds4d_losses(*scene(), order="reverse")


@cuda
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_ds4d_cuda(dtype):
    inputs = scene(dtype=dtype, seed=2)
    cpu = ds4d_losses(*inputs)
    gpu = ds4d_losses(*[t.cuda() for t in inputs])
    for x, y in zip(gpu, cpu):
        assert abs(float(x) - float(y)) <= (1e-5 if dtype == torch.float32 else 1e-12) * abs(float(y))
