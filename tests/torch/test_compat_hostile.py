"""smg_torch.compat as a hostile user meets it (issue 61), every call by one list (CALLS), each
class of input once per call: refusals name the caller's argument and index, before any work;
what upstream accepts is accepted and agrees with the plain-torch readings of test_compat*.py
(self edges, negative weights, shift lists as tensors, shift 0); upstream's degenerate means are
refused with the reason; tensors with torch's negative or conjugate bit read as their values;
sparse tensors are refused by name; a second-order backward (create_graph=True) raises at once
for every smg_torch operator, naming the operator the caller called; and a refused call leaves
nothing behind (a valid call is bitwise the same before and after a batch of refused ones).
CPU; the CUDA checks of these calls are in test_compat*.py (skipped without a device)."""
import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

import smg_torch as smg
from smg_torch.compat import (d3dgs_losses, ds4d_losses, dynomo_losses, marbles_global_rigid, marbles_isometry,
                               mosca_arap, mosca_vel_acc, scgs_arap, som_accel)
from test_compat import GAMMAS, SHIFTS, mosca_arap_torch, mosca_scene
from test_compat_d3dgs import d3dgs_torch, scene as d3dgs_scene, tangent
from test_compat_ds4d import scene as ds4d_scene
from test_compat_dynomo import scene as dynomo_scene
from test_compat_marbles import scene as marbles_scene
from test_compat_scgs import _scene as scgs_scene, cal_arap_error_torch
from test_render import small_scene
from test_skin import skin_scene
from scenes import random_scene


def _rel(a, b):
    m, d = float(b.abs().max()), float((a - b).abs().max())
    return d / m if m > 0 else d


# ---- every compat call: its arguments (a list, float tensors first) and a scalar of its losses ----

def _mosca_args():
    xyz, q, ti, mask, lv = mosca_scene(T=8, M=30, K=6, seed=11)
    return [xyz, q, ti, mask, SHIFTS, GAMMAS], dict(levels=lv)


def _d3dgs_args():
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = d3dgs_scene(N=60, K=6, seed=12)
    return [fg_pts, F.normalize(unnorm, dim=-1), prev_pts, prev_rot, idx, w, d0], {}


def _scgs_args():
    seq, ii, jj, nn, _ = scgs_scene(M=40, Nt=3, seed=13)
    return [seq, ii, jj, nn], {}


def _ds4d_args():
    return ds4d_scene(N=60, seed=15), {}


def _marbles_args():
    xyz, src, p, k, mask = marbles_scene(N=80, seed=16)
    return [xyz, src, p, k, mask], {}


def _marbles_rigid_args():
    xyz, src, _, _, _ = marbles_scene(N=80, seed=17)
    i = torch.arange(80)
    return [src, xyz, i, i.flip(0)], {}


def _dynomo_args():
    return dynomo_scene(N=60, K=5, seed=18), {}


def _som_args():
    g = torch.Generator().manual_seed(14)
    return [torch.randn(5, 6, 2, 3, generator=g)], {}


# name: (function, arguments, the float arguments that take gradients (positions), the
# quaternion arguments, the argument names in order)
CALLS = {
    "som_accel": (som_accel, _som_args, (0,), (), ("transls",)),
    "mosca_arap": (mosca_arap, _mosca_args, (0, 1), (1,),
                   ("node_xyz", "node_quat", "topo_ind", "topo_mask", "shifts", "shift_weights")),
    "mosca_vel_acc": (mosca_vel_acc, lambda: (_mosca_args()[0][:2], {}), (0, 1), (1,), ("node_xyz", "node_quat")),
    "scgs_arap": (scgs_arap, _scgs_args, (0,), (), ("nodes_sequence", "ii", "jj", "nn")),
    "d3dgs_losses": (d3dgs_losses, _d3dgs_args, (0, 1), (1, 3),
                     ("fg_pts", "fg_rot", "prev_pts", "prev_rot", "neighbor_indices", "neighbor_weight",
                      "neighbor_dist")),
    "ds4d_losses": (ds4d_losses, _ds4d_args, (0, 1, 2, 3, 4, 5), (2, 3),
                    ("pos_curr", "pos_prev", "rot_deform_curr", "rot_deform_prev", "scales_deform_prev",
                     "scales_base", "nn_indices", "nn_weights")),
    "marbles_isometry": (marbles_isometry, _marbles_args, (0,), (),
                         ("xyz", "src_xyz", "point_idxs", "knn_idxs", "mask")),
    "marbles_global_rigid": (marbles_global_rigid, _marbles_rigid_args, (1,), (),
                             ("xyz", "transformed_xyz", "idx1", "idx2")),
    "dynomo_losses": (dynomo_losses, _dynomo_args, (0, 1), (1, 3),
                      ("curr_means", "curr_rot", "prev_means", "prev_rot", "self_indices", "neighbor_indices",
                       "neighbor_weight", "offset_0")),
}


