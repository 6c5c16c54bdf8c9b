"""smg_torch.compat — the field's regularisers as their code computes them, through smg's
operators, so that a training script swaps one line (docs/compat.md).

    from smg_torch.compat import som_accel
    loss = som_accel(transls)          # Shape of Motion's compute_accel_loss(transls)

Covered: Shape of Motion's `compute_accel_loss` (flow3d/loss_utils.py), on 3-vectors; MoSca's
`MoSca.compute_arap_loss` and `MoSca.compute_vel_acc_loss` (lib_mosca/mosca.py); SC-GS's
`cal_arap_error` (utils/deform_utils.py: per-node Procrustes rotations, then the weighted sum of
squared stretches) as `scgs_arap`, through smg's plain ARAP (E9); Dynamic 3D Gaussians' rigid,
rot and iso losses (train.py get_loss) as `d3dgs_losses`, through smg's plain ARAP under the
sqrt_weighted penalty (E24) and the relative-rotation term (E25); DreamScene4D's scale and local
rigidity losses (gs_renderer_4d.py render_flow) as `ds4d_losses`, through the same ARAP; Dynamic
Gaussian Marbles' adjacent and instance isometry (src/models/gaussians.py) as `marbles_isometry` and
`marbles_global_rigid`, and DynOMo's physics-based losses (src/utils/losses.py) as `dynomo_losses`,
these three in plain torch with their gradients written out. The neighbour tables these
codebases build with tools of their own, through smg's exact point KNN (smg_torch.knn_points):
`open3d_knn` (Dynamic 3D Gaussians' and DynOMo's `o3d_knn`, Open3D's KDTreeFlann), `ckdtree_knn`
(scipy's cKDTree.query, DreamScene4D's `precompute_nn`) and `frnn_knn` (frnn.frnn_grid_points,
Dynamic Gaussian Marbles' `_cache_isometry_knn`).
"""
from __future__ import annotations

import concurrent.futures
import math
import numbers
from typing import Optional, Sequence, Tuple

import torch

from . import (_REGULARIZER_ENERGIES, REGULARIZER_DEFAULTS, REGULARIZER_TERMS, _C, _CarapFunction, _first_order,
               _regularizers, _scale, _term_options, has_cuda, knn_points, memory_limit)

__all__ = ["som_accel", "mosca_arap", "mosca_vel_acc", "scgs_arap", "d3dgs_losses", "ds4d_losses",
           "marbles_isometry", "marbles_global_rigid", "dynomo_losses", "open3d_knn", "ckdtree_knn", "frnn_knn"]

# smg's smoothness (E21) with the unsquared norm (E22) and Normalization::mean, i.e. the mean of
# ‖a‖ over the (T − 2)·N terms: the accel term's options.
_SOM_ACCEL = dict(REGULARIZER_DEFAULTS["accel"], form="acceleration", penalty="norm",
                  confidence_weighted=False, normalize=True, weight=1.0)
# On CUDA tensors: the fused step with smoothness alone (no term reads the empty graph).
_OFF = dict(confidence=False, carap=False, arap=False, lrm=False)


def _dense(name, t):
    """t as smg reads it: a torch.Tensor, dense (strided), its negative and conjugate bits
    resolved (torch._neg_view and conj().imag are views whose storage holds the negated values;
    resolve_neg is differentiable, so autograd still reaches the caller's tensor). Else one error
    naming the argument (a sparse tensor's own error names neither)."""
    if not isinstance(t, torch.Tensor):
        raise ValueError(f"{name}: expected a torch.Tensor, got {type(t).__name__}")
    if t.layout != torch.strided:
        raise ValueError(f"{name}: a tensor of layout {t.layout}; pass a dense (strided) tensor (.to_dense())")
    return t.resolve_conj().resolve_neg()


def _index_of(flat, shape):
    """The caller's index "[i, j, ...]" of entry `flat` of a tensor of this shape."""
    out = []
    for n in reversed(shape):
        out.append(flat % n)
        flat //= n
    return "[" + ", ".join(str(i) for i in reversed(out)) + "]"


def _refuse_out_of_range(name, t, hi, what, hi_name=None, why=""):
    """Refuses an integer tensor t with an entry outside [0, hi), by the caller's index of the
    first one: "<name>[i, ...] = v is not <what> in [0, <hi_name> = hi)<why>"."""
    bad = (t < 0) | (t >= hi)
    if bool(bad.any()):
        flat = int(bad.reshape(-1).nonzero()[0])
        bound = f"{hi_name} = {hi}" if hi_name else f"{hi}"
        raise ValueError(f"{name}{_index_of(flat, tuple(t.shape))} = {int(t.reshape(-1)[flat])} is not {what} in "
                         f"[0, {bound}){why}")


def _check_vectors(name, t, quaternions=False):
    """Refuses, before any work, the first vector (the last dim: a point or a quaternion) with a
    NaN or infinite coordinate, or, for quaternions, the zero quaternion (it has no rotation),
    naming it by the caller's index: `node_quat[3, 17] is the zero quaternion`."""
    x = t.detach()
    # Fast path: one reduction, no [..] mask, when the sum is finite (no NaN or inf; a finite sum
    # that overflows only sends it to the full scan below).
    bad = None if bool(torch.isfinite(x.sum())) else ~torch.isfinite(x).all(-1)
    what = "has a NaN or infinite coordinate"
    if quaternions and (bad is None or not bool(bad.any())):
        bad = (x == 0).all(-1)
        what = "is the zero quaternion"
    if bad is not None and bool(bad.any()):
        flat = int(bad.reshape(-1).nonzero()[0])
        row = x.reshape(-1, x.shape[-1])[flat].tolist()
        raise ValueError(f"{name}{_index_of(flat, tuple(bad.shape))} {what}: {row}")


def _check_finite(name, t):
    """Refuses the first NaN or infinite entry of t, by the caller's index."""
    x = t.detach()
    if bool(torch.isfinite(x.sum())):  # the fast path of _check_vectors
        return
    bad = ~torch.isfinite(x)
    if bool(bad.any()):
        flat = int(bad.reshape(-1).nonzero()[0])
        raise ValueError(f"{name}{_index_of(flat, tuple(x.shape))} is {float(x.reshape(-1)[flat])}")


def _check_floats(name, t):
    """A float32/float64 tensor on the CPU, or on CUDA with smg's CUDA operators: else one error
    naming the argument."""
    if t.dtype not in (torch.float32, torch.float64):
        raise ValueError(f"{name}: dtype must be float32 or float64, got {t.dtype}")
    if t.device.type not in ("cpu", "cuda"):
        raise ValueError(f"{name}: device must be cpu or cuda, got {t.device}")
    if t.is_cuda and not has_cuda:
        raise NotImplementedError(f"{name}: a CUDA tensor, but smg_torch was built without its CUDA "
                                  "operators (smg_torch.has_cuda is False)")


class _AccelFunction(torch.autograd.Function):
    """smg::accel_windows on CPU tensors x [G, T, B, 3] (trajectory-major windows): the energy,
    and its gradient in x's layout computed in the same pass when x requires grad (scaled by
    grad_output in backward)."""

    @staticmethod
    def forward(ctx, x, options):
        e, g = _C._accel_windows(x.detach(), options, bool(ctx.needs_input_grad[0]))
        ctx.grad = g
        return e

    @staticmethod
    @_first_order("compat.som_accel")
    def backward(ctx, grad_output):
        return _scale(grad_output, ctx.grad), None


def som_accel(transls: torch.Tensor) -> torch.Tensor:
    """Shape of Motion's `compute_accel_loss(transls)`: the mean over every index but the last of
    the unsquared norm of the second difference along dim 1 (time),

        mean ‖2 x[:, t] − x[:, t−1] − x[:, t+1]‖,   t = 1 … T−2,

    which is smg's trajectory smoothness (E21) with penalty="norm" (E22) and normalize=True.
    transls: [K, T, 3] (the motion bases' translations, or [G, T, 3] tracks) or [K, T, ..., 3]
    (e.g. the trainer's [G, 3, B, 3] track neighbourhoods: time is dim 1, as upstream slices it;
    the dims after it are more trajectories), float32 or float64, CPU or CUDA (with a CUDA build),
    T >= 3 and no empty dim. Returns a 0-dim tensor of transls' dtype with autograd to transls;
    where a second difference is exactly 0 its gradient is exactly 0, as torch's norm backward
    gives. Shape of Motion's rotation bases ([K, T, 6]) are not covered: smg's smoothness is on
    3-vectors, and splitting a 6-vector in two is exact only for the squared form.

    On CPU tensors it calls smg::accel_windows, the smoothness term on trajectory-major windows:
    transls is read in place as [K, T, B, 3] (B = the product of the dims after time; a view,
    no copy, for a contiguous transls) and the gradient is written in the same pass in that
    layout, so autograd gets it in transls' shape with no copy either. No [..., T − 2, 3]
    intermediates: the differences, norms and their gradients are formed per element inside
    smg's loop, and no scratch. On CUDA tensors: the fused step with smoothness alone
    (smg::cuda::regularizers, the same element) on one copy of transls in smg's frame-major
    layout [T, N, 3] (transls.movedim(1, 0), N = the product of the other dims)."""
    transls = _dense("transls", transls)
    if transls.dim() < 3:
        raise ValueError(f"transls: expected shape [K, T, 3] or [K, T, ..., 3], got {list(transls.shape)}")
    if transls.shape[-1] != 3:
        raise ValueError(f"transls: the last dim must be 3 (smg's smoothness is on 3-vectors; Shape of "
                         f"Motion's 6-D rotation bases are not covered), got shape {list(transls.shape)}")
    _check_floats("transls", transls)
    T = transls.shape[1]
    if T < 3:
        raise ValueError(f"transls: needs T >= 3 frames on dim 1 for a second difference, got shape "
                         f"{list(transls.shape)} (Shape of Motion's mean over no terms is NaN)")
    if transls.numel() == 0:
        raise ValueError(f"transls: has an empty dim, shape {list(transls.shape)} (Shape of Motion's "
                         "mean over no terms is NaN)")
    _check_vectors("transls", transls)  # by transls' own index, not smg's [t, i] of the copy below
    if not transls.is_cuda:  # [K, T, B, 3] in place: smg::accel_windows reads and writes this layout
        return _AccelFunction.apply(transls.reshape(transls.shape[0], T, -1, 3), _SOM_ACCEL)
    x = transls.movedim(1, 0).reshape(T, -1, 3)  # [T, N, 3]: a copy unless dim 0 has size 1
    # CUDA: smg::cuda::regularizers runs the same element (AccelElement); an empty [N, 0] graph.
    n = x.shape[1]
    idx = torch.empty((n, 0), dtype=torch.int32, device=transls.device)
    w = torch.empty((n, 0), dtype=transls.dtype, device=transls.device)
    return _regularizers(x, None, (idx, w), None, False, dict(_OFF, accel=_SOM_ACCEL), "compat.som_accel").total


# ---- MoSca (JiahuiLei/MoSca, lib_mosca/mosca.py) ---------------------------------------------------

# Every term of the fused step off: each call below turns on the one it needs.
_ALL_OFF = {name: False for name in REGULARIZER_TERMS}


def _check_nodes(node_xyz, node_quat):
    """MoSca's node_xyz [T, M, 3] and node_quat [T, M, 4] as smg reads them (_dense), checked before
    any work: shapes, dtypes, devices, then every point finite and every quaternion finite and
    nonzero, each refusal naming the caller's argument and index."""
    node_xyz, node_quat = _dense("node_xyz", node_xyz), _dense("node_quat", node_quat)
    if node_xyz.dim() != 3 or node_xyz.shape[-1] != 3:
        raise ValueError(f"node_xyz: expected a tensor of shape [T, M, 3], got {list(node_xyz.shape)}")
    _check_floats("node_xyz", node_xyz)
    if tuple(node_quat.shape) != tuple(node_xyz.shape[:2]) + (4,):
        raise ValueError(f"node_quat: expected shape {list(node_xyz.shape[:2]) + [4]} ([T, M, 4] of node_xyz), "
                         f"got {list(node_quat.shape)}")
    if node_quat.dtype != node_xyz.dtype:
        raise ValueError(f"node_quat: dtype {node_quat.dtype} differs from node_xyz's {node_xyz.dtype}")
    if node_quat.device != node_xyz.device:
        raise ValueError(f"node_quat: device {node_quat.device} differs from node_xyz's {node_xyz.device}")
    _check_vectors("node_xyz", node_xyz)
    _check_vectors("node_quat", node_quat, quaternions=True)
    return node_xyz, node_quat


