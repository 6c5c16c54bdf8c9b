"""smg_torch.compat against plain-torch implementations of the upstream losses, written here from
their reading (docs/compat.md): values and autograd gradients, float64 and float32, the inputs
where torch's gradient is exactly 0, bad arguments, and CUDA (skipped without a device)."""
import pytest
import torch
import torch.nn.functional as F

import smg_torch as smg
from pytorch3d_reference import matrix_to_quaternion, quaternion_to_axis_angle, quaternion_to_matrix
from smg_torch.compat import mosca_arap, mosca_vel_acc, som_accel

cuda = pytest.mark.skipif(not (torch.cuda.is_available() and smg.has_cuda),
                          reason="no CUDA device or smg_torch built without CUDA")


def som_accel_torch(transls):
    """Shape of Motion's compute_accel_loss as its code computes it: the second difference along
    dim 1 (2 x_t − x_{t−1} − x_{t+1}), its norm over the last dim, the mean over the rest."""
    T = transls.shape[1]
    mid = transls.narrow(1, 1, T - 2)
    prev = transls.narrow(1, 0, T - 2)
    nxt = transls.narrow(1, 2, T - 2)
    return (2 * mid - prev - nxt).norm(dim=-1).mean()


def _rel(a, b):
    """Largest difference relative to the largest reference value."""
    return float((a.double() - b.double()).abs().max() / b.double().abs().max().clamp_min(1e-300))


def _smooth(shape, dtype=torch.float64, seed=0):
    """Random smooth trajectories along dim 1 (cumulative sums of random steps)."""
    g = torch.Generator().manual_seed(seed)
    return (torch.randn(shape, generator=g, dtype=torch.float64).cumsum(1) * 0.1).to(dtype)


def _both(x):
    """(value, gradient) of som_accel and of the torch reference on copies of x."""
    a = x.detach().clone().requires_grad_()
    b = x.detach().clone().requires_grad_()
    ea, eb = som_accel(a), som_accel_torch(b)
    ea.backward()
    eb.backward()
    return ea, a.grad, eb, b.grad


# The shapes Shape of Motion passes: motion bases [K, T, 3] (10 bases), the initial optimisation's
# tracks [G, T, 3], the trainer's neighbourhoods [G, 3, B, 3] (time on dim 1, B batch frames), a
# single trajectory, the minimum T = 3.
SHAPES = [(10, 30, 3), (500, 30, 3), (64, 3, 8, 3), (1, 17, 3), (7, 3, 3), (5, 6, 2, 2, 3)]


@pytest.mark.parametrize("shape", SHAPES)
def test_som_accel_float64(shape):
    x = _smooth(shape)
    ea, ga, eb, gb = _both(x)
    assert ea.dim() == 0 and ea.dtype == torch.float64
    assert float(eb) > 0
    assert abs(float(ea) - float(eb)) <= 1e-9 * abs(float(eb))
    assert ga.shape == x.shape
    assert _rel(ga, gb) <= 1e-7


@pytest.mark.parametrize("shape", SHAPES)
def test_som_accel_float32(shape):
    x = _smooth(shape, torch.float32, seed=1)
    ea, ga, eb, gb = _both(x)
    assert ea.dtype == torch.float32 and ga.dtype == torch.float32
    ref = som_accel_torch(x.double())  # the float64 value: both float results near it
    assert abs(float(ea) - float(ref)) <= 1e-5 * float(ref)
    assert abs(float(ea) - float(eb)) <= 1e-5 * float(ref)
    assert _rel(ga, gb) <= 1e-4