def _total(out):
    """A scalar of a call's result: the sum of its losses, or of its per-edge errors (marbles_isometry)."""
    return out.sum() if isinstance(out, torch.Tensor) else sum(out)


def _values_and_grads(name, args, kw, wrap=None):
    """The losses and the gradient of their sum w.r.t. the differentiable arguments; `wrap`
    (position, leaf) -> what the call receives in place of the leaf."""
    fn, _, diff, _, _ = CALLS[name]
    args = list(args)
    leaves = {}
    for i in diff:
        leaves[i] = args[i].detach().clone().requires_grad_()
        args[i] = wrap(i, leaves[i]) if wrap else leaves[i]
    out = fn(*args, **kw)
    _total(out).backward()
    vals = [out] if isinstance(out, torch.Tensor) else list(out)
    return [v.detach().clone() for v in vals], [leaves[i].grad for i in diff]


def _neg_view(t):
    """A tensor with torch's negative bit set that reads as t (its storage holds -t)."""
    v = torch._neg_view(-t)
    assert v.is_neg() and torch.equal(v, t)
    return v


def _conj_imag(t):
    """A real tensor from a conjugate view (conj().imag: the negative bit again) reading as t."""
    v = torch.complex(torch.zeros_like(t), -t).conj().imag
    assert v.is_neg() and torch.equal(v, t)
    return v


@pytest.mark.parametrize("name", list(CALLS))
def test_negative_bit_reads_as_its_values(name):
    fn, make, diff, _, _ = CALLS[name]
    args, kw = make()
    ref_v, ref_g = _values_and_grads(name, args, kw)
    v, g = _values_and_grads(name, args, kw, wrap=lambda i, leaf: _neg_view(leaf))
    for a, b in zip(v, ref_v):
        assert torch.equal(a, b), name
    for a, b in zip(g, ref_g):
        assert torch.equal(a, b), name
    # The other float arguments (constants), as conj().imag views.
    args2 = [(_conj_imag(a) if isinstance(a, torch.Tensor) and a.is_floating_point() and i not in diff else a)
             for i, a in enumerate(args)]
    v2, g2 = _values_and_grads(name, args2, kw)
    for a, b in zip(v2 + g2, ref_v + ref_g):
        assert torch.equal(a, b), name


@pytest.mark.parametrize("name", list(CALLS))
def test_sparse_tensors_are_refused_by_name(name):
    fn, make, _, _, names = CALLS[name]
    for i, a in enumerate(make()[0]):
        if not isinstance(a, torch.Tensor):
            continue
        args, kw = make()
        args[i] = a.to_sparse()
        with pytest.raises(ValueError, match=rf"^{names[i]}: a tensor of layout torch.sparse_coo; pass a dense"):
            fn(*args, **kw)