def _check_reduce(reduce, square):
    if reduce not in ("mean", "sum"):
        raise ValueError(f"reduce: must be 'mean' or 'sum', got {reduce!r}")
    if not isinstance(square, bool):
        raise ValueError(f"square: must be a bool, got {type(square).__name__}")


def _numbers(name, values, integer):
    """A shift list (integer=True) or a weight list as Python numbers: ints, or floats read in
    double (exact for every float32 or float64 value: the gap weights are then formed in double,
    whatever dtype the caller's tensor had). Takes a sequence of Python or numpy numbers or
    0-dim tensors, or a 1-D tensor of any real dtype; one error naming name[k] for an entry that
    is not such a number (upstream slices local_coord[:-shift]: a shift must be an integer)."""
    if isinstance(values, torch.Tensor):
        values = _dense(name, values)
        if values.dim() > 1:
            raise ValueError(f"{name}: expected a sequence or a 1-D tensor, got shape {list(values.shape)}")
        if values.dtype == torch.bool or values.is_complex():
            raise ValueError(f"{name}: dtype must be a real number type, got {values.dtype}")
        items = values.detach().cpu().reshape(-1).tolist()
    elif isinstance(values, (str, bytes)):
        raise ValueError(f"{name}: expected a sequence of numbers, got {type(values).__name__}")
    else:
        try:
            items = list(values)
        except TypeError:
            raise ValueError(f"{name}: expected a sequence of numbers, got {type(values).__name__}") from None
    out = []
    for k, v in enumerate(items):
        if isinstance(v, torch.Tensor):
            if v.numel() != 1 or v.dtype == torch.bool or v.is_complex():
                raise ValueError(f"{name}[{k}]: expected a real number, got a {v.dtype} tensor of shape {list(v.shape)}")
            v = _dense(f"{name}[{k}]", v).item()
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise ValueError(f"{name}[{k}]: expected a real number, got {v!r}")
        if integer:
            if not isinstance(v, numbers.Integral):
                raise ValueError(f"{name}[{k}]: expected an integer (MoSca slices local_coord[:-shift]), got {v!r}")
            v = int(v)
            if v < 0:
                raise ValueError(f"{name}[{k}]: is {v}; a negative shift makes MoSca's local_coord[:-shift] compare "
                                 "the first frames with the last ones, which smg does not reproduce (shifts >= 0)")
        else:
            v = float(v)
            if not math.isfinite(v):
                raise ValueError(f"{name}[{k}]: is {v} (MoSca's loss would be NaN or infinite)")
        out.append(v)
    return out


def _frame_owner_graph(owner, other, weight, M):
    """smg's graph of MoSca's local coordinates ℓ = R_owner^T (x_other − x_owner): row `owner`
    (whose rotation expresses the edge, smg's row i), neighbour `other` (smg's j), weight `weight`
    (1-D, one per edge, >= 0). Edges to itself and zero weights are left out (each adds exactly 0
    to the unsquared and the squared forms; smg refuses self edges); rows padded with −1 to the
    largest in-degree. Returns (indices [M, D] int64, weights [M, D])."""
    keep = (owner != other) & (weight != 0)
    owner, other, weight = owner[keep], other[keep], weight[keep]
    order = torch.argsort(owner, stable=True)
    owner, other, weight = owner[order], other[order], weight[order]
    counts = torch.bincount(owner, minlength=M)
    D = int(counts.max()) if owner.numel() > 0 else 0
    starts = torch.cumsum(counts, 0) - counts
    slot = torch.arange(owner.numel(), device=owner.device) - starts[owner]
    idx = torch.full((M, D), -1, dtype=torch.int64, device=owner.device)
    w = torch.zeros((M, D), dtype=weight.dtype, device=owner.device)
    idx[owner, slot] = other
    w[owner, slot] = weight
    return idx, w


def _signed_graphs(owner, other, weight, M):
    """[(sign, indices, weights)] of the edges with positive and with negative weights: smg's graph
    weights are >= 0, and MoSca multiplies by a negative weight as by any other (the energy is
    linear in the weights, so the loss is the positive graph's minus the negated one's)."""
    out = [(1.0,) + _frame_owner_graph(owner, other, weight.clamp(min=0), M)]
    if bool((weight < 0).any()):
        out.append((-1.0,) + _frame_owner_graph(owner, other, (-weight).clamp(min=0), M))
    return out


def _shift_gaps(shifts, shift_weights, T, rows, reduce):
    """MoSca's shift loop as smg's gaps, split by the sign of the weights (smg's gap weights are
    >= 0): {sign: (gaps, weights)} with weights |γ_s|/((T − s)·rows) for reduce="mean" (its
    per-shift mean over (T − s)·rows), |γ_s| for "sum"; a shift with T − s < 1 adds nothing, as
    upstream skips it, and so does shift 0 (upstream's local_coord[:-0] is empty) and a weight 0.
    The caller has refused rows == 0 under "mean" where a shift is active (upstream's NaN)."""
    out = {}
    for s, g in zip(shifts, shift_weights):
        if s == 0 or T - s < 1 or rows == 0 or g == 0:
            continue
        gaps, weights = out.setdefault(1.0 if g > 0 else -1.0, ([], []))
        gaps.append(s)
        weights.append(abs(g) / ((T - s) * rows) if reduce == "mean" else abs(g))
    return out


_SIDE_POOL = None


def _side_by_side(cpu, *calls):
    """The results of independent calls (functions of no arguments), in order. On CPU tensors with
    torch's intra-op threads > 1, the first runs on a worker thread beside the others: a two-frame
    pass of smg's fused step is one block of frames, one core (docs/math/energy.md, "Kernel and
    determinism"), so two such passes side by side use two. Bit for bit what running them in turn
    gives: smg's bindings release the GIL and keep their scratch per thread (thread_local
    workspaces), and each pass's sums do not depend on the thread it runs on."""
    global _SIDE_POOL
    if not cpu or len(calls) < 2 or torch.get_num_threads() < 2:
        return [c() for c in calls]
    if _SIDE_POOL is None:
        _SIDE_POOL = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="smg_side")
    first = _SIDE_POOL.submit(calls[0])
    rest = [c() for c in calls[1:]]
    return [first.result()] + rest


def _fused(x, q, idx, w, terms, need_x, need_q):
    """One call of smg's fused step (the raw binding): (energies by name, grad x, grad q)."""
    on, opts = {}, {}
    for name in REGULARIZER_TERMS:
        on[name], opts[name] = _term_options(name, terms.get(name, False))
    e, _, gx, gq = _C.regularizers(x, q, idx, w, None, on, opts, need_x, need_q, False)
    return dict(zip(_REGULARIZER_ENERGIES, e.tolist())), gx, gq


class _RigidPartsFunction(torch.autograd.Function):
    """(coordinate part, length part) of smg's ARAP (E9, E24) on one graph, each a loss of its own.
    Forward: one energy-only pass with both parts (C-ARAP with α = 1 and c ≡ 1 is plain ARAP:
    its λl = 0 for the coordinates, ARAP's λc = 0 for the lengths, the fused step returns both
    energies). Backward: the parts are linear in λ, so the gradient of g_c·coord + g_l·len is one
    pass with λc = g_c, λl = g_l where both are finite and >= 0 (smg's λ >= 0); otherwise one pass
    per part with λ = 1, each scaled by its g in torch (so an infinite or NaN g gives torch's
    inf·0 = NaN, as upstream's own backward would)."""

    @staticmethod
    def forward(ctx, x, q, idx, w, gaps, gap_weights, penalty, stop_gradient):
        rigid = dict(gaps=gaps, gap_weights=gap_weights, normalize=False, weight=1.0, penalty=penalty,
                     stop_gradient=stop_gradient)
        e, _, _ = _fused(x.detach(), q.detach(), idx, w,
                         dict(carap=dict(rigid, alpha=1.0, lambda_c=1.0, lambda_l=0.0),
                              arap=dict(rigid, lambda_c=0.0, lambda_l=1.0)), False, False)
        ctx.save_for_backward(x, q, idx, w)
        ctx.rigid = rigid
        return x.new_tensor(e["carap"]), x.new_tensor(e["arap"])

    @staticmethod
    @_first_order("compat.mosca_arap")
    def backward(ctx, g_coord, g_len):
        x, q, idx, w = ctx.saved_tensors
        need_x, need_q = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        gc, gl = float(g_coord), float(g_len)
        if gc >= 0 and gl >= 0 and math.isfinite(gc) and math.isfinite(gl):
            _, gx, gq = _fused(x.detach(), q.detach(), idx, w, dict(arap=dict(ctx.rigid, lambda_c=gc, lambda_l=gl)),
                               need_x, need_q)
        else:
            gx = gq = None
            for lam, (lc, ll) in ((g_coord, (1.0, 0.0)), (g_len, (0.0, 1.0))):
                _, px, pq = _fused(x.detach(), q.detach(), idx, w, dict(arap=dict(ctx.rigid, lambda_c=lc, lambda_l=ll)),
                                   need_x, need_q)
                gx = None if px is None else (px * lam if gx is None else gx + px * lam)
                gq = None if pq is None else (pq * lam if gq is None else gq + pq * lam)
        return (gx, gq) + (None,) * 6


def _rigid_parts(x, q, graphs, gaps, penalty, stop_gradient):
    """(coordinate part, length part) of smg's ARAP (E9, E24) on the signed graphs
    (_signed_graphs) and signed gaps (_shift_gaps), each differentiable (a loss is weighted by
    its own λ upstream): Σ sign_graph · sign_gaps · parts, one _RigidPartsFunction per nonempty
    pair (one in the usual case, where every weight is >= 0)."""
    coord = length = None
    for sg, idx, w in graphs:
        for sh, (gs, gw) in gaps.items():
            if idx.shape[1] == 0:
                continue
            c, l = _RigidPartsFunction.apply(x, q, idx, w, tuple(gs), tuple(gw), penalty, stop_gradient)
            sign = sg * sh
            coord = c * sign if coord is None else coord + c * sign
            length = l * sign if length is None else length + l * sign
    if coord is None:
        zero = x.sum() * 0 + q.sum() * 0  # keeps the autograd graph, as upstream's 0-sums do
        return zero, zero
    return coord, length


def _active(shifts, T):
    """Whether some shift adds a term upstream (0 < s < T; its weight may be 0: the mean is taken
    before it multiplies)."""
    return any(0 < s < T for s in shifts)