def test_som_accel_gradcheck():
    x = _smooth((4, 6, 3), seed=2).requires_grad_()
    assert torch.autograd.gradcheck(som_accel, (x,), eps=1e-6, atol=1e-8, rtol=1e-6)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_som_accel_constant_velocity_has_exactly_zero_gradient(dtype):
    # Dyadic positions and velocities: the second differences are exactly 0, so torch's norm
    # backward gives exactly 0 there; tracks 2 and 5 accelerate, the others move at constant
    # velocity (track 0 is still).
    G, T = 8, 9
    t = torch.arange(T, dtype=torch.float64)[None, :, None]
    g = torch.arange(G, dtype=torch.float64)[:, None, None]
    d = torch.arange(3, dtype=torch.float64)[None, None, :]
    x = 0.125 * (g + d) + t * 0.0625 * g * (d + 1)
    x[2] += 0.01 * t[0] ** 2
    x[5] -= 0.03 * t[0] ** 3
    x = x.to(dtype)
    ea, ga, eb, gb = _both(x)
    assert float(ea) > 0
    still = [i for i in range(G) if i not in (2, 5)]
    assert torch.equal(gb[still], torch.zeros_like(gb[still]))  # the premise: torch gives 0
    assert torch.equal(ga[still], torch.zeros_like(ga[still]))
    assert _rel(ga, gb) <= (1e-7 if dtype == torch.float64 else 1e-4)
    # Every track at constant velocity: the loss is exactly 0 and so is every gradient.
    x[2] = 0.25 * t[0] + 0.5
    x[5] = -0.125 * t[0]
    ea, ga, eb, gb = _both(x)
    assert float(ea) == 0.0 and float(eb) == 0.0
    assert torch.equal(ga, torch.zeros_like(ga)) and torch.equal(gb, torch.zeros_like(gb))


def test_som_accel_non_contiguous_and_trainer_weighting():
    base = _smooth((12, 3, 40), seed=3)
    x = base.transpose(1, 2)[:, :, :3]  # [12, 40, 3], a non-contiguous view
    assert not x.is_contiguous()
    ea, ga, eb, gb = _both(x)
    assert abs(float(ea) - float(eb)) <= 1e-9 * float(eb)
    assert _rel(ga, gb) <= 1e-7
    # The trainer's form: 0.5 * mean(...) * w_smooth_tracks, a scale of the same loss.
    a = x.detach().clone().requires_grad_()
    (0.5 * som_accel(a) * 2.0).backward()
    assert _rel(a.grad, gb) <= 1e-7
    # No grad needed: a plain value.
    assert not som_accel(x.detach()).requires_grad


@pytest.mark.parametrize("bad,err,match", [
    (lambda: [[0.0] * 3] * 3, ValueError, "transls: expected a torch.Tensor"),
    (lambda: torch.zeros(5, 3), ValueError, r"transls: expected shape \[K, T, 3\]"),
    (lambda: torch.zeros(4, 5, 6), ValueError, "transls: the last dim must be 3"),
    (lambda: torch.zeros(4, 5, 3, dtype=torch.int64), ValueError, "transls: dtype must be float32 or float64"),
    (lambda: torch.zeros(4, 5, 3, dtype=torch.float16), ValueError, "transls: dtype must be float32 or float64"),
    (lambda: torch.zeros(4, 2, 3), ValueError, "transls: needs T >= 3"),
    (lambda: torch.zeros(0, 5, 3), ValueError, "transls: has an empty dim"),
    (lambda: torch.zeros(4, 5, 0, 3), ValueError, "transls: has an empty dim"),
    (lambda: torch.full((4, 5, 3), float("nan")), ValueError, r"^transls\[0, 0\] has a NaN"),
])
def test_som_accel_refuses_bad_arguments(bad, err, match):
    with pytest.raises(err, match=match):
        som_accel(bad())


def test_som_accel_refuses_cuda_without_cuda_build():
    if smg.has_cuda or not torch.cuda.is_available():
        pytest.skip("needs a CUDA device and an smg_torch built without CUDA")
    with pytest.raises(NotImplementedError, match="transls"):
        som_accel(torch.zeros(4, 5, 3, device="cuda"))


@cuda
@pytest.mark.parametrize("dtype,tol_e,tol_g", [(torch.float64, 1e-9, 1e-7), (torch.float32, 1e-5, 1e-4)])
@pytest.mark.parametrize("shape", [(10, 30, 3), (64, 3, 8, 3)])
def test_som_accel_cuda(dtype, tol_e, tol_g, shape):
    x = _smooth(shape, dtype, seed=4).cuda()
    ea, ga, eb, gb = _both(x)
    assert ea.device.type == "cuda" and ga.device.type == "cuda"
    assert abs(float(ea) - float(eb)) <= tol_e * float(eb)
    assert _rel(ga, gb) <= tol_g
    ec, gc, _, _ = _both(x.cpu())
    assert abs(float(ea) - float(ec)) <= tol_e * float(ec)
    assert _rel(ga.cpu(), gc) <= tol_g