@pytest.mark.parametrize("name", list(CALLS))
@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_non_finite_entries_are_refused_by_the_callers_index(name, value):
    fn, make, _, quats, names = CALLS[name]
    args, kw = make()
    for i, a in enumerate(args):
        if not (isinstance(a, torch.Tensor) and a.is_floating_point()):
            continue
        args, kw = make()
        bad = a.clone()
        where = tuple(min(1, s - 1) for s in bad.shape[:-1])  # the vector [1, 1, ...] of the caller's layout
        bad[where + (bad.shape[-1] - 1,)] = value
        args[i] = bad
        idx = ", ".join(str(j) for j in where)
        if names[i] in ("neighbor_weight", "neighbor_dist", "nn_weights"):  # per-entry tables, not vectors
            idx = ", ".join(str(j) for j in where + (bad.shape[-1] - 1,))
            pattern = rf"^{names[i]}\[{idx}\] is {value}"
        else:
            pattern = rf"^{names[i]}\[{idx}\] has a NaN or infinite coordinate"
        with pytest.raises(ValueError, match=pattern):
            fn(*args, **kw)


@pytest.mark.parametrize("name", [n for n in CALLS if CALLS[n][3]])
def test_zero_quaternions_are_refused_by_the_callers_index(name):
    fn, make, _, quats, names = CALLS[name]
    for i in quats:
        args, kw = make()
        bad = args[i].clone()
        bad[(1,) * (bad.dim() - 1)] = 0
        args[i] = bad
        idx = ", ".join("1" for _ in range(bad.dim() - 1))
        with pytest.raises(ValueError, match=rf"^{names[i]}\[{idx}\] is the zero quaternion"):
            fn(*args, **kw)


# ---- second order: every smg_torch operator ----

def _operators():
    """name -> a function of fresh leaves returning (the leaves, a scalar loss)."""
    x, q, idx, w, c = random_scene()
    g = (idx, w)
    sk = skin_scene()
    t, W, H = small_scene()

    def leaves(*ts):
        return [a.detach().clone().requires_grad_() for a in ts]

    def op(f, *ts):
        def run():
            ls = leaves(*ts)
            return ls, _total(f(*ls))
        return run

    ops = {
        "carap": op(lambda a, b: smg.carap(a, b, g, c), x, q),
        "arap": op(lambda a, b: smg.arap(a, b, g), x, q),
        "lrm": op(lambda a: smg.lrm(a, g, c), x),
        "regularizers": op(lambda a, b: smg.regularizers(a, b, g).total, x, q),
        "dqb": op(lambda a, b: sum(v.sum() for v in smg.dqb(a, b, (sk[2], sk[3]), sk[4], sk[5], sk[6], sk[7],
                                                                 sk[8], sk[9])), sk[0], sk[1]),
        "render": op(lambda m: sum(v.sum() for v in smg.render(m, t["quats"], t["scales"], t["opacities"],
                                                                t["colors"], t["viewmat"], t["K"], W, H)),
                     t["means"]),
    }
    for name, (fn, make, diff, _, _) in CALLS.items():
        args, kw = make()

        def run(fn=fn, args=args, kw=kw, diff=diff):
            a = list(args)
            ls = leaves(*(a[i] for i in diff))
            for i, leaf in zip(diff, ls):
                a[i] = leaf
            return ls, _total(fn(*a, **kw))
        ops["compat." + name] = run
    return ops


@pytest.mark.parametrize("name", list(_operators()))
def test_second_order_is_refused_at_the_first_backward(name):
    run = _operators()[name]
    ls, loss = run()
    with pytest.raises(RuntimeError, match=rf"^smg_torch\.{name}: no second-order gradient"):
        torch.autograd.grad(loss, ls, create_graph=True)
    # First order still works on the same graph's inputs.
    ls, loss = run()
    grads = torch.autograd.grad(loss, ls)
    assert all(gr is not None and bool(torch.isfinite(gr).all()) for gr in grads)


# ---- MoSca: shift lists, signs, degenerate means ----

def _mosca(shifts=SHIFTS, weights=GAMMAS, reduce="mean", levels=None, scene=None):
    xyz, q, ti, mask, lv = scene or mosca_scene(T=8, M=30, K=6, seed=11)
    lv = lv if levels is None else levels
    out = []
    for fn in (mosca_arap, mosca_arap_torch):
        x, r = xyz.clone().requires_grad_(), q.clone().requires_grad_()
        if fn is mosca_arap:
            c, l = fn(x, r, ti, mask, shifts, weights, reduce=reduce, levels=lv)
        else:
            c, l = fn(x, r, ti, mask, [int(s) for s in shifts], [float(g) for g in weights], reduce=reduce,
                      levels=lv)
        (3 * c + 2 * l).backward()
        out.append((float(c), float(l), x.grad, r.grad))
    return out


