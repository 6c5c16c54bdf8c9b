"""smg_torch.compat.scgs_arap against a plain-torch implementation of SC-GS's ARAP loss written here
from a reading of yihua7/SC-GS (commit 0986d0a, utils/deform_utils.py: produce_edge_matrix_nfmt
l.35-42, cal_connectivity_from_points l.58-110, estimate_rotation l.130-166, cal_arap_error
l.177-205; utils/time_utils.py ControlNodeWarp.arap_loss, which passes cal_arap_error the
connectivity of the first frame's nodes and weight=None): values and gradients in float64 and
float32, rigid motions, the "unchanged rows" rule of l.148, the det flip of l.158-163, weight-0
edges, bad arguments and CUDA (skipped without a device). docs/compat.md quotes the figures."""
import pytest
import torch

import smg_torch as smg
from smg_torch.compat import scgs_arap

cuda = pytest.mark.skipif(not (torch.cuda.is_available() and smg.has_cuda),
                          reason="no CUDA device or smg_torch built without CUDA")


# ---- the upstream pipeline, in plain torch (pytorch3d's knn_points -> cdist + topk, no .cuda()) ----

def connectivity(points, radius=0.1, K=10, least_edge_num=3):
    """cal_connectivity_from_points(points, radius, K) in its default mode ('nn', no trajectory,
    adaptive_weighting=True): the K nearest other nodes by squared distance; from the
    (least_edge_num + 1)-th on, those at squared distance >= radius² are dropped (index -1,
    distance inf); weights exp(−d² / mean d²) normalised per row. Returns the flat edge lists
    ii, jj, nn (row, neighbour, slot) of the kept neighbours and the [Nv, K] weights."""
    Nv = points.shape[0]
    d2 = torch.cdist(points, points, compute_mode="donot_use_mm_for_euclid_dist") ** 2
    dist, idx = d2.topk(K + 1, dim=1, largest=False)
    dist, idx = dist[:, 1:].clone(), idx[:, 1:].clone()  # column 0 is the node itself (d² = 0)
    far = dist[:, least_edge_num:] >= radius ** 2
    idx[:, least_edge_num:][far] = -1
    dist[:, least_edge_num:][far] = float("inf")
    weight = torch.exp(-dist / dist.mean())
    weight = weight / weight.sum(dim=-1, keepdim=True)
    rows = torch.arange(Nv)[:, None].expand(Nv, K).reshape(-1)
    slots = torch.arange(K)[None, :].expand(Nv, K).reshape(-1)
    cols = idx.reshape(-1)
    valid = cols >= 0
    return rows[valid], cols[valid], slots[valid], weight


def edge_matrix(verts, K, ii, jj, nn):
    """produce_edge_matrix_nfmt: slot (i, n) holds verts[i] − verts[j], the other slots 0, in the
    verts' dtype (upstream allocates in torch's default dtype, float64 in this suite, conftest.py;
    under float32 its index assignment refuses float64 verts)."""
    E = torch.zeros(verts.shape[0], K, 3, dtype=verts.dtype)
    E[ii, nn] = verts[ii] - verts[jj]
    return E


def procrustes(source, target, ii, jj, nn, K, weight, stats=None):
    """estimate_rotation: per row, the rotation R with target edges ≈ R · source edges."""
    A = edge_matrix(source, K, ii, jj, nn)
    B = edge_matrix(target, K, ii, jj, nn)
    S = torch.einsum("nka,nk,nkb->nab", A, weight, B)  # Σ_k w_k a_k b_kᵀ
    # l.148: a row is "unchanged" when, for at least one coordinate, all K slots agree exactly.
    unchanged = torch.zeros(A.shape[0], dtype=torch.bool)
    for c in range(3):
        unchanged |= (A[:, :, c] == B[:, :, c]).all(dim=1)
    S[unchanged] = 0
    U, sig, V = torch.svd(S)
    R = V @ U.transpose(1, 2)
    flip = torch.det(R) <= 0
    if stats is not None:
        stats["unchanged"] = stats.get("unchanged", 0) + int(unchanged.sum())
        stats["flipped"] = stats.get("flipped", 0) + int(flip.sum())
    for i in torch.nonzero(flip).flatten().tolist():
        u = U[i].clone()
        u[:, int(torch.argmin(sig[i]))] *= -1
        R[i] = V[i] @ u.T
    return R