def mosca_arap(node_xyz: torch.Tensor, node_quat: torch.Tensor, topo_ind: torch.Tensor,
               topo_mask: torch.Tensor, shifts: Sequence[int], shift_weights: Sequence[float], *,
               reduce: str = "mean", square: bool = False,
               levels: Sequence[tuple] = ()) -> Tuple[torch.Tensor, torch.Tensor]:
    """MoSca's `MoSca.compute_arap_loss(tids, shift_weights, shifts, reduce_type=reduce,
    square=square)` → (loss_coord, loss_len), with node_xyz = `_node_xyz[tids]` [T, M, 3],
    node_quat = `_node_rotation[tids]` [T, M, 4] (raw, w x y z: normalised as its q2R does),
    topo_ind = `topo_knn_ind` [M, K], topo_mask = `topo_knn_mask` [M, K] bool. The local
    coordinate of row i and slot k is ℓ = R_j^T (x_i − x_j), j = topo_ind[i, k] (the neighbour's
    frame), weighted by mask / (Σ_k mask + 1e-6) (computed in float32, as upstream does);
    loss_coord = Σ_s γ_s ρ_s[Σ_k w ‖ℓ^t − ℓ^{t+s}‖], loss_len the same with |‖ℓ^t‖ − ‖ℓ^{t+s}‖|,
    ρ_s the mean over (T − s)·M rows (reduce="mean") or the sum; square=True squares each norm.
    shifts: integers >= 0 (0 and shifts >= T add nothing, as upstream skips them), shift_weights
    real numbers of any sign, as sequences of Python or numpy numbers or 0-dim tensors, or 1-D
    tensors of any dtype (read in double).

    levels: MoSca's multi-level edges, each (edges [E, 2], weight [E], mu, detach_nn,
    detach_self) = (`multilevel_arap_edge_list[l]`, `multilevel_arap_topo_w[l]`,
    `mlevel_w_list[l]`, `mlevel_detach_nn_flag`, `mlevel_detach_self_flag`): column 0 the node
    expressed, column 1 the node whose frame expresses it; weights used as given (any sign:
    upstream multiplies by them); the mean over (T − s)·E; mu times each loss added; detach_nn
    holds column 1's position, detach_self column 0's (upstream refuses both).

    Where upstream's mean is over nothing (M = 0 nodes, or a level with E = 0 edges, under
    reduce="mean" with a shift 0 < s < T) its loss is NaN and compute_arap asserts on it: this
    refuses that call naming the argument.

    How: smg's ARAP (E9) with the unsquared `norm` penalty (E24), or `squared`, on the graph
    whose rows are the frame owners (MoSca's row i is smg's neighbour of row j, so smg's
    d = R_j^T (x_i − x_j) is ℓ itself); the per-shift mean is in the gap weights; a held position
    is smg's stop_gradient ("row" for detach_nn, "neighbor" for detach_self). Per graph, one
    energy-only fused pass gives both losses, and backward one fused pass with λc, λl the two
    losses' incoming gradients (the energy is linear in them); negative weights are a second
    graph (or gap list) subtracted. Gradients reach node_xyz and the raw node_quat; torch's
    sub-gradient 0 where a difference is 0. Returns two 0-dim tensors of node_xyz's dtype."""
    # Everything is checked before any work.
    node_xyz, node_quat = _check_nodes(node_xyz, node_quat)
    _check_reduce(reduce, square)
    T, M = node_xyz.shape[:2]
    topo_ind, topo_mask = _dense("topo_ind", topo_ind), _dense("topo_mask", topo_mask)
    if topo_ind.dim() != 2 or topo_ind.shape[0] != M or topo_ind.dtype not in (torch.int32, torch.int64):
        raise ValueError(f"topo_ind: expected an int32 or int64 tensor of shape [M, K] with M = {M}, got "
                         f"{topo_ind.dtype} {list(topo_ind.shape)}")
    if topo_mask.shape != topo_ind.shape or topo_mask.dtype != torch.bool:
        raise ValueError(f"topo_mask: expected a bool tensor of topo_ind's shape {list(topo_ind.shape)}, got "
                         f"{topo_mask.dtype} {list(topo_mask.shape)}")
    for name, t in (("topo_ind", topo_ind), ("topo_mask", topo_mask)):
        if t.device != node_xyz.device:
            raise ValueError(f"{name}: device {t.device} differs from node_xyz's {node_xyz.device}")
    if topo_ind.numel() and (int(topo_ind.min()) < 0 or int(topo_ind.max()) >= M):
        raise ValueError(f"topo_ind: entries must lie in [0, {M}), got [{int(topo_ind.min())}, {int(topo_ind.max())}]")
    shifts = _numbers("shifts", shifts, integer=True)
    shift_weights = _numbers("shift_weights", shift_weights, integer=False)
    if len(shifts) != len(shift_weights):
        raise ValueError(f"shift_weights: {len(shift_weights)} weights for {len(shifts)} shifts")
    active = reduce == "mean" and _active(shifts, T)
    if active and M == 0:
        raise ValueError(f"node_xyz: has no nodes (shape {list(node_xyz.shape)}): MoSca's mean over (T - s)·M rows "
                         "is then NaN and its compute_arap asserts on it")
    checked = []
    for k, level in enumerate(levels):
        if not isinstance(level, (tuple, list)) or len(level) != 5:
            raise ValueError(f"levels[{k}]: expected (edges, weight, mu, detach_nn, detach_self)")
        edges, weight, mu, detach_nn, detach_self = level
        edges, weight = _dense(f"levels[{k}].edges", edges), _dense(f"levels[{k}].weight", weight)
        if edges.dim() != 2 or edges.shape[1] != 2 or edges.dtype not in (torch.int32, torch.int64):
            raise ValueError(f"levels[{k}].edges: expected an int32 or int64 tensor of shape [E, 2], got "
                             f"{edges.dtype} {list(edges.shape)}")
        if weight.shape != edges.shape[:1] or not weight.is_floating_point():
            raise ValueError(f"levels[{k}].weight: expected a float tensor of shape [E] = [{edges.shape[0]}], got "
                             f"{weight.dtype} {list(weight.shape)}")
        _refuse_out_of_range(f"levels[{k}].edges", edges, M, "a node", "M")
        _check_finite(f"levels[{k}].weight", weight)
        if isinstance(mu, bool) or not isinstance(mu, (numbers.Real, torch.Tensor)):
            raise ValueError(f"levels[{k}].mu: expected a real number, got {mu!r}")
        if detach_nn and detach_self:
            raise ValueError(f"levels[{k}]: detach_nn and detach_self are exclusive (as upstream asserts)")
        if active and edges.shape[0] == 0:
            raise ValueError(f"levels[{k}].edges: has no edges: MoSca's mean over (T - s)·E rows is then NaN and "
                             "its compute_arap asserts on it")
        checked.append((edges, weight, float(mu), "row" if detach_nn else "neighbor" if detach_self else "none"))
    penalty = "squared" if square else "norm"
    dev = node_xyz.device
    # Main graph: row i's weights as upstream forms them (float32), on smg's edge j -> i.
    m = topo_mask.float()
    w_rows = (m / (m.sum(dim=-1, keepdim=True) + 1e-6)).to(node_xyz.dtype)
    K = topo_ind.shape[1]
    rows = torch.arange(M, device=dev).unsqueeze(1).expand(M, K)
    graphs = _signed_graphs(topo_ind.reshape(-1).long(), rows.reshape(-1), w_rows.reshape(-1), M)
    gaps = _shift_gaps(shifts, shift_weights, T, M, reduce)
    loss_coord, loss_len = _rigid_parts(node_xyz, node_quat, graphs, gaps, penalty, "none")
    for edges, weight, mu, stop in checked:
        E = edges.shape[0]
        graphs = _signed_graphs(edges[:, 1].long().to(dev), edges[:, 0].long().to(dev),
                                weight.to(device=dev, dtype=node_xyz.dtype), M)
        c, l = _rigid_parts(node_xyz, node_quat, graphs, _shift_gaps(shifts, shift_weights, T, E, reduce),
                            penalty, stop)
        loss_coord = loss_coord + c * mu
        loss_len = loss_len + l * mu
    return loss_coord, loss_len


def mosca_vel_acc(node_xyz: torch.Tensor, node_quat: torch.Tensor, *, reduce: str = "mean",
                  square: bool = False) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """MoSca's `MoSca.compute_vel_acc_loss(tids, reduce_type=reduce, square=square)` →
    (loss_p_vel, loss_q_vel, loss_p_acc, loss_q_acc), node_xyz = `_node_xyz[tids]` [T, M, 3],
    node_quat = `_node_rotation[tids]` [T, M, 4] (raw, w x y z): ‖x^{t+1} − x^t‖,
    θ_t = the angle of R^{t+1} R^{tT} in [0, π], ‖x^{t+2} − 2x^{t+1} + x^t‖ and |θ_{t+1} − θ_t|,
    each squared when square=True, the mean (over (T − 1)·M or (T − 2)·M terms) or the sum.
    How: smg's smoothness (E21) in its velocity and acceleration forms with the `norm` (or
    `squared`) penalty (E22) and smg's rotation-angle term (E23) in both forms with the same
    penalty, one fused call each (each loss differentiable on its own). Needs T >= 3 (upstream's
    mean of no acceleration term is NaN). Gradients reach node_xyz and the raw node_quat."""
    node_xyz, node_quat = _check_nodes(node_xyz, node_quat)
    _check_reduce(reduce, square)
    T, M = node_xyz.shape[:2]
    if T < 3 or M == 0:
        raise ValueError(f"node_xyz: needs T >= 3 frames and M >= 1 nodes, got shape {list(node_xyz.shape)} "
                         "(upstream's mean over no terms is NaN)")
    penalty = "squared" if square else "norm"
    normalize = reduce == "mean"
    empty = (torch.empty((M, 0), dtype=torch.int64, device=node_xyz.device),
             torch.empty((M, 0), dtype=node_xyz.dtype, device=node_xyz.device))
    out = []
    for form in ("velocity", "acceleration"):
        accel = dict(REGULARIZER_DEFAULTS["accel"], form=form, penalty=penalty, confidence_weighted=False,
                     normalize=normalize, weight=1.0)
        angle = dict(REGULARIZER_DEFAULTS["angle"], form=form, penalty=penalty, confidence_weighted=False,
                     normalize=normalize, weight=1.0)
        out.append(_regularizers(node_xyz, None, empty, None, False, dict(_ALL_OFF, accel=accel),
                                 "compat.mosca_vel_acc").total)
        # The angle term reads no positions: a detached view gives the shapes, so the binding
        # neither computes nor returns a position gradient of zeros [T, M, 3] (as upstream, whose
        # q losses have no xyz gradient at all).
        out.append(_regularizers(node_xyz.detach(), node_quat, empty, None, False, dict(_ALL_OFF, angle=angle),
                                 "compat.mosca_vel_acc").total)
    return out[0], out[1], out[2], out[3]


# SC-GS's cal_arap_error keeps every row up to this many nodes; above it, it samples this many
# rows with replacement (np.random.choice), which scgs_arap does not reproduce.
_SCGS_SAMPLE_NUM = 512


def _scgs_edges(x: torch.Tensor, ii, jj, nn, K: int) -> torch.Tensor:
    """SC-GS's produce_edge_matrix_nfmt (utils/deform_utils.py l.35-42) on x [Nv, 3]: E [Nv, K, 3]
    with E[i, n] = x_i − x_j for each edge (i, j, n) and 0 in the other slots. In x's dtype
    (upstream allocates E in torch's default dtype)."""
    E = x.new_zeros((x.shape[0], K, 3))
    E[ii, nn] = x[ii] - x[jj]
    return E


def _scgs_rotations(E0: torch.Tensor, Et: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """SC-GS's estimate_rotation (utils/deform_utils.py l.130-166) from the edge matrices E0, Et
    [Nv, K, 3] and the weights w [Nv, K]: R_i [Nv, 3, 3] minimising Σ_k w_ik ‖e'_ik − R e_ik‖².
    S_i = Σ_k w_ik e_ik e'_ikᵀ (l.144-146); S_i = 0 for the rows upstream calls unchanged, i.e.
    where for SOME coordinate c all K slots have e[.., c] == e'[.., c] exactly (l.148: .all over
    the K dim, then any row index torch.where returns), so R_i = V Uᵀ of a zero matrix (I with
    torch's SVD); S = U Σ Vᵀ, R = V Uᵀ (l.152-153); where det R <= 0, the column of U at the
    smallest singular value (the first one on a tie, argmin) is negated and R recomputed
    (l.158-163)."""
    S = torch.bmm(E0.transpose(1, 2), w[:, :, None] * Et)  # [Nv, 3, 3]
    unchanged = (E0 == Et).all(dim=1).any(dim=1)
    S[unchanged] = 0
    U, sig, Vh = torch.linalg.svd(S)
    V = Vh.transpose(1, 2)
    R = torch.bmm(V, U.transpose(1, 2))
    rows = torch.nonzero(torch.det(R) <= 0, as_tuple=False).flatten()
    if rows.numel() > 0:
        Um = U.clone()
        Um[rows, :, sig[rows].argmin(dim=1)] *= -1
        R[rows] = torch.bmm(V[rows], Um[rows].transpose(1, 2))
    return R


def _quat_from_matrix(R: torch.Tensor) -> torch.Tensor:
    """Unit quaternions (w, x, y, z) [..., 4] of rotation matrices R [..., 3, 3] (Shepperd's
    method): the largest of 4w², 4x², 4y², 4z² (the diagonal combinations below, summing to 4)
    picks the row of the symmetric table 4 q qᵀ that is divided by 4 |q_k| >= 2."""
    m = R.reshape(R.shape[:-2] + (9,)).unbind(-1)
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m
    d = torch.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22,
                     1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)  # 4w², 4x², 4y², 4z²
    a, b, c = m21 - m12, m02 - m20, m10 - m01  # 4wx, 4wy, 4wz
    p, q, r = m01 + m10, m02 + m20, m12 + m21  # 4xy, 4xz, 4yz
    table = torch.stack([torch.stack([d[..., 0], a, b, c], -1),
                         torch.stack([a, d[..., 1], p, q], -1),
                         torch.stack([b, p, d[..., 2], r], -1),
                         torch.stack([c, q, r, d[..., 3]], -1)], -2)  # [..., 4, 4] = 4 q qᵀ
    k = d.argmax(-1, keepdim=True)  # [..., 1]
    row = table.gather(-2, k[..., None].expand(k.shape + (4,))).squeeze(-2)
    return row / (2 * d.gather(-1, k).sqrt())