def _agree(pair, tol_e=1e-9, tol_g=1e-7):
    (c, l, gx, gq), (rc, rl, rgx, rgq) = pair
    assert abs(c - rc) <= tol_e * abs(rc) and abs(l - rl) <= tol_e * abs(rl)
    assert _rel(gx, rgx) <= tol_g and _rel(gq, rgq) <= tol_g


@pytest.fixture
def float32_default():
    """torch's default dtype as most training scripts have it (this suite's conftest sets float64)."""
    before = torch.get_default_dtype()
    torch.set_default_dtype(torch.float32)
    yield
    torch.set_default_dtype(before)


@pytest.mark.parametrize("shifts, weights", [
    (torch.tensor(SHIFTS), torch.tensor(GAMMAS, dtype=torch.float64)),
    (torch.tensor(SHIFTS, dtype=torch.int32), torch.tensor(GAMMAS, dtype=torch.float32)),
    (np.array(SHIFTS), np.array(GAMMAS, dtype=np.float32)),
    ([torch.tensor(s) for s in SHIFTS], [torch.tensor(g, dtype=torch.float32) for g in GAMMAS]),
])
def test_mosca_shift_lists_of_any_kind_are_read_exactly(shifts, weights, float32_default):
    """Shifts as int64 tensors once gave float32 gap weights under torch's default dtype float32
    (5e-8 off in float64); now every form is read as Python numbers, so the result equals the
    list call's bit for bit where the weights are the same numbers (float32 weights: the float32
    values, read exactly)."""
    xyz, q, ti, mask, lv = mosca_scene(T=8, M=30, K=6, seed=11)
    w_list = [float(g) for g in (weights.tolist() if hasattr(weights, "tolist") else weights)]
    a = mosca_arap(xyz, q, ti, mask, shifts, weights, levels=lv)
    b = mosca_arap(xyz, q, ti, mask, SHIFTS, w_list, levels=lv)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    _agree(_mosca(shifts, weights, levels=lv))


def test_mosca_negative_shift_and_level_weights_are_multiplied_as_upstream():
    xyz, q, ti, mask, lv = mosca_scene(T=8, M=30, K=6, seed=11)
    edges, weight, mu, dn, ds = lv[0]
    signed = weight * torch.where(torch.arange(len(weight)) % 3 == 0, -2.0, 1.0)
    for shifts, weights, levels in (([1, 3, 6], [0.6, -0.3, 0.1], lv),
                                    ([1, 3, 6], [-0.6, -0.3, -0.1], lv),
                                    (SHIFTS, GAMMAS, ((edges, signed, mu, dn, ds),)),
                                    (SHIFTS, [0.6, -0.3, 0.1], ((edges, signed, -0.4, dn, ds),))):
        for reduce in ("mean", "sum"):
            _agree(_mosca(shifts, weights, reduce, levels))


def test_mosca_shift_zero_adds_nothing_and_negative_shifts_are_refused():
    xyz, q, ti, mask, lv = mosca_scene(T=8, M=30, K=6, seed=11)
    a = mosca_arap(xyz, q, ti, mask, [0] + SHIFTS, [5.0] + GAMMAS, levels=lv)
    b = mosca_arap(xyz, q, ti, mask, SHIFTS, GAMMAS, levels=lv)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    for shifts, weights, match in (([1, -2], [1.0, 1.0], r"^shifts\[1\]: is -2; a negative shift"),
                                   ([1, 1.5], [1.0, 1.0], r"^shifts\[1\]: expected an integer"),
                                   ([1, True], [1.0, 1.0], r"^shifts\[1\]: expected a real number"),
                                   ("13", [1.0, 1.0], r"^shifts: expected a sequence of numbers"),
                                   (torch.tensor([[1, 2]]), [1.0, 1.0], r"^shifts: expected a sequence or a 1-D"),
                                   ([1, 2], [1.0, "a"], r"^shift_weights\[1\]: expected a real number"),
                                   ([1, 2], [1.0, float("nan")], r"^shift_weights\[1\]: is nan"),
                                   ([1, 2], torch.tensor([1.0, float("inf")]), r"^shift_weights\[1\]: is inf"),
                                   ([1, 2], [1.0], r"^shift_weights: 1 weights for 2 shifts")):
        with pytest.raises(ValueError, match=match):
            mosca_arap(xyz, q, ti, mask, shifts, weights)