def cal_arap_error_torch(nodes_sequence, ii, jj, nn, K=10, weight=None, stats=None):
    """cal_arap_error for Nv <= sample_num (every row kept): Σ_t Σ_i Σ_n w_in ‖e^t − R_i^t e^0‖²
    with R^t from frame 0 to t under no_grad, the norm squared as upstream writes it."""
    Nt, Nv, _ = nodes_sequence.shape
    if weight is None:
        weight = torch.zeros(Nv, K, dtype=nodes_sequence.dtype)
        weight[ii, nn] = 1
    E0 = edge_matrix(nodes_sequence[0], K, ii, jj, nn)
    total = 0
    for t in range(1, Nt):
        with torch.no_grad():
            R = procrustes(nodes_sequence[0], nodes_sequence[t], ii, jj, nn, K, weight, stats)
        Et = edge_matrix(nodes_sequence[t], K, ii, jj, nn)
        stretch = Et - torch.einsum("nab,nkb->nka", R, E0)
        total = total + (weight * stretch.norm(dim=2) ** 2).sum()
    return total


# ---- helpers ----

def _rel(a, b):
    """Largest difference relative to the largest reference value."""
    return float((a.double() - b.double()).abs().max() / b.double().abs().max().clamp_min(1e-300))


def _erel(a, b):
    return abs(float(a) - float(b)) / abs(float(b))


def _report(case, ea, ga, eb, gb):
    """One line of the agreement figures (pytest -s shows it; docs/compat.md copies a run)."""
    print(f"\nscgs agreement | {case} | {_erel(ea, eb):.1e} | {_rel(ga, gb):.1e} |")


def _both(seq, ii, jj, nn, K=10, weight=None):
    """(value, gradient) of scgs_arap and of the reference on copies of seq."""
    a = seq.detach().clone().requires_grad_()
    b = seq.detach().clone().requires_grad_()
    ea = scgs_arap(a, ii, jj, nn, K, weight)
    eb = cal_arap_error_torch(b, ii, jj, nn, K, weight)
    ea.backward()
    eb.backward()
    return ea, a.grad, eb, b.grad


def _scene(M=300, Nt=2, seed=0, dtype=torch.float64):
    """M nodes uniform in a 0.5-cube (at M = 300, 40 % of the 4th to 10th neighbours lie beyond
    radius 0.1: a tenth of the 4th, two thirds of the 10th), moved non-rigidly: a rotation growing
    with t, a smooth bend and noise."""
    g = torch.Generator().manual_seed(seed)
    x0 = torch.rand(M, 3, generator=g, dtype=torch.float64) * 0.5
    frames = [x0]
    for t in range(1, Nt):
        a = 0.3 * t
        Rz = torch.tensor([[torch.cos(torch.tensor(a)), -torch.sin(torch.tensor(a)), 0],
                           [torch.sin(torch.tensor(a)), torch.cos(torch.tensor(a)), 0], [0, 0, 1]],
                          dtype=torch.float64)
        bend = 0.05 * t * torch.stack([torch.sin(6 * x0[:, 1]), torch.cos(5 * x0[:, 2]),
                                       torch.sin(4 * x0[:, 0])], 1)
        noise = 0.01 * torch.randn(M, 3, generator=g, dtype=torch.float64)
        frames.append(x0 @ Rz.T + bend + noise + 0.1 * t)
    seq = torch.stack(frames).to(dtype)
    ii, jj, nn, w = connectivity(seq[0].double())
    return seq, ii, jj, nn, w


