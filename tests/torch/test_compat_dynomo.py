"""smg_torch.compat.dynomo_losses against a plain-torch implementation of DynOMo's physics-based
losses written here from a reading of dvl-tum/DynOMo (commit 1b0e384):

- src/utils/losses.py l2_loss_v2 (lines 82-92): sqrt((x − y)² + 1e-20) per component, times the
  weight (outside the root), mean over every entry;
- src/utils/losses.py physics_based_losses (lines 106-169): weight = neighbor_weight[:, None];
  other_rot = the previous raw rotations, detached, vector part negated (lines 128-129);
  rel_rot = quat_mult(curr_rot, other_rot), rel_rot_mat = build_rotation(rel_rot) (lines 132-133);
  rigid: offset = curr[self] − curr[neighbor] warped by rel_rot_mat[self]ᵀ against the previous
  offset (lines 136-143); rot: rel_rot[neighbor] against rel_rot[self] (lines 146-149); iso: the
  offset's length sqrt(‖·‖² + 1e-20) against offset_0's, weight squeezed (lines 165-168);
- src/utils/gaussian_utils.py build_rotation (lines 24-40, q over its norm + 1e-20) and quat_mult
  (lines 50-58).

Values and gradients (curr_means and the raw curr_rot) in float64 and float32, raw quaternions of
norm ≠ 1, self edges with weight 1, zero weights, a zero-length edge, a rigid motion, bad
arguments, CUDA (skipped without a device)."""
import math

import pytest
import torch

import smg_torch as smg
from smg_torch.compat import dynomo_losses

cuda = pytest.mark.skipif(not (torch.cuda.is_available() and smg.has_cuda),
                          reason="no CUDA device or smg_torch built without CUDA")


def quat_mult(q1, q2):
    w1, x1, y1, z1 = q1.T
    w2, x2, y2, z2 = q2.T
    return torch.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2]).T


def build_rotation(q):
    q = q / (torch.sqrt((q * q).sum(-1)) + 1e-20)[:, None]
    r, x, y, z = q.unbind(-1)
    return torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - r * z), 2 * (x * z + r * y),
                        2 * (x * y + r * z), 1 - 2 * (x * x + z * z), 2 * (y * z - r * x),
                        2 * (x * z - r * y), 2 * (y * z + r * x), 1 - 2 * (x * x + y * y)], -1).view(-1, 3, 3)


def l2_loss_v2(x, y, weight):
    return (torch.sqrt((x - y) ** 2 + 1e-20) * weight).mean()


def dynomo_torch(curr_means, curr_rot, prev_means, prev_rot, s, n, w, offset_0):
    weight = w.unsqueeze(1)
    other_rot = prev_rot.detach().clone()
    other_rot[:, 1:] = -1 * other_rot[:, 1:]
    other_means = prev_means.detach().clone()
    rel_rot = quat_mult(curr_rot, other_rot)
    rel_rot_mat = build_rotation(rel_rot)
    offset = curr_means[s] - curr_means[n]
    offset_other = (rel_rot_mat[s].transpose(2, 1) @ offset.unsqueeze(-1)).squeeze(-1)
    other_offset = other_means[s] - other_means[n]
    rigid = l2_loss_v2(offset_other, other_offset, weight)
    rot = l2_loss_v2(rel_rot[n], rel_rot[s], weight)
    iso = l2_loss_v2(torch.sqrt((offset ** 2).sum(-1) + 1e-20), torch.sqrt((offset_0 ** 2).sum(-1) + 1e-20),
                     weight.squeeze())
    return rigid, rot, iso