def test_mosca_means_over_nothing_are_refused_as_upstream_asserts():
    xyz, q, ti, mask, lv = mosca_scene(T=8, M=30, K=6, seed=11)
    e = (torch.empty((0, 2), dtype=torch.int64), torch.empty(0), 1.0, True, False)
    with pytest.raises(ValueError, match=r"^levels\[0\]\.edges: has no edges: MoSca's mean .* asserts"):
        mosca_arap(xyz, q, ti, mask, SHIFTS, GAMMAS, levels=(e,))
    none = (xyz[:, :0], q[:, :0], ti[:0], mask[:0])
    with pytest.raises(ValueError, match=r"^node_xyz: has no nodes .* asserts"):
        mosca_arap(*none, SHIFTS, GAMMAS)
    # Upstream's sums over nothing are 0, and so is a window no shift reaches, mean or not.
    c, l = mosca_arap(*none, SHIFTS, GAMMAS, reduce="sum")
    assert float(c) == 0.0 and float(l) == 0.0
    c, l = mosca_arap(xyz, q, ti, mask, SHIFTS, GAMMAS, reduce="sum", levels=(e,))
    rc, rl = mosca_arap_torch(xyz, q, ti, mask, SHIFTS, GAMMAS, reduce="sum")
    assert abs(float(c) - float(rc)) <= 1e-12 * float(rc)
    c, l = mosca_arap(xyz[:1], q[:1], ti, mask, SHIFTS, GAMMAS, levels=(e,))
    assert float(c) == 0.0 and float(l) == 0.0


def test_mosca_level_arguments_name_the_level():
    xyz, q, ti, mask, lv = mosca_scene(T=8, M=30, K=6, seed=11)
    edges, weight, mu, dn, ds = lv[0]
    bad_w = weight.clone()
    bad_w[4] = float("nan")
    for level, match in (((edges, bad_w, mu, dn, ds), r"^levels\[0\]\.weight\[4\] is nan"),
                         ((edges.float(), weight, mu, dn, ds), r"^levels\[0\]\.edges: expected an int32"),
                         ((edges + 100, weight, mu, dn, ds), r"^levels\[0\]\.edges\[\d+, \d\] = \d+ is not a node in \[0, M = "),
                         ((edges, weight[:-1], mu, dn, ds), r"^levels\[0\]\.weight: expected a float tensor"),
                         ((edges, weight, "x", dn, ds), r"^levels\[0\]\.mu: expected a real number"),
                         ((edges, weight, mu), r"^levels\[0\]: expected \(edges")):
        with pytest.raises(ValueError, match=match):
            mosca_arap(xyz, q, ti, mask, SHIFTS, GAMMAS, levels=(level,))