# ---- tests ----

def test_scene_has_neighbours_beyond_the_radius():
    # The premise of the agreement tests: slots 4-10 are sometimes dropped, never 1-3.
    seq, ii, jj, nn, _ = _scene()
    per_slot = torch.bincount(nn, minlength=10)
    assert per_slot[:3].tolist() == [300, 300, 300]
    assert int(per_slot[3]) < 300 and int(per_slot[9]) < 300 and int(per_slot[9]) > 0
    assert ii.shape[0] < 3000


@pytest.mark.parametrize("Nt", [2, 3])
def test_scgs_arap_float64(Nt):
    seq, ii, jj, nn, _ = _scene(Nt=Nt, seed=Nt)
    ea, ga, eb, gb = _both(seq, ii, jj, nn)
    _report(f"float64, M = 300, Nt = {Nt}", ea, ga, eb, gb)
    assert ea.dim() == 0 and ea.dtype == torch.float64
    assert float(eb) > 0
    assert _erel(ea, eb) <= 1e-9
    assert ga.shape == seq.shape
    assert float(gb.abs().max()) > 0
    assert _rel(ga, gb) <= 1e-7


@pytest.mark.parametrize("Nt", [2, 3])
def test_scgs_arap_float32(Nt):
    seq, ii, jj, nn, _ = _scene(Nt=Nt, seed=10 + Nt, dtype=torch.float32)
    ea, ga, eb, gb = _both(seq, ii, jj, nn)
    _report(f"float32, M = 300, Nt = {Nt}", ea, ga, eb, gb)
    assert ea.dtype == torch.float32 and ga.dtype == torch.float32
    ref = cal_arap_error_torch(seq.double(), ii, jj, nn)  # the float64 value of the same input
    assert abs(float(ea) - float(ref)) <= 1e-5 * float(ref)
    assert abs(float(ea) - float(eb)) <= 1e-5 * float(ref)
    assert _rel(ga, gb) <= 1e-4


def test_scgs_arap_with_weights_and_a_zero_weight_edge():
    seq, ii, jj, nn, _ = _scene(Nt=3, seed=4)
    g = torch.Generator().manual_seed(5)
    w = torch.rand(300, 10, generator=g, dtype=torch.float64) + 0.1
    w[7, 2] = 0.0  # an edge (row 7, slot 2 is always kept) of weight 0
    ea, ga, eb, gb = _both(seq, ii, jj, nn, weight=w)
    _report("float64, weights in [0.1, 1.1) and one 0, Nt = 3", ea, ga, eb, gb)
    assert _erel(ea, eb) <= 1e-9
    assert _rel(ga, gb) <= 1e-7
    # The same edges without that one: the same energy (a weight-0 edge adds nothing, to S or to
    # the sum) up to rounding.
    keep = ~((ii == 7) & (nn == 2))
    assert int((~keep).sum()) == 1
    ec = scgs_arap(seq, ii[keep], jj[keep], nn[keep], 10, w)
    assert _erel(ec, ea) <= 1e-12
    # Weights differ from upstream's default (1 on the edges): so does the energy.
    assert _erel(scgs_arap(seq, ii, jj, nn), ea) > 1e-3


def test_scgs_arap_self_edges_are_dropped():
    # A self edge (ii = jj) is 0 in every frame: it adds nothing upstream; smg refuses self edges,
    # scgs_arap drops them.
    seq, ii, jj, nn, _ = _scene(M=40, Nt=2, seed=6)
    K = 11  # a free slot 10 in every row
    ii2 = torch.cat([ii, torch.arange(40)])
    jj2 = torch.cat([jj, torch.arange(40)])
    nn2 = torch.cat([nn, torch.full((40,), 10)])
    ea, ga, eb, gb = _both(seq, ii2, jj2, nn2, K)
    assert _erel(ea, eb) <= 1e-9 and _rel(ga, gb) <= 1e-7
    ref = cal_arap_error_torch(seq, ii, jj, nn, K)
    assert _erel(ea, ref) <= 1e-12