def _scgs_index(name: str, t, n_edges: Optional[int], hi: int, hi_name: str, device) -> torch.Tensor:
    t = _dense(name, t)
    if t.dim() != 1:
        raise ValueError(f"{name}: expected shape [Ne], got {list(t.shape)}")
    if t.dtype not in (torch.int32, torch.int64):
        raise ValueError(f"{name}: dtype must be int32 or int64, got {t.dtype}")
    if n_edges is not None and t.shape[0] != n_edges:
        raise ValueError(f"{name}: expected {n_edges} entries (as ii), got {t.shape[0]}")
    t = t.detach().to(device=device, dtype=torch.int64)
    _refuse_out_of_range(name, t, hi, "a node" if hi_name == "Nv" else "a neighbour slot", hi_name)
    return t


def scgs_arap(nodes_sequence: torch.Tensor, ii: torch.Tensor, jj: torch.Tensor, nn: torch.Tensor,
              K: int = 10, weight: Optional[torch.Tensor] = None, *,
              sample_num: Optional[int] = _SCGS_SAMPLE_NUM) -> torch.Tensor:
    """SC-GS's `cal_arap_error(nodes_sequence, ii, jj, nn, K, weight)` (yihua7/SC-GS,
    utils/deform_utils.py l.177-205), the ARAP loss of its control nodes
    (ControlNodeWarp.arap_loss in utils/time_utils.py calls it with the ii, jj, nn of
    cal_connectivity_from_points, l.58-110, and weight=None), as the SUM

        Σ_{t=1}^{Nt−1} Σ_i Σ_{(i, j, n)} w_in ‖e^t_in − R_i^t e^0_in‖²,   e^t_in = x^t_i − x^t_j,

    over the edges (i, j, n): node i's n-th neighbour is j (edge slot n of row i, as
    produce_edge_matrix_nfmt places it, l.35-42). R_i^t is the Procrustes rotation of row i's
    edges from frame 0 to frame t (estimate_rotation, l.130-166, with its rules: weighted SVD;
    S zeroed for the rows l.148 calls unchanged, i.e. where some coordinate of all K slots is
    exactly equal in both frames; the U column at the smallest singular value flipped where
    det R <= 0), computed without gradient as upstream does (torch.no_grad, l.196-197): the
    result is differentiable w.r.t. nodes_sequence with the rotations held constant. weight=None
    is upstream's: 1 on every (ii, nn) slot, 0 elsewhere (l.184-186).

    nodes_sequence: [Nt, Nv, 3], float32 or float64, CPU (or CUDA with a CUDA build), finite;
    Nt >= 2 (upstream returns the Python int 0 for Nt = 1) and Nv >= 1. sample_num: upstream's
    (512): with Nv <= sample_num every row is summed, as upstream does; above it upstream sums
    sample_num rows drawn with replacement (np.random.choice, l.189-190), which is not reproduced
    (refused, naming sample_num=None). sample_num=None: every row at any Nv, the loss the draw
    estimates (its expectation is sample_num / Nv times this sum) without its variance, and what
    SC-GS's `no_arap_loss  # For large scenes arap is too slow` switched off. ii, jj, nn: [Ne] int32/int64 (any device), ii, jj in [0, Nv), nn in
    [0, K), each slot (ii, nn) at most once (upstream's scatter would keep one of the duplicates).
    K: int >= 1, the slots per row. weight: None or [Nv, K] float32/float64, finite (upstream: a
    NaN or inf weight, even in a slot without an edge, makes S NaN and its SVD fails on CPU;
    cal_connectivity_from_points' adaptive weights are NaN in the rows with a neighbour beyond
    the radius), of any sign (upstream multiplies by it); a constant here (no gradient to it, where upstream would
    differentiate a weight that requires grad).
    Returns a 0-dim tensor of nodes_sequence's dtype and device.

    How: the rotations are computed here in torch, in nodes_sequence's dtype, exactly as above;
    the energy and its gradient come from smg's plain ARAP (E9) with d^t = R_iᵀ(x_j − x_i),
    positions [x^0, x^t] (T = 2), quaternions [identity, quat(R_i^t)], gap 1 of weight 1,
    lambda_c = 1, lambda_l = 0, squared, normalize=False, since ‖R_iᵀ e^t − e^0‖ = ‖e^t − R_i e^0‖
    (the sign of e does not matter). The Nt − 1 frame pairs go into one call as Nt − 1 copies of
    the graph side by side ([2, (Nt − 1)·Nv, 3]). smg's graph: row i lists the j of its edges in
    slot order with the weights w_in, padded with −1 / 0; self edges (ii = jj) are dropped (their
    edge is 0 in both frames: they add nothing to S or to the energy)."""
    x = _dense("nodes_sequence", nodes_sequence)
    if x.dim() != 3 or x.shape[-1] != 3:
        raise ValueError(f"nodes_sequence: expected shape [Nt, Nv, 3], got {list(x.shape)}")
    _check_floats("nodes_sequence", x)
    Nt, Nv = int(x.shape[0]), int(x.shape[1])
    if Nt < 2:
        raise ValueError(f"nodes_sequence: needs Nt >= 2 frames, got shape {list(x.shape)} (SC-GS "
                         "returns the Python int 0 for a single frame)")
    if Nv < 1:
        raise ValueError(f"nodes_sequence: has no nodes, shape {list(x.shape)}")
    if sample_num is not None:
        if isinstance(sample_num, bool) or not isinstance(sample_num, numbers.Integral) or sample_num < 1:
            raise ValueError(f"sample_num: expected an int >= 1 or None (every node), got {sample_num!r}")
        if Nv > sample_num:
            raise ValueError(f"nodes_sequence: Nv = {Nv} nodes > {int(sample_num)} (SC-GS's sample_num): "
                             "SC-GS then sums over a random sample of rows drawn with replacement "
                             "(np.random.choice), which scgs_arap does not reproduce; sample_num=None sums "
                             "every node")
    _check_vectors("nodes_sequence", x)
    if isinstance(K, bool) or not isinstance(K, numbers.Integral) or K < 1:
        raise ValueError(f"K: expected an int >= 1 (the neighbour slots per node), got {K!r}")
    K = int(K)
    # SC-GS's edge matrices [Nv, K, 3] (one per frame, as upstream makes them) and the [Nv, K]
    # slot tables, estimated before anything is allocated (and before ii·K could overflow int64).
    need = (Nt + 2) * Nv * K * 3 * x.element_size() + 2 * Nv * K * 8
    if need > memory_limit():
        raise ValueError(f"K: {K} slots per node would need {need / 2 ** 30:.3g} GiB for SC-GS's [Nv, K, 3] edge "
                         f"matrices (Nv = {Nv}, Nt = {Nt}), above smg_torch's memory limit of "
                         f"{memory_limit() / 2 ** 30:.3g} GiB (smg_torch.set_memory_limit)")
    dev, dt = x.device, x.dtype
    ii = _scgs_index("ii", ii, None, Nv, "Nv", dev)
    jj = _scgs_index("jj", jj, ii.shape[0], Nv, "Nv", dev)
    nn = _scgs_index("nn", nn, ii.shape[0], K, "K", dev)
    slot_key = ii * K + nn
    if torch.unique(slot_key).numel() != slot_key.numel():
        raise ValueError("nn: a slot (ii[e], nn[e]) appears more than once (SC-GS's edge matrix "
                         "would keep one of the edges written there)")
    with torch.no_grad():
        if weight is None:
            w = torch.zeros((Nv, K), dtype=dt, device=dev)
            w[ii, nn] = 1
        else:
            weight = _dense("weight", weight)
            if tuple(weight.shape) != (Nv, K):
                raise ValueError(f"weight: expected shape [Nv, K] = [{Nv}, {K}], got {list(weight.shape)}")
            if weight.dtype not in (torch.float32, torch.float64):
                raise ValueError(f"weight: dtype must be float32 or float64, got {weight.dtype}")
            w = weight.detach().to(device=dev, dtype=dt)
            bad = ~torch.isfinite(w)
            if bool(bad.any()):
                flat = int(bad.reshape(-1).nonzero()[0])
                raise ValueError(f"weight{_index_of(flat, (Nv, K))} is {float(w.reshape(-1)[flat])} (in SC-GS it "
                                 "reaches the covariance S, whose SVD then fails on CPU; cal_connectivity_from_points' "
                                 "adaptive weights are NaN in the rows with a neighbour beyond the radius)")
        # smg's neighbour table: row i's edges in slot order, self edges dropped, -1 / 0 after.
        slot = torch.full((Nv, K), -1, dtype=torch.int64, device=dev)
        slot[ii, nn] = jj
        keep = (slot >= 0) & (slot != torch.arange(Nv, device=dev)[:, None])
        order = torch.sort((~keep).to(torch.int32), dim=1, stable=True).indices
        g_idx = slot.masked_fill(~keep, -1).gather(1, order)
        g_w = w.masked_fill(~keep, 0).gather(1, order)
        # The rotations of every frame pair, as upstream computes them.
        xd = x.detach()
        E0 = _scgs_edges(xd[0], ii, jj, nn, K)
        P = Nt - 1
        R = torch.stack([_scgs_rotations(E0, _scgs_edges(xd[t], ii, jj, nn, K), w)
                         for t in range(1, Nt)])  # [P, Nv, 3, 3]
        q1 = _quat_from_matrix(R).reshape(P * Nv, 4)
        q0 = torch.zeros_like(q1)
        q0[:, 0] = 1
        quats = torch.stack([q0, q1])  # [2, P·Nv, 4]: constants (no gradient, as upstream)
        # Pair p uses nodes p·Nv … p·Nv + Nv − 1.
        off = (torch.arange(P, device=dev, dtype=torch.int64) * Nv)[:, None, None]
        g_idx = torch.where(g_idx >= 0, g_idx + off, g_idx).reshape(P * Nv, K)
        g_w = g_w.expand(P, Nv, K).reshape(P * Nv, K)
    positions = torch.stack([x[0].expand(P, Nv, 3).reshape(P * Nv, 3), x[1:].reshape(P * Nv, 3)])
    # smg_torch.arap's Function, naming this call in its second-order refusal. smg's graph weights
    # are >= 0 and SC-GS multiplies by a negative weight like any other: the energy is linear in
    # the weights, so such edges are a second graph, subtracted.
    def part(weights):
        return _CarapFunction.apply(positions, quats, g_idx, weights, None, True, 1.0, 1.0, 0.0, [1], [1.0], False,
                                    False, "compat.scgs_arap")
    if bool((g_w < 0).any()):
        return part(g_w.clamp(min=0)) - part((-g_w).clamp(min=0))
    return part(g_w)


# Dynamic 3D Gaussians' floor inside every square root (helpers.py weighted_l2_loss_v1/_v2 and
# train.py's curr_offset_mag).
_D3DGS_EPS = 1e-20
# Rows per chunk of the isometry loss: a [rows, K, 3] gather at a time (about 4 MiB in float32 at
# K = 20), not the whole [N, K, 3].
_D3DGS_ISO_ROWS = 16384
# How far from 1 the norm of fg_rot and prev_rot may be: smg normalises them, D3DGS's rot loss
# compares the raw products fg ⊗ prev* (so it scales with their norms); F.normalize's output is
# within 1e-7 of 1 in float32, and a float32 one cast to float64 stays so.
_D3DGS_UNIT_TOL = 1e-5


def _refuse_negative(name, w, upstream):
    """A ValueError naming the first negative entry of w (the caller's index): `upstream`'s
    sqrt(w·‖r‖² + 1e-20) is NaN there."""
    neg = w < 0
    if bool(neg.any()):
        flat = int(neg.reshape(-1).nonzero()[0])
        raise ValueError(f"{name}{_index_of(flat, tuple(w.shape))} = {float(w.reshape(-1)[flat])} is negative: "
                         f"{upstream}'s sqrt(w·‖r‖² + 1e-20) is NaN there")


def _self_edges_as_padding(idx, w, *tables):
    """(idx, w, n_self, tables) with every self edge (j = i) moved to the end of its row as
    padding (−1 / 0), the other entries in their order, and each further [N, K] table permuted
    alike (0 on the padding): smg's graph takes no self edge, while D3DGS's and DreamScene4D's
    tables may hold them (each adds sqrt(0 + 1e-20) to the rigid and rot means and no gradient;
    the caller adds n_self such floors back)."""
    N = idx.shape[0]
    self_edge = idx == torch.arange(N, device=idx.device, dtype=idx.dtype)[:, None]
    n_self = int(self_edge.sum())
    if not n_self:
        return idx, w, 0, tables
    perm = torch.sort(self_edge.to(torch.int8), dim=1, stable=True).indices
    return (idx.masked_fill(self_edge, -1).gather(1, perm), w.masked_fill(self_edge, 0).gather(1, perm), n_self,
            tuple(t.masked_fill(self_edge, 0).gather(1, perm) for t in tables))