@pytest.mark.parametrize("g", [float("inf"), -float("inf"), float("nan")])
def test_mosca_backward_of_a_non_finite_loss_weight_is_torchs(g):
    """A loss scaled by inf once reached smg as lambda_c = inf and was refused as
    "arap.lambda_c"; now each part's gradient is scaled in torch, as upstream's backward does
    (one graph here: with levels, each graph's part is scaled, then summed, and inf − inf is NaN
    as in torch's own accumulation)."""
    xyz, q, ti, mask, _ = mosca_scene(T=8, M=30, K=6, seed=11)
    lv = ()
    x = xyz.clone().requires_grad_()
    c, l = mosca_arap(x, q, ti, mask, SHIFTS, GAMMAS, levels=lv)
    (gx1,) = torch.autograd.grad(c, x)
    x2 = xyz.clone().requires_grad_()
    c2, l2 = mosca_arap(x2, q, ti, mask, SHIFTS, GAMMAS, levels=lv)
    (gx,) = torch.autograd.grad(c2 * g + l2 * 0.0, x2)
    expect = gx1 * g
    assert torch.equal(torch.isnan(gx), torch.isnan(expect))
    assert torch.equal(gx[~torch.isnan(gx)], expect[~torch.isnan(expect)])


# ---- Dynamic 3D Gaussians: self edges, unit quaternions, negative weights ----

def test_d3dgs_self_edges_are_taken_as_upstream():
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = d3dgs_scene(N=80, K=6, seed=21)
    fg_rot = F.normalize(unnorm, dim=-1)
    idx = idx.clone()
    idx[::4, 2] = torch.arange(0, 80, 4)  # every fourth row names itself in slot 2
    idx[7, :] = 7                          # a row of self edges only
    res = []
    for fn in (d3dgs_losses, d3dgs_torch):
        x, r = fg_pts.clone().requires_grad_(), fg_rot.clone().requires_grad_()
        out = fn(x, r, prev_pts, prev_rot, idx, w, d0)
        (4 * out[0] + 4 * out[1] + 2 * out[2]).backward()
        res.append(([float(v) for v in out], x.grad, r.grad))
    (e_s, gx_s, gq_s), (e_t, gx_t, gq_t) = res
    for a, b in zip(e_s, e_t):
        assert abs(a - b) <= 1e-12 * b
    assert _rel(gx_s, gx_t) < 1e-10
    assert _rel(gq_s, tangent(gq_t, fg_rot)) < 1e-10


def test_d3dgs_refuses_what_it_would_compute_differently():
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = d3dgs_scene(N=40, K=5, seed=22)
    fg_rot = F.normalize(unnorm, dim=-1)
    args = [fg_pts, fg_rot, prev_pts, prev_rot, idx, w, d0]
    for i, change, match in ((1, lambda t: t * torch.where(torch.arange(40)[:, None] == 3, 2.0, 1.0),
                              r"^fg_rot\[3\] has norm 2: d3dgs_losses takes unit quaternions"),
                             (3, lambda t: t * 1.001, r"^prev_rot\[0\] has norm 1.001"),
                             (5, lambda t: t.index_fill(1, torch.tensor([2]), -1.0),
                              r"^neighbor_weight\[0, 2\] = -1.0 is negative"),
                             (4, lambda t: t.index_fill(1, torch.tensor([1]), 40),
                              r"^neighbor_indices\[0, 1\] = 40 is not a node in \[0, 40\)")):
        a = list(args)
        a[i] = change(a[i])
        with pytest.raises(ValueError, match=match):
            d3dgs_losses(*a)
    # Within 1e-5 of unit norm is taken (float32 normalisation cast to float64 is within 1e-7).
    a = list(args)
    a[1] = F.normalize(fg_rot.float(), dim=-1).double()
    d3dgs_losses(*a)


# ---- SC-GS: signed weights, K's size ----

def test_scgs_negative_edge_weights_are_multiplied_as_upstream():
    seq, ii, jj, nn, _ = scgs_scene(M=40, Nt=3, seed=23)
    w = torch.ones(40, 10, dtype=torch.float64)
    w[::3] = -0.5
    a = seq.clone().requires_grad_()
    b = seq.clone().requires_grad_()
    ea = scgs_arap(a, ii, jj, nn, 10, w)
    eb = cal_arap_error_torch(b, ii, jj, nn, 10, w)
    ea.backward()
    eb.backward()
    assert abs(float(ea) - float(eb)) <= 1e-9 * abs(float(eb))
    assert _rel(a.grad, b.grad) <= 1e-7