# ---- MoSca: compute_arap_loss, compute_vel_acc_loss (lib_mosca/mosca.py) ------------------------

def mosca_local_coord_torch(xyz, R, self_ind, nn_ind, detach_self=False, detach_nn=False):
    """get_local_coord as MoSca computes it: the node `self_ind` expressed in the frame of the
    node `nn_ind`, R_nn^T (x_self − x_nn), with either position detached; [T, rows, K, 3]."""
    xs, xn = xyz[:, self_ind], xyz[:, nn_ind]
    if detach_self:
        xs = xs.detach()
    if detach_nn:
        xn = xn.detach()
    return torch.einsum("trkji,trkj->trki", R[:, nn_ind], xs - xn)


def mosca_shift_losses_torch(local, w, shifts, shift_weights, reduce, square):
    """compute_arap's shift loop: per shift the coordinate change's norm and the length change's
    absolute value, squared with square, weighted over k, then the mean or sum over (t, row)."""
    lens = local.norm(dim=-1)
    coord = local.new_zeros(())
    length = local.new_zeros(())
    for s, g in zip(shifts, shift_weights):
        if local.shape[0] - s < 1:
            continue
        dc = (local[:-s] - local[s:]).norm(dim=-1)
        dl = (lens[:-s] - lens[s:]).abs()
        if square:
            dc, dl = dc ** 2, dl ** 2
        dc, dl = (dc * w[None]).sum(-1), (dl * w[None]).sum(-1)
        coord = coord + g * (dc.mean() if reduce == "mean" else dc.sum())
        length = length + g * (dl.mean() if reduce == "mean" else dl.sum())
    return coord, length


def mosca_arap_torch(xyz, quat, topo_ind, topo_mask, shifts, shift_weights, reduce="mean",
                     square=False, levels=()):
    """MoSca.compute_arap_loss as its code computes it, with pytorch3d's conversions."""
    R = quaternion_to_matrix(F.normalize(quat, dim=-1))
    M = xyz.shape[1]
    w = topo_mask.float()
    w = (w / (w.sum(dim=-1, keepdim=True) + 1e-6)).to(xyz.dtype)
    self_ind = torch.arange(M)[:, None].expand_as(topo_ind)
    coord, length = mosca_shift_losses_torch(mosca_local_coord_torch(xyz, R, self_ind, topo_ind), w,
                                             shifts, shift_weights, reduce, square)
    for edges, weight, mu, detach_nn, detach_self in levels:
        local = mosca_local_coord_torch(xyz, R, edges[:, :1], edges[:, 1:], detach_self, detach_nn)
        c, l = mosca_shift_losses_torch(local, weight[:, None].to(xyz.dtype), shifts, shift_weights,
                                        reduce, square)
        coord, length = coord + c * mu, length + l * mu
    return coord, length


def mosca_vel_acc_torch(xyz, quat, reduce="mean", square=False):
    """MoSca.compute_vel_acc_loss: position velocity and acceleration norms, the rotation angle of
    R^{t+1} R^{tT} (matrix -> quaternion -> axis-angle, its norm) and its change's magnitude."""
    R = quaternion_to_matrix(F.normalize(quat, dim=-1))
    p_vel = (xyz[1:] - xyz[:-1]).norm(dim=-1)
    p_acc = (xyz[2:] - 2 * xyz[1:-1] + xyz[:-2]).norm(dim=-1)
    q_vel = quaternion_to_axis_angle(matrix_to_quaternion(torch.einsum("tnij,tnkj->tnik", R[1:], R[:-1]))).norm(dim=-1)
    q_acc = (q_vel[1:] - q_vel[:-1]).abs()
    out = [p_vel, q_vel, p_acc, q_acc]
    if square:
        out = [v ** 2 for v in out]
    return tuple(v.mean() if reduce == "mean" else v.sum() for v in out)