class _D3dgsPartsFunction(torch.autograd.Function):
    """(rigid, rot) of Dynamic 3D Gaussians from smg's fused step on the two-frame window
    x = [prev_pts, fg_pts], q = [prev_rot, fg_rot]: rigid is plain ARAP's coordinate part (E9)
    under sqrt_weighted (E24), rot the relative-rotation term (E25), each summed over the
    graph's edges with weight `scale` = 1/(N·K) (D3DGS's mean over N·K slots) plus `floor`, the
    sqrt(1e-20)·scale of each self edge the graph left out (its residual is 0 in both losses, so
    it adds exactly that and no gradient). Forward: where a gradient is wanted, one pass per loss
    with its gradient (each loss has its own weight upstream, and the two passes cost less than
    an energy pass and a gradient pass of both: 281 against 385 ms at N = 100 000, K = 20, 2
    threads); else one energy-only pass with both. Backward: g_r·∇rigid + g_q·∇rot of the frame-1
    rows (fg's; the previous state gets none). The two passes run side by side (_side_by_side:
    each is a two-frame window, one core)."""

    @staticmethod
    def forward(ctx, fg_pts, fg_rot, prev_pts, prev_rot, idx, w, scale, floor):
        x = torch.stack((prev_pts.detach(), fg_pts.detach()))
        q = torch.stack((prev_rot.detach(), fg_rot.detach()))
        need_x, need_q = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        if not (need_x or need_q):
            e, _, _ = _fused(x, q, idx, w, _d3dgs_terms(scale, scale), False, False)
            return fg_pts.new_tensor(e["arap"] + floor), fg_pts.new_tensor(e["relrot"] + floor)
        (er, gxr, gqr), (eq, gxq, gqq) = _side_by_side(
            not x.is_cuda, lambda: _fused(x, q, idx, w, _d3dgs_terms(scale, 0.0), need_x, need_q),
            lambda: _fused(x, q, idx, w, _d3dgs_terms(0.0, scale), need_x, need_q))
        ctx.grads = tuple(None if g is None else g[1] for g in (gxr, gqr, gxq, gqq))
        return fg_pts.new_tensor(er["arap"] + floor), fg_pts.new_tensor(eq["relrot"] + floor)

    @staticmethod
    @_first_order("compat.d3dgs_losses")
    def backward(ctx, g_rigid, g_rot):
        gxr, gqr, gxq, gqq = ctx.grads
        gx = None if gxr is None else gxr * g_rigid + gxq * g_rot
        gq = None if gqr is None else gqr * g_rigid + gqq * g_rot
        return gx, gq, None, None, None, None, None, None


def _d3dgs_terms(w_rigid, w_rot):
    """The fused step's terms for D3DGS's rigid and rot losses, with these weights (0 turns one
    off), summed (normalize=False: the weight holds the mean's 1/(N·K))."""
    sq = dict(penalty="sqrt_weighted", penalty_eps=_D3DGS_EPS, normalize=False)
    terms = {}
    if w_rigid != 0:
        terms["arap"] = dict(REGULARIZER_DEFAULTS["arap"], lambda_c=1.0, lambda_l=0.0, gaps=[1], gap_weights=[1.0],
                             weight=w_rigid, stop_gradient="none", **sq)
    if w_rot != 0:
        terms["relrot"] = dict(REGULARIZER_DEFAULTS["relrot"], weight=w_rot, **sq)
    return terms


class _EdgeIsometryFunction(torch.autograd.Function):
    """D3DGS's isometry loss through smg's (E26) (smg::edge_isometry, CPU): `scale` · Σ over the
    graph's edges of sqrt(w (sqrt(‖x_j − x_i‖² + 1e-20) − d0)² + 1e-20), plus `floor` (the self
    edges' constant terms the graph left out); the gradient formed in the same pass."""

    @staticmethod
    def forward(ctx, fg_pts, idx, w, d0, scale, floor):
        e, g = _C._edge_isometry(fg_pts.detach()[None], idx, w, d0, "sqrt_weighted", _D3DGS_EPS, _D3DGS_EPS, scale,
                                 ctx.needs_input_grad[0])
        ctx.grad = None if g is None else g[0]
        return e + floor

    @staticmethod
    @_first_order("compat.d3dgs_losses")
    def backward(ctx, g):
        return ctx.grad * g, None, None, None, None, None


class _D3dgsIsoFunction(torch.autograd.Function):
    """D3DGS's isometry loss, mean over N·K of sqrt(w (sqrt(‖x_j − x_i‖² + 1e-20) − d0)² + 1e-20),
    by chunks of rows (smg has no rest-length input: this loss alone is plain torch, with the
    gradient written out and formed in the forward pass when wanted): dL/dx_j = c e / ℓ and
    dL/dx_i = −Σ_j c e / ℓ with e = x_j − x_i, ℓ = sqrt(‖e‖² + 1e-20),
    c = w (ℓ − d0) / (N K sqrt(w (ℓ − d0)² + 1e-20)); the x_j part by scatter_add_ on the flat
    gradient (a third of index_add_'s time on a CPU)."""

    @staticmethod
    def forward(ctx, fg_pts, idx, w, d0):
        x = fg_pts.detach()
        N, K = idx.shape
        grad = ctx.needs_input_grad[0]
        total = x.new_zeros(())
        g = torch.zeros(N * 3, dtype=x.dtype, device=x.device) if grad else None
        xyz = torch.arange(3, device=x.device)
        for a in range(0, N, _D3DGS_ISO_ROWS):
            b = min(N, a + _D3DGS_ISO_ROWS)
            nb = idx[a:b]
            e = x[nb] - x[a:b, None]
            ell = torch.sqrt((e * e).sum(-1) + _D3DGS_EPS)
            r = ell - d0[a:b]
            root = torch.sqrt(r * r * w[a:b] + _D3DGS_EPS)
            total = total + root.sum()
            if grad:
                ge = (w[a:b] * r / (root * ell))[..., None] * e
                g.scatter_add_(0, (nb[..., None] * 3 + xyz).reshape(-1), ge.reshape(-1))
                g[3 * a:3 * b] -= ge.sum(1).reshape(-1)
        ctx.grad = None if g is None else g.view(N, 3) / (N * K)
        return total / (N * K)

    @staticmethod
    @_first_order("compat.d3dgs_losses")
    def backward(ctx, g):
        return ctx.grad * g, None, None, None