@pytest.mark.parametrize("K", [2 ** 40, 2 ** 62, 10 ** 30])
def test_scgs_huge_K_is_refused_naming_K(K):
    seq, ii, jj, nn, _ = scgs_scene(M=40, Nt=2, seed=24)
    with pytest.raises(ValueError, match=r"^K: \d+ slots per node would need .* GiB .* memory limit"):
        scgs_arap(seq, ii, jj, nn, K)


# ---- nothing left behind ----

def _refused_batch():
    """A batch of calls each refused (ValueError)."""
    xyz, q, ti, mask, lv = mosca_scene(T=8, M=30, K=6, seed=11)
    bad_q = q.clone()
    bad_q[2, 3] = 0
    nan_x = xyz.clone()
    nan_x[1, 2, 0] = float("nan")
    fg_pts, unnorm, prev_pts, prev_rot, idx, w, d0 = d3dgs_scene(N=40, K=5, seed=22)
    calls = [lambda: mosca_arap(xyz, bad_q, ti, mask, SHIFTS, GAMMAS),
             lambda: mosca_arap(nan_x, q, ti, mask, SHIFTS, GAMMAS),
             lambda: mosca_arap(xyz, q, ti, mask, [1, -1], [1.0, 1.0]),
             lambda: mosca_vel_acc(nan_x, q),
             lambda: som_accel(nan_x),
             lambda: d3dgs_losses(fg_pts, unnorm * 3, prev_pts, prev_rot, idx, w, d0),
             lambda: scgs_arap(nan_x, torch.tensor([0]), torch.tensor([1]), torch.tensor([0]))]
    for call in calls:
        with pytest.raises(ValueError):
            call()
    return len(calls)


def test_refused_calls_leave_nothing_behind():
    before = {}
    for name, (fn, make, _, _, _) in CALLS.items():
        args, kw = make()
        before[name] = _values_and_grads(name, args, kw)
    assert _refused_batch() == 7
    for name, (fn, make, _, _, _) in CALLS.items():
        args, kw = make()
        v, g = _values_and_grads(name, args, kw)
        for a, b in zip(v + g, before[name][0] + before[name][1]):
            assert torch.equal(a, b), name
    assert math.isfinite(float(_total(mosca_vel_acc(*_mosca_args()[0][:2]))))


# ---- CUDA (skipped without a device and a CUDA build of smg_torch) ----

cuda = pytest.mark.skipif(not (torch.cuda.is_available() and smg.has_cuda),
                          reason="no CUDA device or smg_torch built without CUDA")


def _to_cuda(args):
    return [a.cuda() if isinstance(a, torch.Tensor) else a for a in args]


@cuda
@pytest.mark.parametrize("name", list(CALLS))
def test_cuda_refusals_name_the_callers_index_and_negative_bits_read_as_values(name):
    """The classes above on CUDA tensors: a NaN is refused by the caller's index (the check reads
    one flag back to the host), a negative-bit tensor gives the plain tensor's values and
    gradients, and the values agree with the CPU's."""
    fn, make, diff, _, names = CALLS[name]
    args, kw = make()
    cpu_v, _ = _values_and_grads(name, args, kw)
    cargs = _to_cuda(args)
    ckw = {k: tuple(tuple(_to_cuda(list(level))) for level in v) if k == "levels" else v for k, v in kw.items()}
    ref_v, ref_g = _values_and_grads(name, cargs, ckw)
    v, g = _values_and_grads(name, cargs, ckw, wrap=lambda i, leaf: _neg_view(leaf))
    for a, b in zip(v + g, ref_v + ref_g):
        assert torch.equal(a, b), name
    for a, b in zip(ref_v, cpu_v):
        assert abs(float(a) - float(b)) <= 1e-9 * max(abs(float(b)), 1e-300), name
    bad = cargs[0].clone()
    bad[(1,) * (bad.dim() - 1) + (0,)] = float("nan")
    cargs[0] = bad
    with pytest.raises(ValueError, match=rf"^{names[0]}\[{', '.join(['1'] * (bad.dim() - 1))}\] has a NaN"):
        fn(*cargs, **ckw)