def scene(N=300, K=8, seed=0, dtype=torch.float64, self_edges=False):
    """DynOMo's tables: self_indices = arange(N) tiled K times, neighbor_indices the K nearest
    (o3d_knn: self dropped unless self_edges), weights exp(−2000 d²); raw rotations of norm ≠ 1."""
    g = torch.Generator().manual_seed(seed)
    prev = torch.rand(N, 3, generator=g, dtype=torch.float64) * 0.2
    curr = prev + 0.005 * torch.randn(N, 3, generator=g, dtype=torch.float64)
    prev_rot = torch.randn(N, 4, generator=g, dtype=torch.float64) * 0.3 + torch.tensor([1.5, 0, 0, 0],
                                                                                          dtype=torch.float64)
    curr_rot = prev_rot + 0.05 * torch.randn(N, 4, generator=g, dtype=torch.float64)
    d2, idx = smg.knn_points(prev, K + (0 if self_edges else 1))
    if not self_edges:
        d2, idx = d2[:, 1:], idx[:, 1:]
    s = torch.arange(N).repeat_interleave(K)
    n = idx.flatten()
    w = torch.exp(-2000 * d2.flatten())
    if self_edges:
        w = torch.where(s == n, torch.ones_like(w), w)
    first = prev + 0.01 * torch.randn(N, 3, generator=g, dtype=torch.float64)
    offset_0 = first[s] - first[n]
    return [t.to(dtype) for t in (curr, curr_rot, prev, prev_rot)] + [s, n, w.to(dtype), offset_0.to(dtype)]


def rel(a, b):
    return float((a.double() - b.double()).abs().max() / b.double().abs().max().clamp_min(1e-300))


def both(inputs, weights=(1.0, 0.7, 0.3)):
    a = [t.detach().clone().requires_grad_() for t in inputs[:2]]
    b = [t.detach().double().clone().requires_grad_() for t in inputs[:2]]
    ea = dynomo_losses(*a, *inputs[2:])
    eb = dynomo_torch(*b, *[t.double() if t.is_floating_point() else t for t in inputs[2:]])
    sum(c * e for c, e in zip(weights, ea)).backward()
    sum(c * e for c, e in zip(weights, eb)).backward()
    return ea, [t.grad for t in a], eb, [t.grad for t in b]


@pytest.mark.parametrize("seed,self_edges", [(0, False), (1, True)])
def test_dynomo_float64(seed, self_edges):
    ea, ga, eb, gb = both(scene(seed=seed, self_edges=self_edges))
    for x, y in zip(ea, eb):
        assert abs(float(x) - float(y)) <= 1e-12 * abs(float(y))
    for x, y in zip(ga, gb):
        assert rel(x, y) <= 1e-10


def test_dynomo_float32_against_the_float64_reading():
    ea, ga, eb, gb = both(scene(seed=3, dtype=torch.float32))
    assert all(e.dtype == torch.float32 for e in ea)
    for x, y in zip(ea, eb):
        assert abs(float(x) - float(y)) <= 1e-5 * abs(float(y))
    for x, y in zip(ga, gb):
        assert rel(x, y) <= 1e-4


def test_dynomo_each_loss_alone_and_the_radial_gradient_of_raw_quaternions():
    inputs = scene(seed=4)
    for which in range(3):
        weights = tuple(1.0 if i == which else 0.0 for i in range(3))
        _, ga, _, gb = both(inputs, weights)
        for x, y in zip(ga, gb):
            assert rel(x, y) <= 1e-10
    _, ga, _, _ = both(inputs, (0.0, 1.0, 0.0))
    q = inputs[1]
    radial = (ga[1] * q).sum(-1)  # rot on raw products has a radial part (D3DGS's normalised one has none)
    assert float(radial.abs().max()) > 1e-6


def test_dynomo_a_rigid_motion_and_zero_weights():
    """Means and raw rotations moved rigidly together: rigid at w·sqrt(1e-20) per component,
    rot at its floor only where the raw norms match; zero weights give exactly 0."""
    curr, curr_rot, prev, prev_rot, s, n, w, offset_0 = scene(seed=5)
    axis = torch.tensor([0.2, 0.9, -0.4], dtype=torch.float64)
    axis = axis / axis.norm()
    dq = torch.cat([torch.tensor([math.cos(0.3)], dtype=torch.float64), math.sin(0.3) * axis])
    R = build_rotation(dq[None])[0]
    curr = prev @ R.T + torch.tensor([0.3, -0.1, 0.2], dtype=torch.float64)
    curr_rot = quat_mult(dq.expand_as(prev_rot), prev_rot)
    rigid, rot, iso = dynomo_losses(curr, curr_rot, prev, prev_rot, s, n, w, prev[s] - prev[n])
    floor = float(w.mean()) * 1e-10
    assert float(rigid) == pytest.approx(floor, rel=1e-5, abs=1e-14)
    assert float(iso) == pytest.approx(floor, rel=1e-5, abs=1e-14)
    ref = dynomo_torch(curr, curr_rot, prev, prev_rot, s, n, w, prev[s] - prev[n])
    assert float(rot) == pytest.approx(float(ref[1]), rel=1e-12)  # rel = dq·|prev|²: not at the floor
    zero = dynomo_losses(curr, curr_rot, prev, prev_rot, s, n, torch.zeros_like(w), offset_0)
    assert all(float(z) == 0.0 for z in zero)