def test_scgs_arap_rigid_motion():
    # A rotation about an axis off every coordinate axis plus a translation: each row's Procrustes
    # rotation is the motion's rotation, the energy is 0 up to rounding (against Σ w ‖e‖²).
    seq, ii, jj, nn, _ = _scene(Nt=2, seed=7)
    x0 = seq[0]
    axis = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    axis = axis / axis.norm()
    ang = torch.tensor(0.7, dtype=torch.float64)
    Kx = torch.tensor([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    Q = torch.eye(3, dtype=torch.float64) + torch.sin(ang) * Kx + (1 - torch.cos(ang)) * Kx @ Kx
    seq = torch.stack([x0, x0 @ Q.T + torch.tensor([0.3, -0.2, 0.1], dtype=torch.float64)])
    stats = {}
    ea, ga, eb, gb = _both(seq, ii, jj, nn)
    cal_arap_error_torch(seq, ii, jj, nn, stats=stats)
    assert stats == {"unchanged": 0, "flipped": 0}
    scale = float((edge_matrix(x0, 10, ii, jj, nn) ** 2).sum())
    print(f"\nscgs rigid motion | smg {float(ea):.1e}, torch {float(eb):.1e} (Σ w ‖e‖² = {scale:.3g}) | "
          f"largest gradient entry smg {float(ga.abs().max()):.1e}, torch {float(gb.abs().max()):.1e} |")
    assert 0 <= float(ea) <= 1e-26 * scale
    assert 0 <= float(eb) <= 1e-26 * scale
    assert float(ga.abs().max()) <= 1e-13 and float(gb.abs().max()) <= 1e-13


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_scgs_arap_dyadic_translation_is_exactly_zero(dtype):
    # Dyadic nodes and a dyadic translation: every edge is bitwise equal in both frames, so every
    # row is "unchanged" (l.148), S = 0, R = I, and the energy and every gradient entry are 0.
    g = torch.Generator().manual_seed(8)
    x0 = torch.randint(0, 64, (200, 3), generator=g).to(dtype) / 128
    seq = torch.stack([x0, x0 + torch.tensor([0.25, -0.5, 0.125], dtype=dtype)])
    ii, jj, nn, _ = connectivity(x0.double())
    ea, ga, eb, gb = _both(seq, ii, jj, nn)
    assert float(ea) == 0.0 and float(eb) == 0.0
    assert torch.equal(ga, torch.zeros_like(ga)) and torch.equal(gb, torch.zeros_like(gb))


def test_scgs_arap_unchanged_rows_rule():
    # l.148 tests, per row, whether SOME coordinate of all K slots is unchanged, not all three: a
    # rotation about z that keeps every z bitwise makes every row "unchanged", so upstream uses
    # R = I and the loss is Σ w ‖e^1 − e^0‖² (large), not ~0 as a true Procrustes fit would give.
    seq, ii, jj, nn, _ = _scene(Nt=2, seed=9)
    x0 = seq[0]
    c, s = 0.8, 0.6
    x1 = torch.stack([c * x0[:, 0] - s * x0[:, 1], s * x0[:, 0] + c * x0[:, 1], x0[:, 2]], 1)
    seq = torch.stack([x0, x1])
    stats = {}
    ea, ga, eb, gb = _both(seq, ii, jj, nn)
    cal_arap_error_torch(seq, ii, jj, nn, stats=stats)
    _report("float64, rotation about z keeping z (l.148: every row unchanged)", ea, ga, eb, gb)
    assert stats == {"unchanged": 300, "flipped": 0}
    plain = float(((edge_matrix(x1, 10, ii, jj, nn) - edge_matrix(x0, 10, ii, jj, nn)) ** 2).sum())
    assert plain > 1.0
    assert _erel(ea, plain) <= 1e-12 and _erel(eb, plain) <= 1e-12
    assert _rel(ga, gb) <= 1e-7
    # One node's z moved: its rows and its neighbours' rows get a proper fit, the rest keep R = I.
    seq2 = seq.clone()
    seq2[1, 0, 2] += 1e-3
    stats = {}
    ea, ga, eb, gb = _both(seq2, ii, jj, nn)
    cal_arap_error_torch(seq2, ii, jj, nn, stats=stats)
    assert 250 < stats["unchanged"] < 300
    assert _erel(ea, eb) <= 1e-9 and _rel(ga, gb) <= 1e-7


def test_scgs_arap_reflection_flips():
    # A mirror image across a plane off the coordinate planes: the unconstrained fit of every row
    # is a reflection (det V Uᵀ = −1), so l.158-163 flip the smallest singular value's column.
    seq, ii, jj, nn, _ = _scene(Nt=2, seed=10)
    x0 = seq[0]
    nrm = torch.tensor([1.0, 1.0, 1.0], dtype=torch.float64) / 3 ** 0.5
    x1 = x0 - 2 * (x0 @ nrm)[:, None] * nrm[None, :]
    g = torch.Generator().manual_seed(11)
    x1 = x1 + 1e-3 * torch.randn(x1.shape, generator=g, dtype=torch.float64)
    seq = torch.stack([x0, x1])
    stats = {}
    ea, ga, eb, gb = _both(seq, ii, jj, nn)
    cal_arap_error_torch(seq, ii, jj, nn, stats=stats)
    _report("float64, mirror image (l.158-163: every row flipped)", ea, ga, eb, gb)
    assert stats["flipped"] == 300 and stats["unchanged"] == 0
    assert float(eb) > 0
    assert _erel(ea, eb) <= 1e-9
    assert _rel(ga, gb) <= 1e-7


def test_scgs_arap_gradcheck():
    # The rotations are constants (no_grad), but each is the optimal rotation of its row, so the
    # loss's derivative along R is 0 there (envelope theorem): the finite differences of the whole
    # loss, rotations re-estimated, agree with the constant-rotation gradient.
    seq, ii, jj, nn, _ = _scene(M=24, Nt=3, seed=12)
    x = seq.clone().requires_grad_()
    assert torch.autograd.gradcheck(lambda s: scgs_arap(s, ii, jj, nn), (x,), eps=1e-6, atol=1e-7,
                                    rtol=1e-5)


def test_scgs_arap_trainer_call_and_no_grad():
    # ControlNodeWarp.arap_loss: nodes_t [M, T, 3] permuted to [T, M, 3], connectivity of the
    # first frame, weight=None (its weights are discarded), times lambda_arap.
    seq, ii, jj, nn, _ = _scene(M=120, Nt=2, seed=13)
    nodes_t = seq.permute(1, 0, 2).contiguous().requires_grad_()
    ii2, jj2, nn2, _ = connectivity(nodes_t[:, 0].detach(), K=10)
    loss = 0.5 * scgs_arap(nodes_t.permute(1, 0, 2), ii2, jj2, nn2)
    loss.backward()
    b = nodes_t.detach().clone().requires_grad_()
    (0.5 * cal_arap_error_torch(b.permute(1, 0, 2), ii2, jj2, nn2)).backward()
    assert _rel(nodes_t.grad, b.grad) <= 1e-7
    assert not scgs_arap(seq, ii, jj, nn).requires_grad
    # int32 indices read the same.
    e32 = scgs_arap(seq, ii.int(), jj.int(), nn.int())
    assert float(e32) == float(scgs_arap(seq, ii, jj, nn))


def test_scgs_arap_adaptive_weights_with_far_neighbours_are_refused():
    # cal_connectivity_from_points' own weights: mean d² is inf once a neighbour is dropped, so
    # exp(−inf / inf) is NaN in those rows (l.96, l.102); passed on, they make S NaN and torch's
    # SVD fails (on CPU; the trainer discards these weights). scgs_arap refuses them.
    seq, ii, jj, nn, w = _scene(Nt=2, seed=14)
    assert bool(torch.isnan(w).any()) and bool(torch.isfinite(w).any())
    with pytest.raises(RuntimeError, match="non-finite"):
        cal_arap_error_torch(seq, ii, jj, nn, weight=w)
    with pytest.raises(ValueError, match=r"weight\[\d+, \d+\] is nan"):
        scgs_arap(seq, ii, jj, nn, weight=w)


def test_scgs_arap_refuses_more_than_512_nodes():
    g = torch.Generator().manual_seed(15)
    x = torch.rand(2, 513, 3, generator=g, dtype=torch.float64)
    ii, jj, nn, _ = connectivity(x[0])
    with pytest.raises(ValueError, match=r"nodes_sequence: Nv = 513 nodes > 512 .*sample_num=None sums every node"):
        scgs_arap(x, ii, jj, nn)
    with pytest.raises(ValueError, match=r"nodes_sequence: Nv = 513 nodes > 100"):
        scgs_arap(x, ii, jj, nn, sample_num=100)
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match=r"sample_num: expected an int >= 1 or None"):
            scgs_arap(x, ii, jj, nn, sample_num=bad)
    # 512 is still one deterministic sum.
    x = x[:, :512]
    ii, jj, nn, _ = connectivity(x[0])
    ea, ga, eb, gb = _both(x, ii, jj, nn)
    _report("float64, M = 512, Nt = 2", ea, ga, eb, gb)
    assert _erel(ea, eb) <= 1e-9 and _rel(ga, gb) <= 1e-7


_X = torch.rand(2, 5, 3)
_I = torch.tensor([0, 1, 2, 3, 4])
_J = torch.tensor([1, 2, 3, 4, 0])
_N = torch.tensor([0, 0, 0, 0, 0])


@pytest.mark.parametrize("args,match", [
    (([[0.0] * 3] * 5, _I, _J, _N), "nodes_sequence: expected a torch.Tensor"),
    ((torch.rand(5, 3), _I, _J, _N), r"nodes_sequence: expected shape \[Nt, Nv, 3\]"),
    ((torch.rand(2, 5, 2), _I, _J, _N), r"nodes_sequence: expected shape \[Nt, Nv, 3\]"),
    ((torch.zeros(2, 5, 3, dtype=torch.int64), _I, _J, _N), "nodes_sequence: dtype must be float32"),
    ((torch.zeros(2, 5, 3, dtype=torch.float16), _I, _J, _N), "nodes_sequence: dtype must be float32"),
    ((torch.rand(1, 5, 3), _I, _J, _N), "nodes_sequence: needs Nt >= 2"),
    ((torch.rand(2, 0, 3), _I[:0], _J[:0], _N[:0]), "nodes_sequence: has no nodes"),
    ((torch.full((2, 5, 3), float("nan")), _I, _J, _N), r"nodes_sequence\[0, 0\] has a NaN"),
    ((_X, _I, _J, _N, 0), "K: expected an int >= 1"),
    ((_X, _I, _J, _N, 2.0), "K: expected an int >= 1"),
    ((_X, [0, 1], _J, _N), "ii: expected a torch.Tensor"),
    ((_X, _I[None], _J, _N), r"ii: expected shape \[Ne\]"),
    ((_X, _I.double(), _J, _N), "ii: dtype must be int32 or int64"),
    ((_X, _I, _J[:4], _N), "jj: expected 5 entries"),
    ((_X, _I, _J, _N[:4]), "nn: expected 5 entries"),
    ((_X, _I + 1, _J, _N), r"ii\[\d+\] = 5 is not a node in \[0, Nv = 5\)"),
    ((_X, _I, _J - 1, _N), r"jj\[\d+\] = -1 is not a node in \[0, Nv"),
    ((_X, _I, _J, _N + 10), r"nn\[\d+\] = 1\d is not a neighbour slot in \[0, K = 10\)"),
    ((_X, torch.tensor([0, 0]), torch.tensor([1, 2]), torch.tensor([3, 3])), "nn: a slot"),
    ((_X, _I, _J, _N, 10, torch.ones(5, 9)), r"weight: expected shape \[Nv, K\] = \[5, 10\]"),
    ((_X, _I, _J, _N, 10, torch.ones(5, 10, dtype=torch.int64)), "weight: dtype must be float32"),
    ((_X, _I, _J, _N, 10, [[1.0] * 10] * 5), "weight: expected a torch.Tensor"),
    ((_X, _I, _J, _N, 10, torch.full((5, 10), float("inf"))), r"weight\[0, 0\] is inf"),
])
def test_scgs_arap_refuses_bad_arguments(args, match):
    with pytest.raises(ValueError, match=match):
        scgs_arap(*args)


def test_scgs_arap_negative_weight_off_the_edges_is_ignored():
    # A weight in a slot that holds no edge multiplies a zero stretch upstream: accepted, no effect.
    w = torch.ones(5, 10)
    w[:, 5:] = -3.0
    assert float(scgs_arap(_X, _I, _J, _N, 10, w)) == float(scgs_arap(_X, _I, _J, _N))


def test_scgs_arap_refuses_cuda_without_cuda_build():
    if smg.has_cuda or not torch.cuda.is_available():
        pytest.skip("needs a CUDA device and an smg_torch built without CUDA")
    with pytest.raises(NotImplementedError, match="nodes_sequence"):
        scgs_arap(_X.cuda(), _I, _J, _N)


@cuda
@pytest.mark.parametrize("dtype,tol_e,tol_g", [(torch.float64, 1e-9, 1e-7), (torch.float32, 1e-5, 1e-4)])
@pytest.mark.parametrize("Nt", [2, 3])
def test_scgs_arap_cuda(dtype, tol_e, tol_g, Nt):
    seq, ii, jj, nn, _ = _scene(Nt=Nt, seed=20 + Nt, dtype=dtype)
    a = seq.cuda().requires_grad_()
    ea = scgs_arap(a, ii.cuda(), jj.cuda(), nn.cuda())
    ea.backward()
    assert ea.device.type == "cuda" and a.grad.device.type == "cuda"
    _, _, eb, gb = _both(seq, ii, jj, nn)
    ref = float(cal_arap_error_torch(seq.double(), ii, jj, nn))
    assert abs(float(ea) - float(eb)) <= tol_e * ref
    assert _rel(a.grad.cpu(), gb) <= tol_g


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_scgs_arap_every_node_past_sample_num(dtype):
    """sample_num=None: every row at Nv = 2000 (4x SC-GS's sample), against the reading summing
    every row (its Nv <= sample_num branch), float64 to 1e-9 / 1e-7, float32 to the float64 reading."""
    seq, ii, jj, nn, w = _scene(M=2000, Nt=3, seed=21)
    a = seq.to(dtype).detach().clone().requires_grad_()
    b = seq.detach().clone().requires_grad_()
    ea = scgs_arap(a, ii, jj, nn, sample_num=None)
    eb = cal_arap_error_torch(b, ii, jj, nn)
    ea.backward()
    eb.backward()
    _report(f"{dtype}, M = 2000, Nt = 3, sample_num=None", ea, a.grad, eb, b.grad)
    tol_e, tol_g = (1e-9, 1e-7) if dtype == torch.float64 else (1e-4, 1e-3)
    assert _erel(ea, eb) <= tol_e and _rel(a.grad, b.grad) <= tol_g
    # At Nv <= sample_num both readings are upstream's full sum: the same value either way.
    small = seq[:, :400].detach()
    i4, j4, n4, _ = connectivity(small[0].double())
    assert torch.equal(scgs_arap(small, i4, j4, n4), scgs_arap(small, i4, j4, n4, sample_num=None))