def mosca_scene(T=20, M=64, K=16, seed=0, dtype=torch.float64, levels=True):
    """MoSca-like inputs (docs/compat.md's recipe): a rigid motion plus a small smooth deformation,
    raw quaternions of norm 1.3, topo_ind = [self, the 15 nearest at frame 0], a fifth of the other
    mask entries off, and one coarse level: every node to its 8 nearest among a random third."""
    g = torch.Generator().manual_seed(seed)
    p0 = torch.rand(M, 3, generator=g, dtype=torch.float64)
    t = torch.linspace(0, 1, T, dtype=torch.float64)[:, None, None]
    ang = 0.8 * t[..., 0]
    c, s_ = torch.cos(ang), torch.sin(ang)
    zero, one = torch.zeros_like(c), torch.ones_like(c)
    Rz = torch.stack([c, -s_, zero, s_, c, zero, zero, zero, one], -1).reshape(T, 1, 3, 3)
    bend = 0.05 * torch.sin(3 * t + p0[None, :, :1] * 4) * torch.tensor([0.0, 1.0, 0.5], dtype=torch.float64)
    xyz = torch.einsum("tnij,nj->tni", Rz.expand(T, M, 3, 3), p0) + 0.3 * t + bend
    xyz = xyz + 0.002 * torch.randn(T, M, 3, generator=g, dtype=torch.float64)
    q = torch.randn(T, M, 4, generator=g, dtype=torch.float64).cumsum(0) * 0.1 + torch.randn(1, M, 4, generator=g, dtype=torch.float64)
    q = 1.3 * F.normalize(q, dim=-1)
    d = torch.cdist(p0, p0)
    d.fill_diagonal_(float("inf"))
    nn = d.topk(K - 1, largest=False).indices
    topo_ind = torch.cat([torch.arange(M)[:, None], nn], 1)
    mask = torch.rand(M, K, generator=g) > 0.2
    mask[:, 0] = True
    lv = ()
    if levels:
        coarse = torch.randperm(M, generator=g)[: M // 3]
        dc = torch.cdist(p0, p0[coarse])
        near = coarse[dc.topk(8, largest=False).indices]  # may contain the node itself
        edges = torch.stack([torch.arange(M)[:, None].expand(M, 8), near], -1).reshape(-1, 2)
        weight = (torch.rand(edges.shape[0], generator=g) > 0.1).float()
        lv = ((edges, weight, 0.4, True, False),)
    return xyz.to(dtype), q.to(dtype), topo_ind, mask, lv


SHIFTS, GAMMAS = [1, 3, 6], [0.6, 0.3, 0.1]


def _arap_both(xyz, q, topo_ind, mask, levels, reduce, square, lam=(10.0, 10.0), dtype=torch.float64):
    """(values, x grad, q grad) of λc·coord + λl·len for smg and the torch reference."""
    out = []
    for fn in (mosca_arap, mosca_arap_torch):
        x = xyz.detach().clone().to(dtype).requires_grad_()
        r = q.detach().clone().to(dtype).requires_grad_()
        lv = tuple((e, w, mu, dn, ds) for e, w, mu, dn, ds in levels)
        if fn is mosca_arap:
            c, l = fn(x, r, topo_ind, mask, SHIFTS, GAMMAS, reduce=reduce, square=square, levels=lv)
        else:
            c, l = fn(x, r, topo_ind, mask, SHIFTS, GAMMAS, reduce, square, lv)
        (lam[0] * c + lam[1] * l).backward()
        out.append((c.detach(), l.detach(), x.grad, r.grad))
    return out


@pytest.mark.parametrize("reduce", ["mean", "sum"])
@pytest.mark.parametrize("square", [False, True])
@pytest.mark.parametrize("detach", ["nn", "self", "none"])
def test_mosca_arap_float64(reduce, square, detach):
    xyz, q, ti, mask, lv = mosca_scene()
    e, w, mu, _, _ = lv[0]
    lv = ((e, w, mu, detach == "nn", detach == "self"),)
    (c, l, gx, gq), (rc, rl, rgx, rgq) = _arap_both(xyz, q, ti, mask, lv, reduce, square)
    assert float(rc) > 0 and float(rl) > 0
    assert abs(float(c) - float(rc)) <= 1e-9 * float(rc)
    assert abs(float(l) - float(rl)) <= 1e-9 * float(rl)
    assert _rel(gx, rgx) <= 1e-7
    assert _rel(gq, rgq) <= 1e-7


@pytest.mark.parametrize("stop", ["none", "neighbor", "row"])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_rigid_frame_neighbor_is_moscas_local_coordinate(stop, dtype):
    # smg's ARAP with frame="neighbor" (E24) on MoSca's own rows (no reversed graph): d = R_j^T
    # (x_j − x_i) = −ℓ, the same norms; detach_nn (x_j held) is stop_gradient="neighbor",
    # detach_self (x_i held) "row". Sum over the shifts, both parts, against the plain-torch
    # reading of get_local_coord and compute_arap.
    xyz, q, ti, mask, _ = mosca_scene(T=12, M=48, K=10, seed=3, levels=False)
    M, K = ti.shape
    w_rows = mask.double() / (mask.double().sum(-1, keepdim=True) + 1e-6)
    keep = mask & (ti != torch.arange(M)[:, None])  # smg refuses self edges (each adds exactly 0)
    D = int(keep.sum(-1).max())
    idx = torch.full((M, D), -1, dtype=torch.int64)
    w = torch.zeros((M, D), dtype=dtype)
    for i in range(M):
        js = ti[i][keep[i]]
        idx[i, :js.numel()] = js
        w[i, :js.numel()] = w_rows[i][keep[i]].to(dtype)
    x = xyz.detach().clone().to(dtype).requires_grad_()
    r = q.detach().clone().to(dtype).requires_grad_()
    e = smg.regularizers(x, r, (idx, w), confidence=False, carap=False, lrm=False,
                         arap=dict(frame="neighbor", penalty="norm", stop_gradient=stop, gaps=SHIFTS,
                                   gap_weights=GAMMAS, lambda_c=1.0, lambda_l=0.5)).total
    e.backward()
    x64 = xyz.detach().clone().requires_grad_()
    r64 = q.detach().clone().requires_grad_()
    R = quaternion_to_matrix(F.normalize(r64, dim=-1))
    local = mosca_local_coord_torch(x64, R, torch.arange(M)[:, None].expand_as(ti), ti,
                                    detach_self=stop == "row", detach_nn=stop == "neighbor")
    c, l = mosca_shift_losses_torch(local, w_rows, SHIFTS, GAMMAS, "sum", False)
    ref = c + 0.5 * l
    ref.backward()
    tol_e, tol_g = (1e-12, 1e-10) if dtype == torch.float64 else (1e-5, 1e-4)
    assert float(ref) > 0
    assert abs(float(e) - float(ref)) <= tol_e * float(ref)
    assert _rel(x.grad.double(), x64.grad) <= tol_g
    assert _rel(r.grad.double(), r64.grad) <= tol_g
    # ... and the row's frame is another energy.
    other = smg.regularizers(xyz, q, (idx, w.double()), confidence=False, carap=False, lrm=False,
                             arap=dict(penalty="norm", gaps=SHIFTS, gap_weights=GAMMAS, lambda_l=0.5)).total
    assert abs(float(other) - float(ref)) > 1e-3 * float(ref)


@pytest.mark.parametrize("lam", [(-1.0, 2.5), (0.0, 1.0), (3.0, 0.0), (-2.0, -0.5)])
def test_mosca_arap_any_loss_weights(lam):
    # Backward forms λc = g_coord, λl = g_len in one pass (two where one is negative): any
    # weighting of the two losses, zero and negative included, gives torch's gradient.
    xyz, q, ti, mask, lv = mosca_scene(T=10, M=40, K=8, seed=8)
    (c, l, gx, gq), (rc, rl, rgx, rgq) = _arap_both(xyz, q, ti, mask, lv, "mean", False, lam=lam)
    # The length part does not depend on the rotations: torch's q gradient is round-off (1e-20)
    # where smg's is 0, so both are held to the scale of the whole gradient.
    scale = max(float(rgx.abs().max()), float(rgq.abs().max()))
    assert float((gx - rgx).abs().max()) <= 1e-7 * scale
    assert float((gq - rgq).abs().max()) <= 1e-7 * scale


def test_mosca_arap_float32():
    xyz, q, ti, mask, lv = mosca_scene(seed=1)
    (c, l, gx, gq), _ = _arap_both(xyz, q, ti, mask, lv, "mean", False, dtype=torch.float32)
    (rc, rl, rgx, rgq), _ = _arap_both(xyz, q, ti, mask, lv, "mean", False)
    assert c.dtype == torch.float32 and gx.dtype == torch.float32
    assert abs(float(c) - float(rc)) <= 1e-5 * float(rc)
    assert abs(float(l) - float(rl)) <= 1e-5 * float(rl)
    assert _rel(gx, rgx) <= 1e-4 and _rel(gq, rgq) <= 1e-4


def test_mosca_arap_hard_cases():
    # A rigid window (every frame the first): both losses 0 and torch's gradient exactly 0.
    xyz, q, ti, mask, lv = mosca_scene(T=8, seed=2)
    xyz, q = xyz[:1].expand_as(xyz).clone(), q[:1].expand_as(q).clone()
    (c, l, gx, gq), (rc, rl, rgx, rgq) = _arap_both(xyz, q, ti, mask, lv, "mean", False)
    assert float(rc) == 0.0 and float(rl) == 0.0
    assert torch.equal(rgx, torch.zeros_like(rgx)) and torch.equal(rgq, torch.zeros_like(rgq))
    assert float(c) == 0.0 and float(l) == 0.0
    assert torch.equal(gx, torch.zeros_like(gx)) and torch.equal(gq, torch.zeros_like(gq))
    # A window shorter than the longest shift (T = 4: shift 6 adds nothing), a row whose mask is
    # all false (self included), a zero-weight level edge, nodes that are nobody's neighbour.
    xyz, q, ti, mask, lv = mosca_scene(T=4, M=40, seed=3)
    mask[5] = False
    (c, l, gx, gq), (rc, rl, rgx, rgq) = _arap_both(xyz, q, ti, mask, lv, "mean", False)
    assert abs(float(c) - float(rc)) <= 1e-9 * float(rc)
    assert abs(float(l) - float(rl)) <= 1e-9 * float(rl)
    assert _rel(gx, rgx) <= 1e-7 and _rel(gq, rgq) <= 1e-7
    # Every shift at least the window: upstream's zeros.
    c, l = mosca_arap(xyz[:1], q[:1], ti, mask, SHIFTS, GAMMAS)
    assert float(c) == 0.0 and float(l) == 0.0


@pytest.mark.parametrize("reduce", ["mean", "sum"])
@pytest.mark.parametrize("square", [False, True])
def test_mosca_vel_acc_float64(reduce, square):
    xyz, q, _, _, _ = mosca_scene(T=12, M=30, seed=4, levels=False)
    for k in range(4):  # each loss differentiable on its own
        a = xyz.clone().requires_grad_(), q.clone().requires_grad_()
        b = xyz.clone().requires_grad_(), q.clone().requires_grad_()
        va = mosca_vel_acc(*a, reduce=reduce, square=square)
        vb = mosca_vel_acc_torch(*b, reduce, square)
        assert float(vb[k]) > 0
        assert abs(float(va[k]) - float(vb[k])) <= 1e-9 * float(vb[k])
        va[k].backward()
        vb[k].backward()
        for ga, gb in zip((a[0].grad, a[1].grad), (b[0].grad, b[1].grad)):
            if gb is None or not gb.abs().max() > 0:
                assert ga is None or torch.equal(ga, torch.zeros_like(ga))
            else:
                assert _rel(ga, gb) <= 1e-7


def test_mosca_vel_acc_constant_rotation_and_still_node():
    # Node 0 keeps its rotation (θ = 0: torch's gradient there is exactly 0) and its position.
    xyz, q, _, _, _ = mosca_scene(T=9, M=12, K=6, seed=5, levels=False)
    q[:, 0] = q[0, 0]
    xyz[:, 0] = xyz[0, 0]
    a = xyz.clone().requires_grad_(), q.clone().requires_grad_()
    b = xyz.clone().requires_grad_(), q.clone().requires_grad_()
    sum(mosca_vel_acc(*a)).backward()
    sum(mosca_vel_acc_torch(*b)).backward()
    assert torch.equal(b[1].grad[:, 0], torch.zeros_like(b[1].grad[:, 0]))  # the premise
    assert torch.equal(a[1].grad[:, 0], torch.zeros_like(a[1].grad[:, 0]))
    assert torch.equal(a[0].grad[:, 0], torch.zeros_like(a[0].grad[:, 0]))
    assert _rel(a[0].grad, b[0].grad) <= 1e-7 and _rel(a[1].grad, b[1].grad) <= 1e-7


@pytest.mark.parametrize("call,match", [
    (lambda x, q, ti, m: mosca_arap(x, q[:, :5], ti, m, SHIFTS, GAMMAS), "node_quat: expected shape"),
    (lambda x, q, ti, m: mosca_arap(x, q.float(), ti, m, SHIFTS, GAMMAS), "node_quat: dtype"),
    (lambda x, q, ti, m: mosca_arap(x, q, ti, m.float(), SHIFTS, GAMMAS), "topo_mask: expected a bool tensor"),
    (lambda x, q, ti, m: mosca_arap(x, q, ti.float(), m, SHIFTS, GAMMAS), "topo_ind: expected an int32 or int64"),
    (lambda x, q, ti, m: mosca_arap(x, q, ti + 100, m, SHIFTS, GAMMAS), "topo_ind: entries must lie in"),
    (lambda x, q, ti, m: mosca_arap(x, q, ti, m, SHIFTS, GAMMAS[:2]), "shift_weights: 2 weights for 3 shifts"),
    (lambda x, q, ti, m: mosca_arap(x, q, ti, m, [-1, 1, 2], GAMMAS), r"shifts\[0\]: is -1; a negative shift"),
    (lambda x, q, ti, m: mosca_arap(x, q, ti, m, SHIFTS, GAMMAS, reduce="max"), "reduce: must be"),
    (lambda x, q, ti, m: mosca_arap(x, q, ti, m, SHIFTS, GAMMAS,
                                    levels=((ti[:, :2], torch.ones(len(ti)), 1.0, True, True),)), "exclusive"),
    (lambda x, q, ti, m: mosca_arap(x, torch.zeros_like(q), ti, m, SHIFTS, GAMMAS),
     r"node_quat\[0, 0\] is the zero quaternion"),
    (lambda x, q, ti, m: mosca_vel_acc(x[:2], q[:2]), "node_xyz: needs T >= 3"),
    (lambda x, q, ti, m: mosca_vel_acc(x.int(), q), "node_xyz: dtype"),
])
def test_mosca_refuses_bad_arguments(call, match):
    xyz, q, ti, mask, _ = mosca_scene(T=6, M=20, K=6, seed=6, levels=False)
    with pytest.raises(ValueError, match=match):
        call(xyz, q, ti, mask)


@cuda
@pytest.mark.parametrize("dtype,tol_e,tol_g", [(torch.float64, 1e-9, 1e-7), (torch.float32, 1e-5, 1e-4)])
def test_mosca_cuda(dtype, tol_e, tol_g):
    xyz, q, ti, mask, lv = mosca_scene(seed=7)
    dev = lambda t: t.to(dtype).cuda()  # noqa: E731
    lvc = tuple((e.cuda(), w.cuda(), mu, dn, ds) for e, w, mu, dn, ds in lv)
    x, r = dev(xyz).requires_grad_(), dev(q).requires_grad_()
    c, l = mosca_arap(x, r, ti.cuda(), mask.cuda(), SHIFTS, GAMMAS, levels=lvc)
    (c + l + sum(mosca_vel_acc(x, r))).backward()
    x2, r2 = xyz.clone().requires_grad_(), q.clone().requires_grad_()
    rc, rl = mosca_arap_torch(x2, r2, ti, mask, SHIFTS, GAMMAS, levels=lv)
    (rc + rl + sum(mosca_vel_acc_torch(x2, r2))).backward()
    assert abs(float(c) - float(rc)) <= tol_e * float(rc)
    assert _rel(x.grad.cpu(), x2.grad) <= tol_g and _rel(r.grad.cpu(), r2.grad) <= tol_g