def test_dynomo_zero_length_edge():
    inputs = scene(N=60, seed=6, self_edges=True)
    inputs[0][3] = inputs[0][9]  # coincident at the current time
    inputs[4] = torch.cat([inputs[4], torch.tensor([3, 9])])
    inputs[5] = torch.cat([inputs[5], torch.tensor([9, 3])])
    inputs[6] = torch.cat([inputs[6], torch.tensor([0.5, 0.25], dtype=torch.float64)])
    inputs[7] = torch.cat([inputs[7], torch.zeros(2, 3, dtype=torch.float64)])
    ea, ga, eb, gb = both(inputs)
    for x, y in zip(ea, eb):
        assert abs(float(x) - float(y)) <= 1e-12 * abs(float(y))
    for x, y in zip(ga, gb):
        assert rel(x, y) <= 1e-10


def test_dynomo_gradcheck():
    inputs = scene(N=25, K=4, seed=7)
    xs = [t.detach().clone().requires_grad_() for t in inputs[:2]]
    assert torch.autograd.gradcheck(lambda *v: sum(c * e for c, e in zip((1.0, 0.6, 0.4), dynomo_losses(*v, *inputs[2:]))),
                                    tuple(xs), eps=1e-6, atol=1e-8, rtol=1e-6)


def test_dynomo_chunks_agree_with_one_pass(monkeypatch):
    import smg_torch.compat as compat
    inputs = scene(N=200, seed=8)
    ea, ga, _, _ = both(inputs)
    monkeypatch.setattr(compat, "_EDGE_CHUNK", 97)
    eb, gb, _, _ = both(inputs)
    for x, y in zip(ea, eb):
        assert abs(float(x) - float(y)) <= 1e-13 * abs(float(y))
    for x, y in zip(ga, gb):
        assert rel(x, y) <= 1e-13


@pytest.mark.parametrize("change,match", [
    (lambda a: a.__setitem__(5, torch.where(a[5] == 7, 300, a[5])), r"neighbor_indices\[\d+\] = 300 is not a row"),
    (lambda a: a[0].__setitem__((2, 1), math.nan), r"curr_means\[2\] has a NaN"),
    (lambda a: a[3].__setitem__(4, 0.0), r"prev_rot\[4\] is the zero quaternion"),
    (lambda a: a.__setitem__(7, a[7][:10]), r"offset_0: expected shape \[2400, 3\]"),
    (lambda a: a.__setitem__(6, a[6].float()), r"neighbor_weight: torch.float32"),
    (lambda a: a[6].__setitem__(5, math.inf), r"neighbor_weight\[5\] is inf"),
    (lambda a: a.__setitem__(4, a[4][:0]), r"self_indices: no edges"),
    (lambda a: a.__setitem__(4, a[4].float()), r"self_indices: dtype must be int64 or int32"),
])
def test_dynomo_refuses_bad_arguments(change, match):
    inputs = scene()
    change(inputs)
    with pytest.raises(ValueError, match=match):
        dynomo_losses(*inputs)


@cuda
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_dynomo_cuda(dtype):
    inputs = scene(dtype=dtype, seed=2)
    cpu = dynomo_losses(*inputs)
    gpu = dynomo_losses(*[t.cuda() for t in inputs])
    for x, y in zip(gpu, cpu):
        assert abs(float(x) - float(y)) <= (1e-5 if dtype == torch.float32 else 1e-12) * abs(float(y))