def d3dgs_losses(fg_pts: torch.Tensor, fg_rot: torch.Tensor, prev_pts: torch.Tensor, prev_rot: torch.Tensor,
                 neighbor_indices: torch.Tensor, neighbor_weight: torch.Tensor,
                 neighbor_dist: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Dynamic 3D Gaussians' rigidity, rotation and isometry losses (train.py get_loss, timesteps
    after the first) → (rigid, rot, iso): fg_pts [N, 3] and fg_rot [N, 4] the foreground means
    and normalised rotations (w x y z) being optimised; prev_pts, prev_rot the same at the end
    of the previous timestep (variables["prev_pts"][is_fg] and variables["prev_rot"][is_fg]: the
    state D3DGS's prev_offset and prev_inv_rot_fg are made from); neighbor_indices [N, K] (int64
    or int32, every slot a node: Open3D's KNN; a slot naming its own row, a self edge, is taken and
    adds sqrt(1e-20) to each mean, as upstream), neighbor_weight [N, K] ≥ 0, neighbor_dist [N, K]
    (variables["neighbor_*"], from the first timestep). fg_rot and prev_rot must be unit
    quaternions to 1e-5 (D3DGS normalises them; its rot loss on the raw products would scale with
    their norms, smg's normalises: a call off by more is refused, naming the row).

        rigid = mean sqrt(w ‖R(rel_i)ᵀ(x_j − x_i) − (p_j − p_i)‖² + 1e-20),  rel = fg_rot ⊗ prev_rot*
        rot   = mean sqrt(w ‖rel_j − rel_i‖² + 1e-20)
        iso   = mean sqrt(w (sqrt(‖x_j − x_i‖² + 1e-20) − d0_ij)² + 1e-20)

    How: rigid is smg's plain ARAP coordinate part (E9) with the sqrt_weighted penalty (E24) on the
    window [prev, fg] (the same norm: R(rel)ᵀ e = R_prev R_fgᵀ e, and R_prev is orthonormal), rot
    smg's relative-rotation term (E25); both from one fused pass forward and one backward. iso is
    smg's isometry against rest lengths (E26, smg::edge_isometry) on CPU tensors, and plain torch
    by chunks of rows with its gradient written out on CUDA ones.
    Gradients reach fg_pts and fg_rot (the previous state is a constant). fg_rot's gradient is
    that of the rotation: its radial part, which D3DGS's raw 4-vector "rot" has and
    F.normalize's backward then removes, is 0 here, so the gradient of the optimised
    unnorm_rotations is D3DGS's (docs/math/terms/relrot.md). CPU and CUDA tensors."""
    fg_pts, fg_rot, prev_pts, prev_rot = (_dense(n, t) for n, t in (("fg_pts", fg_pts), ("fg_rot", fg_rot),
                                                                     ("prev_pts", prev_pts), ("prev_rot", prev_rot)))
    neighbor_indices, neighbor_weight, neighbor_dist = (
        _dense(n, t) for n, t in (("neighbor_indices", neighbor_indices), ("neighbor_weight", neighbor_weight),
                                  ("neighbor_dist", neighbor_dist)))
    if fg_pts.dim() != 2 or fg_pts.shape[1] != 3 or fg_pts.shape[0] == 0:
        raise ValueError(f"fg_pts: expected shape [N, 3] with N >= 1, got {list(fg_pts.shape)}")
    _check_floats("fg_pts", fg_pts)
    N = fg_pts.shape[0]
    for name, t, shape in (("fg_rot", fg_rot, [N, 4]), ("prev_pts", prev_pts, [N, 3]), ("prev_rot", prev_rot, [N, 4])):
        if list(t.shape) != shape:
            raise ValueError(f"{name}: expected shape {shape} (N of fg_pts), got {list(t.shape)}")
    if neighbor_indices.dim() != 2 or neighbor_indices.shape[0] != N or neighbor_indices.shape[1] == 0:
        raise ValueError(f"neighbor_indices: expected shape [N, K] with N = {N}, K >= 1, got "
                         f"{list(neighbor_indices.shape)}")
    if neighbor_indices.dtype not in (torch.int64, torch.int32):
        raise ValueError(f"neighbor_indices: dtype must be int64 or int32, got {neighbor_indices.dtype}")
    for name, t in (("neighbor_weight", neighbor_weight), ("neighbor_dist", neighbor_dist)):
        if list(t.shape) != list(neighbor_indices.shape):
            raise ValueError(f"{name}: expected shape {list(neighbor_indices.shape)} (neighbor_indices'), "
                             f"got {list(t.shape)}")
    for name, t in (("fg_rot", fg_rot), ("prev_pts", prev_pts), ("prev_rot", prev_rot),
                    ("neighbor_weight", neighbor_weight), ("neighbor_dist", neighbor_dist)):
        if t.dtype != fg_pts.dtype:
            raise ValueError(f"{name}: dtype {t.dtype} differs from fg_pts' {fg_pts.dtype}")
    for name, t in (("fg_rot", fg_rot), ("prev_pts", prev_pts), ("prev_rot", prev_rot),
                    ("neighbor_indices", neighbor_indices), ("neighbor_weight", neighbor_weight),
                    ("neighbor_dist", neighbor_dist)):
        if t.device != fg_pts.device:
            raise ValueError(f"{name}: device {t.device} differs from fg_pts' {fg_pts.device}")
    # Contents, each refusal by the caller's name and index, before any work.
    _refuse_out_of_range("neighbor_indices", neighbor_indices, N, "a node", why=" (Open3D's KNN fills every slot)")
    _check_vectors("fg_pts", fg_pts)
    _check_vectors("prev_pts", prev_pts)
    for name, t in (("fg_rot", fg_rot), ("prev_rot", prev_rot)):
        _check_vectors(name, t, quaternions=True)
        off = (t.detach().norm(dim=-1) - 1).abs() > _D3DGS_UNIT_TOL
        if bool(off.any()):
            i = int(off.nonzero()[0])
            raise ValueError(f"{name}[{i}] has norm {float(t[i].detach().norm()):.9g}: d3dgs_losses takes unit "
                             "quaternions, as D3DGS's get_loss has them (F.normalize of unnorm_rotations); its rot "
                             "loss compares the raw products fg_rot ⊗ prev_rot*, which scale with their norms")
    _check_finite("neighbor_weight", neighbor_weight)
    _check_finite("neighbor_dist", neighbor_dist)
    _refuse_negative("neighbor_weight", neighbor_weight, "D3DGS")
    K = neighbor_indices.shape[1]
    idx = neighbor_indices.contiguous()
    w = neighbor_weight.contiguous()
    # Self edges (j = i: a duplicate point can come back from Open3D's KNN) are legal upstream,
    # where each adds sqrt(0 + 1e-20) to both means: padding here, their floor added back.
    d0 = neighbor_dist.contiguous()
    g_idx, g_w, n_self, (g_d0,) = _self_edges_as_padding(idx, w, d0)
    scale = 1.0 / (N * K)
    rigid, rot = _D3dgsPartsFunction.apply(fg_pts, fg_rot, prev_pts, prev_rot, g_idx, g_w, scale,
                                           n_self * math.sqrt(_D3DGS_EPS) * scale)
    if fg_pts.is_cuda:
        iso = _D3dgsIsoFunction.apply(fg_pts, idx.long(), w, d0)
    else:
        # A self edge's iso term is sqrt(w (sqrt(1e-20) − d0)² + 1e-20) with no gradient (its
        # offset is 0): added here as a constant, the rest by smg's (E26) over the graph.
        floor = 0.0
        if n_self:
            self_edge = idx == torch.arange(N, device=idx.device, dtype=idx.dtype)[:, None]
            ws, ds = w[self_edge].double(), d0[self_edge].double()
            floor = float(torch.sqrt(ws * (math.sqrt(_D3DGS_EPS) - ds) ** 2 + _D3DGS_EPS).sum()) * scale
        iso = _EdgeIsometryFunction.apply(fg_pts, g_idx, g_w, g_d0, scale, floor)
    return rigid, rot, iso


# ---- DreamScene4D (dreamscene4d/dreamscene4d, gs_renderer_4d.py) ------------------------------------

class _TwoFrameArapFunction(torch.autograd.Function):
    """smg's plain ARAP coordinate part (E9) under sqrt_weighted (E24) on the two-frame window
    x = [x0, x1], q = [q0, q1] (raw quaternions, normalised by smg), every edge weighted inside the
    root and the sum scaled by `scale`, plus `floor` (the self edges' sqrt(1e-20)·scale the graph
    left out); nothing held constant: the gradient reaches all four inputs, from the one pass
    that computes the value (where a gradient is wanted). The pass is the caller's
    (`_two_frame_arap_pass`, so that two of them can run side by side): `result` is its
    (energies, grad x, grad q). op: the caller, for _first_order."""

    @staticmethod
    def forward(ctx, x0, x1, q0, q1, floor, result, op):
        e, gx, gq = result
        ctx.grads = (None, None) if gx is None else (gx[0], gx[1])
        ctx.grads += (None, None) if gq is None else (gq[0], gq[1])
        ctx.op = op
        return x1.new_tensor(e["arap"] + floor)

    @staticmethod
    @_first_order("compat.ds4d_losses")
    def backward(ctx, g):
        return tuple(None if t is None or not need else t * g
                     for t, need in zip(ctx.grads, ctx.needs_input_grad[:4])) + (None,) * 3


def _two_frame_arap_pass(x0, x1, q0, q1, idx, w, scale):
    """The pass _TwoFrameArapFunction returns, as a function of no arguments (for _side_by_side):
    with the position and rotation gradients where autograd will want them (grad mode on and the
    input requiring one, which is what the Function's needs_input_grad then says)."""
    grad = torch.is_grad_enabled()
    need_x = grad and (x0.requires_grad or x1.requires_grad)
    need_q = grad and (q0.requires_grad or q1.requires_grad)
    return lambda: _fused(torch.stack((x0.detach(), x1.detach())), torch.stack((q0.detach(), q1.detach())), idx, w,
                          _d3dgs_terms(scale, 0.0), need_x, need_q)


def ds4d_losses(pos_curr: torch.Tensor, pos_prev: torch.Tensor, rot_deform_curr: torch.Tensor,
                rot_deform_prev: torch.Tensor, scales_deform_prev: torch.Tensor, scales_base: torch.Tensor,
                nn_indices: torch.Tensor, nn_weights: torch.Tensor, *,
                order: str = "upstream") -> Tuple[torch.Tensor, torch.Tensor]:
    """DreamScene4D's `local_scale_loss` and `local_rigidity_loss` (gs_renderer_4d.py,
    Renderer.render_flow) → (scale, rigidity), each a mean over the N·K slots of the
    precompute_nn table:

        scale     = mean sqrt(w_ij ‖s_j − s_i‖² + 1e-20),   s = scales_deform_prev − scales_base
        rigidity  = mean sqrt(w_ij ‖(p_j − p_i) − R(rel_i)ᵀ (c_j − c_i)‖² + 1e-20),
                    rel = q̂_prev ⊗ q̂_curr*   (order="upstream")

    pos_curr, pos_prev [N, 3]: gaussian_3d_pos_curr / _prev (get_2d_gaussian_pos' means);
    rot_deform_curr, rot_deform_prev [N, 4] (w x y z): the deformation network's raw rotations
    at the two times (rotations_deform_T / prev_rotations_deform_T), normalised here as
    rotation_activation (F.normalize) does; scales_deform_prev, scales_base [N, 3]: the raw
    (log) scales, prev_scales_deform_T and gaussians._scaling; nn_indices [N, K] (int32/int64,
    every slot a point; cKDTree's table, the point itself in column 0: a self edge adds
    sqrt(1e-20) to the mean and nothing else, as upstream), nn_weights [N, K] >= 0 (upstream's
    exp(−10 d), float64 from numpy: taken in pos_curr's dtype here, where upstream's products are
    promoted to float64). Nothing is held constant, as upstream detaches nothing: gradients reach
    all six tensors (the rotations' through the normalisation, as F.normalize's backward gives).

    order="upstream" reproduces the code as read: rel = rotations_final ⊗ curr_rotations_final⁻¹
    composes the previous rotation with the inverse of the current one, the reverse of the
    Dynamic 3D Gaussians code it follows (rel = q_curr ⊗ q_prev*), so that a rigid motion whose
    Gaussians co-rotate with it is not at zero loss (by ‖(R_Δ² − I) e‖). order="d3dgs" is
    D3DGS's composition (zero, up to the 1e-20 floors, on such a motion).

    How: both losses are smg's plain ARAP coordinate part (E9) under the sqrt_weighted penalty
    (E24) on a two-frame window, one fused pass each with its gradient: rigidity on
    x = [pos_prev, pos_curr] with q = [q_curr, q_prev] (upstream's order: ‖R_curr R_prevᵀ e_c −
    e_p‖ is its norm) or [q_prev, q_curr] (D3DGS's), scale on x = [0, s] with identity rotations.
    CPU and CUDA tensors."""
    names = ("pos_curr", "pos_prev", "rot_deform_curr", "rot_deform_prev", "scales_deform_prev", "scales_base",
             "nn_indices", "nn_weights")
    pos_curr, pos_prev, rot_curr, rot_prev, sc_prev, sc_base, idx, w = (
        _dense(n, t) for n, t in zip(names, (pos_curr, pos_prev, rot_deform_curr, rot_deform_prev,
                                             scales_deform_prev, scales_base, nn_indices, nn_weights)))
    if order not in ("upstream", "d3dgs"):
        raise ValueError(f"order: must be 'upstream' (DreamScene4D's code) or 'd3dgs' (Dynamic 3D Gaussians' "
                         f"composition), got {order!r}")
    if pos_curr.dim() != 2 or pos_curr.shape[1] != 3 or pos_curr.shape[0] == 0:
        raise ValueError(f"pos_curr: expected shape [N, 3] with N >= 1, got {list(pos_curr.shape)}")
    _check_floats("pos_curr", pos_curr)
    N = pos_curr.shape[0]
    for name, t, shape in (("pos_prev", pos_prev, [N, 3]), ("rot_deform_curr", rot_curr, [N, 4]),
                           ("rot_deform_prev", rot_prev, [N, 4]), ("scales_deform_prev", sc_prev, [N, 3]),
                           ("scales_base", sc_base, [N, 3])):
        if list(t.shape) != shape:
            raise ValueError(f"{name}: expected shape {shape} (N of pos_curr), got {list(t.shape)}")
        if t.dtype != pos_curr.dtype:
            raise ValueError(f"{name}: dtype {t.dtype} differs from pos_curr's {pos_curr.dtype}")
    if idx.dim() != 2 or idx.shape[0] != N or idx.shape[1] == 0:
        raise ValueError(f"nn_indices: expected shape [N, K] with N = {N}, K >= 1, got {list(idx.shape)}")
    if idx.dtype not in (torch.int64, torch.int32):
        raise ValueError(f"nn_indices: dtype must be int64 or int32, got {idx.dtype}")
    if list(w.shape) != list(idx.shape):
        raise ValueError(f"nn_weights: expected shape {list(idx.shape)} (nn_indices'), got {list(w.shape)}")
    if w.dtype not in (torch.float32, torch.float64):
        raise ValueError(f"nn_weights: dtype must be float32 or float64, got {w.dtype}")
    for name, t in zip(names[1:], (pos_prev, rot_curr, rot_prev, sc_prev, sc_base, idx, w)):
        if t.device != pos_curr.device:
            raise ValueError(f"{name}: device {t.device} differs from pos_curr's {pos_curr.device}")
    _refuse_out_of_range("nn_indices", idx, N, "a point", why=" (cKDTree's table fills every slot)")
    for name, t in (("pos_curr", pos_curr), ("pos_prev", pos_prev), ("scales_deform_prev", sc_prev),
                    ("scales_base", sc_base)):
        _check_vectors(name, t)
    _check_vectors("rot_deform_curr", rot_curr, quaternions=True)
    _check_vectors("rot_deform_prev", rot_prev, quaternions=True)
    _check_finite("nn_weights", w)
    _refuse_negative("nn_weights", w, "DreamScene4D")
    K = idx.shape[1]
    # Self edges (cKDTree's column 0) as padding, their floor added back.
    g_idx, g_w, n_self, _ = _self_edges_as_padding(idx.contiguous(), w.to(pos_curr.dtype).contiguous())
    scale = 1.0 / (N * K)
    floor = n_self * math.sqrt(_D3DGS_EPS) * scale
    q0, q1 = (rot_curr, rot_prev) if order == "upstream" else (rot_prev, rot_curr)
    s = sc_prev - sc_base
    ident = torch.zeros((N, 4), dtype=pos_curr.dtype, device=pos_curr.device)
    ident[:, 0] = 1
    zero = torch.zeros_like(s)
    # The two passes side by side (each a two-frame window: one core each).
    rig, sca = _side_by_side(not pos_curr.is_cuda, _two_frame_arap_pass(pos_prev, pos_curr, q0, q1, g_idx, g_w, scale),
                             _two_frame_arap_pass(zero, s, ident, ident, g_idx, g_w, scale))
    rigidity = _TwoFrameArapFunction.apply(pos_prev, pos_curr, q0, q1, floor, rig, "compat.ds4d_losses")
    scale_loss = _TwoFrameArapFunction.apply(zero, s, ident, ident, floor, sca, "compat.ds4d_losses")
    return scale_loss, rigidity


# ---- Dynamic Gaussian Marbles (coltonstearns/dynamic-gaussian-marbles, src/models/gaussians.py) ----

# Edges per chunk of the edge-list losses below (DynOMo's): a few [chunk, 3] temporaries at a
# time (about 1 MiB each in float32), not [E, 3] ones.
_EDGE_CHUNK = 1 << 16


def _check_edge_index(name, t, n_edges, hi, hi_name, device):
    """A 1-D int32/int64 edge index of n_edges entries (None: any length) in [0, hi), on `device`;
    else one error naming it (the first bad entry by its index)."""
    t = _dense(name, t)
    if t.dtype not in (torch.int64, torch.int32):
        raise ValueError(f"{name}: dtype must be int64 or int32, got {t.dtype}")
    if t.dim() != 1 or (n_edges is not None and t.shape[0] != n_edges):
        want = "[E]" if n_edges is None else f"[{n_edges}]"
        raise ValueError(f"{name}: expected shape {want}, got {list(t.shape)}")
    if t.device != device:
        raise ValueError(f"{name}: device {t.device} differs from {hi_name}'s {device}")
    _refuse_out_of_range(name, t, hi, f"a row of {hi_name}")
    return t.long()


def _check_points(name, t, N, like):
    """t [N, 3] (N None: any N >= 0) of like's dtype and device, finite; returns it dense."""
    t = _dense(name, t)
    if t.dim() != 2 or t.shape[1] != 3 or (N is not None and t.shape[0] != N):
        raise ValueError(f"{name}: expected shape [{'N' if N is None else N}, 3], got {list(t.shape)}")
    if like is None:
        _check_floats(name, t)
    else:
        if t.dtype != like[1].dtype:
            raise ValueError(f"{name}: dtype {t.dtype} differs from {like[0]}'s {like[1].dtype}")
        if t.device != like[1].device:
            raise ValueError(f"{name}: device {t.device} differs from {like[0]}'s {like[1].device}")
    _check_vectors(name, t)
    return t


def _scatter_rows(g, rows, v):
    """g [R, C] += v [E, C] at rows [E] (repeats summed in edge order): scatter_add_ on the flat
    storage, about a third of index_add_'s time on a CPU."""
    C = v.shape[1]
    flat = (rows[:, None] * C + torch.arange(C, device=rows.device)).reshape(-1)
    g.view(-1).scatter_add_(0, flat, v.reshape(-1))


def _length_grad(e, d, c):
    """c_e · ∂‖e‖/∂e = c e / ‖e‖ per edge, 0 where ‖e‖ = 0 (torch.norm's backward there)."""
    return torch.where(d > 0, c / torch.where(d > 0, d, torch.ones_like(d)), torch.zeros_like(d))[:, None] * e


class _MarblesIsometryFunction(torch.autograd.Function):
    """Per-edge errors of Marbles' adjacent isometry on the masked subset xs = xyz[mask]; the
    backward sums g_e · ∂err_e/∂x over the kept edges into xyz's masked rows."""

    @staticmethod
    def forward(ctx, xyz, mask, p, k, d_src, avg, use_l2, keep):
        xs = xyz.detach()[mask]
        e = xs.index_select(0, p) - xs.index_select(0, k)
        d = torch.linalg.vector_norm(e, dim=-1)  # torch.norm(·, dim=-1), as upstream
        diffs = d - d_src
        if keep is not None:
            diffs, e, d, p, k = diffs[keep], e[keep], d[keep], p[keep], k[keep]
        err = diffs ** 2 / avg ** 2 if use_l2 else torch.abs(diffs) / avg
        if ctx.needs_input_grad[0]:
            coef = 2.0 * diffs / avg ** 2 if use_l2 else torch.sign(diffs) / avg
            ctx.save_for_backward(mask, p, k, _length_grad(e, d, coef))
        return err

    @staticmethod
    @_first_order("compat.marbles_isometry")
    def backward(ctx, g):
        mask, p, k, v = ctx.saved_tensors
        gv = g[:, None] * v
        gs = torch.zeros((int(mask.sum()), 3), dtype=v.dtype, device=v.device)
        _scatter_rows(gs, p, gv)
        _scatter_rows(gs, k, -gv)
        gx = torch.zeros((mask.shape[0], 3), dtype=v.dtype, device=v.device)
        gx[mask] = gs
        return gx, None, None, None, None, None, None, None


def marbles_isometry(xyz: torch.Tensor, src_xyz: torch.Tensor, point_idxs: torch.Tensor, knn_idxs: torch.Tensor,
                     mask: torch.Tensor, *, use_l2: bool = False,
                     valid_mask: Optional[torch.Tensor] = None) -> torch.Tensor:
    """Dynamic Gaussian Marbles' adjacent isometry errors (GaussianModel._compute_adjacent_isometry_helper,
    src/models/gaussians.py) → err [E'], one per kept edge, with autograd to xyz:

        d_e = ‖xs[p_e] − xs[k_e]‖,  s_e = ‖ss[p_e] − ss[k_e]‖ (held constant),  A = mean_e s_e
        err_e = |d_e − s_e| / A      (use_l2: (d_e − s_e)² / A²)

    xyz [N, 3]: the means mapped to the frame being learned (get_mapped_means3D(frameidx));
    src_xyz [N, 3]: the same at the adjacent frame src_idx = frameidx ± 1 (its live estimate,
    detached here as upstream detaches its distances); mask [N] bool: the Gaussians of the cached
    half (xs = xyz[mask], ss = src_xyz[mask]); point_idxs, knn_idxs [E] int32/int64: the cached
    edges (_cache_isometry_knn: frnn's table without its −1 slots, self edges included, indices
    into the masked subset); valid_mask [N] bool or None: the bundle-adjust dropout, keeping the
    edges whose point is valid (valid_mask[mask][point_idxs]) after A is formed over all edges.
    The caller's reduction stays theirs (field.py compute_isometry_loss: a leading zero, the
    background factor, .mean()).

    As read, reproduced: A averages every cached edge, self edges (length 0) and dropped ones
    included; a self edge's error is |0 − 0| / A = 0 with no gradient (torch.norm's and abs'
    backward at 0). Refused: a zero A with edges (upstream's errors would be NaN or inf)."""
    xyz = _check_points("xyz", xyz, None, None)
    N = xyz.shape[0]
    src_xyz = _check_points("src_xyz", src_xyz, N, ("xyz", xyz))
    mask = _dense("mask", mask)
    if mask.dtype != torch.bool or list(mask.shape) != [N]:
        raise ValueError(f"mask: expected a bool tensor of shape [{N}] (N of xyz), got {mask.dtype} "
                         f"{list(mask.shape)}")
    if mask.device != xyz.device:
        raise ValueError(f"mask: device {mask.device} differs from xyz's {xyz.device}")
    M = int(mask.sum())
    p = _check_edge_index("point_idxs", point_idxs, None, M, "xyz[mask]", xyz.device)
    k = _check_edge_index("knn_idxs", knn_idxs, p.shape[0], M, "xyz[mask]", xyz.device)
    keep = None
    if valid_mask is not None:
        valid_mask = _dense("valid_mask", valid_mask)
        if valid_mask.dtype != torch.bool or list(valid_mask.shape) != [N]:
            raise ValueError(f"valid_mask: expected a bool tensor of shape [{N}] (N of xyz) or None, got "
                             f"{valid_mask.dtype} {list(valid_mask.shape)}")
        if valid_mask.device != xyz.device:
            raise ValueError(f"valid_mask: device {valid_mask.device} differs from xyz's {xyz.device}")
        keep = valid_mask[mask].index_select(0, p)
    ss = src_xyz.detach()[mask]
    d_src = torch.linalg.vector_norm(ss.index_select(0, p) - ss.index_select(0, k), dim=-1)
    if p.shape[0] == 0:
        return xyz.new_zeros((0,)) + 0.0 * xyz.sum()  # no edges: no errors, still in the graph
    avg = d_src.mean().item()  # a Python float, as upstream's .item()
    if not avg > 0:
        raise ValueError("src_xyz: every cached edge has length 0 at the source frame: Marbles divides by their "
                         "mean (avg_neighbor_dist), so its errors would be NaN or inf")
    return _MarblesIsometryFunction.apply(xyz, mask, p, k, d_src, avg, bool(use_l2), keep)


class _MarblesGlobalRigidFunction(torch.autograd.Function):
    """mean_e |‖t_a − t_b‖ − o_e| with o_e the template's lengths; gradient to t only."""

    @staticmethod
    def forward(ctx, t, i1, i2, orig):
        x = t.detach()
        e = x.index_select(0, i1) - x.index_select(0, i2)
        new = torch.linalg.vector_norm(e, dim=-1)
        diff = orig - new
        loss = torch.abs(diff).mean()
        if ctx.needs_input_grad[0]:
            v = _length_grad(e, new, -torch.sign(diff) / diff.shape[0])
            g = torch.zeros_like(x)
            _scatter_rows(g, i1, v)
            _scatter_rows(g, i2, -v)
            ctx.grad = g
        return loss

    @staticmethod
    @_first_order("compat.marbles_global_rigid")
    def backward(ctx, g):
        return ctx.grad * g, None, None, None


def marbles_global_rigid(xyz: torch.Tensor, transformed_xyz: torch.Tensor, idx1: torch.Tensor,
                         idx2: torch.Tensor) -> torch.Tensor:
    """Dynamic Gaussian Marbles' instance isometry (GaussianModel._compute_global_rigid_loss,
    src/models/gaussians.py) on the drawn pairs → the scalar loss, with autograd to transformed_xyz:

        loss = mean_e |‖xyz[a_e] − xyz[b_e]‖ − ‖t[a_e] − t[b_e]‖|,   a = idx1, b = idx2

    xyz [N, 3]: the frozen template (compute_instance_isometry_loss's halves mapped to their
    source frames, detached: no gradient reaches it here either); transformed_xyz [N, 3]: the means
    mapped to the frame being learned; idx1, idx2 [P] int32/int64: the pairs upstream draws per
    segment (torch.randperm: the draw stays the caller's). Upstream reorders both arrays by its
    segment sort first: pass them reordered (xyz[reorder], transformed_xyz[reorder]) with its
    indices, or the original arrays with reorder[idx1], reorder[idx2]. A pair of one point twice,
    or two coincident points, adds |o − 0| with no gradient through its zero length (torch.norm's
    backward at 0). Refused: no pairs (upstream's mean would be NaN)."""
    transformed_xyz = _check_points("transformed_xyz", transformed_xyz, None, None)
    N = transformed_xyz.shape[0]
    xyz = _check_points("xyz", xyz, N, ("transformed_xyz", transformed_xyz))
    a = _check_edge_index("idx1", idx1, None, N, "transformed_xyz", xyz.device)
    b = _check_edge_index("idx2", idx2, a.shape[0], N, "transformed_xyz", xyz.device)
    if a.shape[0] == 0:
        raise ValueError("idx1: no pairs (upstream's mean over them would be NaN)")
    x = xyz.detach()
    orig = torch.linalg.vector_norm(x.index_select(0, a) - x.index_select(0, b), dim=-1)
    return _MarblesGlobalRigidFunction.apply(transformed_xyz, a, b, orig)


# ---- DynOMo (dvl-tum/DynOMo, src/utils/losses.py physics_based_losses) ---------------------------

def _dynomo_rotations(curr, prev):
    """(rel, R) of physics_based_losses: rel = curr ⊗ prev* on the raw quaternions (w x y z; quat_mult
    of curr_rot and other_rot, its vector part negated), R = build_rotation(rel) [N, 3, 3] (rel over
    its norm + 1e-20). Differentiable torch ops over N rows, for the chain rule to curr."""
    w1, x1, y1, z1 = curr.unbind(-1)
    w2, x2, y2, z2 = prev[:, 0], -prev[:, 1], -prev[:, 2], -prev[:, 3]
    rel = torch.stack((w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                       w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                       w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                       w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2), dim=-1)
    u = rel / (torch.sqrt((rel * rel).sum(-1)) + _D3DGS_EPS)[:, None]
    r, x, y, z = u.unbind(-1)
    R = torch.stack((1 - 2 * (y * y + z * z), 2 * (x * y - r * z), 2 * (x * z + r * y),
                     2 * (x * y + r * z), 1 - 2 * (x * x + z * z), 2 * (y * z - r * x),
                     2 * (x * z - r * y), 2 * (y * z + r * x), 1 - 2 * (x * x + y * y)), dim=-1).view(-1, 3, 3)
    return rel, R


class _DynomoFunction(torch.autograd.Function):
    """(rigid, rot, iso) of DynOMo by chunks of edges, each loss's gradient (to curr_means and, through
    _dynomo_rotations' chain, curr_rot) formed in the forward pass when wanted; the backward scales
    them by their incoming gradients."""

    @staticmethod
    def forward(ctx, curr_means, curr_rot, prev_means, prev_rot, s_idx, n_idx, w, offset_0):
        x, p, q0 = curr_means.detach(), prev_means.detach(), prev_rot.detach()
        need_x, need_q = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        E = s_idx.shape[0]
        with torch.enable_grad():
            c = curr_rot.detach().requires_grad_(need_q)
            rel_g, R_g = _dynomo_rotations(c, q0)
        rel, R = rel_g.detach(), R_g.detach()
        eps = _D3DGS_EPS
        sums = [x.new_zeros(()) for _ in range(3)]
        gx = [torch.zeros_like(x) for _ in range(2)] if need_x else None  # rigid, iso
        gR = torch.zeros((x.shape[0], 9), dtype=x.dtype, device=x.device) if need_q else None
        grel = torch.zeros_like(rel) if need_q else None
        for a in range(0, E, _EDGE_CHUNK):
            b = min(E, a + _EDGE_CHUNK)
            s, n, wc = s_idx[a:b], n_idx[a:b], w[a:b, None]
            o = x.index_select(0, s) - x.index_select(0, n)
            Rs = R.index_select(0, s)
            r = (Rs.transpose(2, 1) @ o[..., None])[..., 0] - (p.index_select(0, s) - p.index_select(0, n))
            root = torch.sqrt(r * r + eps)
            sums[0] = sums[0] + (root * wc).sum()
            d = rel.index_select(0, n) - rel.index_select(0, s)
            droot = torch.sqrt(d * d + eps)
            sums[1] = sums[1] + (droot * wc).sum()
            ell = torch.sqrt((o * o).sum(-1) + eps)
            o0 = offset_0[a:b]
            ell0 = torch.sqrt((o0 * o0).sum(-1) + eps)
            ri = ell - ell0
            iroot = torch.sqrt(ri * ri + eps)
            sums[2] = sums[2] + (iroot * wc[:, 0]).sum()
            if need_x or need_q:
                h = wc * r / root / (3 * E)  # ∂rigid/∂r
            if need_x:
                f = (Rs @ h[..., None])[..., 0]  # ∂rigid/∂o = R_s h
                _scatter_rows(gx[0], s, f)
                _scatter_rows(gx[0], n, -f)
                fi = (wc[:, 0] * ri / (iroot * ell) / E)[:, None] * o  # ∂iso/∂o
                _scatter_rows(gx[1], s, fi)
                _scatter_rows(gx[1], n, -fi)
            if need_q:
                _scatter_rows(gR, s, (o[:, :, None] * h[:, None, :]).reshape(-1, 9))  # ∂/∂R_rc = o_r h_c
                hd = wc * d / droot / (4 * E)
                _scatter_rows(grel, n, hd)
                _scatter_rows(grel, s, -hd)
        grads = [None] * 6  # (x, q) of rigid, rot, iso
        if need_x:
            grads[0], grads[4] = gx
        if need_q:
            grads[1], = torch.autograd.grad(R_g, c, gR.view(-1, 3, 3), retain_graph=True)
            grads[3], = torch.autograd.grad(rel_g, c, grel)
        ctx.grads = grads
        return sums[0] / (3 * E), sums[1] / (4 * E), sums[2] / E

    @staticmethod
    @_first_order("compat.dynomo_losses")
    def backward(ctx, g_rigid, g_rot, g_iso):
        gs = ctx.grads

        def combine(parts):
            out = None
            for t, g in parts:
                if t is not None:
                    out = t * g if out is None else out + t * g
            return out
        gx = combine(((gs[0], g_rigid), (gs[2], g_rot), (gs[4], g_iso)))
        gq = combine(((gs[1], g_rigid), (gs[3], g_rot), (gs[5], g_iso)))
        return gx, gq, None, None, None, None, None, None


def dynomo_losses(curr_means: torch.Tensor, curr_rot: torch.Tensor, prev_means: torch.Tensor,
                  prev_rot: torch.Tensor, self_indices: torch.Tensor, neighbor_indices: torch.Tensor,
                  neighbor_weight: torch.Tensor,
                  offset_0: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """DynOMo's physics-based losses (physics_based_losses, src/utils/losses.py, iter_time_idx ≥ 1)
    → (rigid, rot, iso), each l2_loss_v2's mean of a per-component sqrt(r_c² + 1e-20) times the
    edge weight (outside the root):

        rel    = q_curr ⊗ q_prev*  (raw quaternions, not normalised),  R = build_rotation(rel)
        rigid  = mean over 3E of w_e sqrt((R_sᵀ(x_s − x_n) − (p_s − p_n))_c² + 1e-20)
        rot    = mean over 4E of w_e sqrt((rel_n − rel_s)_c² + 1e-20)
        iso    = mean over E of w_e sqrt((ℓ(x_s − x_n) − ℓ(o0_e))² + 1e-20),  ℓ(v) = sqrt(‖v‖² + 1e-20)

    curr_means [N, 3], curr_rot [N, 4] (w x y z, the raw unnorm_rotations being optimised) at the
    current time; prev_means, prev_rot the same at iter_time_idx − 1 (held constant, as upstream
    detaches them); self_indices, neighbor_indices [E] (int32/int64; variables["self_indices"] and
    ["neighbor_indices"]: self edges allowed, as upstream keeps them); neighbor_weight [E];
    offset_0 [E, 3] (variables["offset_0"], the stored first offsets; their bookkeeping at
    iter == 0 stays upstream's). Gradients reach curr_means and curr_rot (the rotations' through
    the raw product and build_rotation's normalisation, as autograd gives upstream).

    As read, reproduced: rot compares relative rotations of raw quaternions, so it scales with
    ‖q_curr‖‖q_prev‖ and has a radial gradient; each component is its own Charbonnier term (the
    loss is not invariant to a rotation of the scene); a self edge adds w·sqrt(1e-20) per
    component and no gradient. Refused: no edges (upstream's means would be NaN), zero quaternions
    (build_rotation's gradient there is NaN). Plain torch by chunks of edges, with each gradient
    written out (smg has no per-component penalty yet)."""
    curr_means = _check_points("curr_means", curr_means, None, None)
    N = curr_means.shape[0]
    like = ("curr_means", curr_means)
    prev_means = _check_points("prev_means", prev_means, N, like)
    rots = []
    for name, t in (("curr_rot", curr_rot), ("prev_rot", prev_rot)):
        t = _dense(name, t)
        if list(t.shape) != [N, 4]:
            raise ValueError(f"{name}: expected shape [{N}, 4] (N of curr_means), got {list(t.shape)}")
        if t.dtype != curr_means.dtype or t.device != curr_means.device:
            raise ValueError(f"{name}: {t.dtype} on {t.device} differs from curr_means' {curr_means.dtype} on "
                             f"{curr_means.device}")
        _check_vectors(name, t, quaternions=True)
        rots.append(t)
    s = _check_edge_index("self_indices", self_indices, None, N, "curr_means", curr_means.device)
    E = s.shape[0]
    if E == 0:
        raise ValueError("self_indices: no edges (upstream's means over 3E, 4E and E entries would be NaN)")
    n = _check_edge_index("neighbor_indices", neighbor_indices, E, N, "curr_means", curr_means.device)
    w = _dense("neighbor_weight", neighbor_weight)
    if list(w.shape) != [E]:
        raise ValueError(f"neighbor_weight: expected shape [{E}] (E of self_indices), got {list(w.shape)}")
    if w.dtype != curr_means.dtype or w.device != curr_means.device:
        raise ValueError(f"neighbor_weight: {w.dtype} on {w.device} differs from curr_means' {curr_means.dtype} on "
                         f"{curr_means.device}")
    _check_finite("neighbor_weight", w)
    offset_0 = _dense("offset_0", offset_0)
    if list(offset_0.shape) != [E, 3]:
        raise ValueError(f"offset_0: expected shape [{E}, 3] (E of self_indices), got {list(offset_0.shape)}")
    if offset_0.dtype != curr_means.dtype or offset_0.device != curr_means.device:
        raise ValueError(f"offset_0: {offset_0.dtype} on {offset_0.device} differs from curr_means' "
                         f"{curr_means.dtype} on {curr_means.device}")
    _check_vectors("offset_0", offset_0)
    return _DynomoFunction.apply(curr_means, rots[0], prev_means, rots[1], s, n, w.detach(), offset_0.detach())


# ---- neighbour tables as each codebase's tool returns them (smg_torch.knn_points underneath) ----

def _knn_input(name, points, dtype=None):
    """points as a [N, 3] tensor (numpy arrays and lists taken as the upstream helpers take them)."""
    if not isinstance(points, torch.Tensor):
        try:
            points = torch.as_tensor(points)
        except (TypeError, ValueError, RuntimeError) as e:
            raise TypeError(f"{name}: expected a [N, 3] array or tensor, got {type(points).__name__}") from e
    if points.dim() != 2 or points.shape[1] != 3:
        raise ValueError(f"{name}: expected shape [N, 3], got {list(points.shape)}")
    if dtype is not None:
        points = points.detach().to(dtype)
    elif not points.is_floating_point():
        points = points.to(torch.get_default_dtype())
    return points


def open3d_knn(pts, num_knn: int):
    """Dynamic 3D Gaussians' `o3d_knn(pts, num_knn)` (helpers.py, kept by DynOMo): for every point,
    Open3D's `KDTreeFlann.search_knn_vector_3d(p, num_knn + 1)` over the points as float64 with the
    first column (the point itself) dropped. -> (sq_dists float64 [N, num_knn], indices int32
    [N, num_knn]) as numpy arrays, the dtypes `np.array` gives Open3D's DoubleVector and
    IntVector, on which the upstream code then calls torch.tensor(...).

    Differences, both where upstream has no defined answer: fewer than num_knn + 1 points pad with
    -1 / inf (upstream's rows would be ragged); among points at exactly equal distance the lower
    index comes first (Open3D's order among exact ties is its tree's), so of exact duplicates the
    lower index is the dropped column 0 of both rows."""
    p = _knn_input("pts", pts, torch.float64)
    d2, idx = knn_points(p.cpu(), int(num_knn) + 1)
    return d2[:, 1:].numpy(), idx[:, 1:].to(torch.int32).numpy()


def ckdtree_knn(data, k: int, distance_upper_bound: float = math.inf):
    """scipy's `cKDTree(data).query(data, k=k, distance_upper_bound=...)`, the table DreamScene4D's
    `precompute_nn` builds (gs_renderer_4d.py, k = 16): data as float64, Euclidean distances
    (not squared), the point itself in column 0. -> (distances float64, indices int64) numpy
    arrays [N, k] ([N] for k = 1, as cKDTree); missing neighbours (distance >= the bound, which
    cKDTree excludes) are inf and index N, as cKDTree pads.

    Difference: among points at exactly equal distance the lower index comes first; cKDTree's
    order among exact ties is its tree's (for exact duplicates its column 0 may be the other
    copy), so a row may list tied neighbours in another order or, at the k-th place, another
    neighbour at the same distance."""
    p = _knn_input("data", data, torch.float64).cpu()
    bound = float(distance_upper_bound)
    if not bound > 0:
        raise ValueError(f"distance_upper_bound: must be > 0, got {bound}")
    d2, idx = knn_points(p, int(k), radius=None if math.isinf(bound) else bound)
    d = d2.sqrt()
    cut = (idx < 0) | ~(d < bound)  # cKDTree keeps d < bound only
    d[cut] = math.inf
    idx[cut] = p.shape[0]
    d, idx = d.numpy(), idx.numpy()
    return (d[:, 0], idx[:, 0]) if int(k) == 1 else (d, idx)


def frnn_knn(points: torch.Tensor, K: int, r: float, segments: Optional[torch.Tensor] = None):
    """frnn's `frnn_grid_points(points[None], points[None], K=K, r=r)` (points1 = points2, the
    table Dynamic Gaussian Marbles' `_cache_isometry_knn` builds, K = 32, r = 0.1 there, 24 / 0.3
    in its configs): squared distances d² <= r² in the points' dtype, self included, sorted.
    -> (dists [1, N, K], idxs int64 [1, N, K]) with frnn's padding: -1 in both.

    segments [N] (optional, integer labels): neighbours only within a point's segment — what
    Marbles gets by appending segment * 2r as a fourth coordinate (two segments are then at least
    2r apart; within one the fourth difference is 0, so d² is the 3D one).
    Difference: among points at exactly equal distance the lower index comes first (frnn's order
    among exact ties is its grid's)."""
    p = _knn_input("points", points)
    K, r = int(K), float(r)
    if not r >= 0:
        raise ValueError(f"r: must be >= 0, got {r}")
    if segments is None:
        d2, idx = knn_points(p.detach(), K, radius=r)
    else:
        if not isinstance(segments, torch.Tensor) or segments.shape != (p.shape[0],):
            raise ValueError(f"segments: expected a tensor of shape [{p.shape[0]}] (one label per point)")
        d2 = torch.full((p.shape[0], K), math.inf, dtype=p.dtype, device=p.device)
        idx = torch.full((p.shape[0], K), -1, dtype=torch.long, device=p.device)
        for label in torch.unique(segments):
            members = (segments == label).nonzero().flatten()
            sd2, sidx = knn_points(p.detach()[members], K, radius=r)
            d2[members] = sd2
            idx[members] = torch.where(sidx >= 0, members[sidx.clamp(min=0)], sidx)
    d2 = torch.where(idx >= 0, d2, d2.new_full((), -1.0))
    return d2[None], idx[None]
