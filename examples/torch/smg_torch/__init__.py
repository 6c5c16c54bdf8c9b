"""smg_torch — smg's Semantic Motion Graph regularisers as PyTorch operators (CPU tensors; with a CUDA
build, also CUDA tensors for node_confidences, carap, arap, lrm, regularizers, dqb and knn_points: docs/cuda.md).

    import smg_torch as smg
    c = smg.node_confidences(positions, g)                        # [T, N], no grad
    e = smg.carap(positions, quats, g, c) + smg.lrm(positions, g, c)
    e.backward()                                                  # analytic gradients
    r = smg.regularizers(positions, quats, g, visibility)         # the same in one fused pass
    r.total.backward()                                            # (CPU or CUDA tensors)

Shapes and meanings: docs/interop.md. Every energy returns a 0-dim tensor and is differentiable
w.r.t. positions [T, N, 3] and the raw, unnormalised quaternions [T, N, 4] (w, x, y, z);
confidences and graph weights are constants. The gradient is computed together with the energy
in forward (the library's kernels produce both in one pass, cheaper than a second pass) when an
input requires grad, and backward scales it by grad_output (energies are linear in it).
float32 and float64; contiguous CPU tensors are read in place; non-contiguous ones are copied
once (.contiguous()); graph indices int32 or int64 are read in place; graph weights of the
other float dtype are converted. Errors raise ValueError with the library's one-line message,
naming the Python argument.

Device: each operator takes CPU or CUDA tensors; the device of its first tensor (positions,
node_positions) decides, in the compiled module. A CUDA tensor raises NotImplementedError for an
operator without CUDA code (build_graph, render) or when smg_torch was built without CUDA.

Instruction set: the energy operators run from smg_torch._C_avx2 (-mavx2 -mfma) on a CPU with AVX2
and FMA, else from _C (SSE2); `isa` says which, SMG_TORCH_ISA=base forces _C (docs/torch.md).

Memory limit: before allocating a large output (dqb's [Q, P, 7] blended frames, render's images
and buffers, build_graph's [N, k] tables), the request's memory is estimated and refused with a
ValueError naming the argument that makes it large when above the limit, as smg_cli's
--max-memory-gb does (docs/interop.md "Limits"): 8 GiB by default, set with
set_memory_limit(bytes) or, at import, the environment variable SMG_TORCH_MAX_MEMORY_GB (GiB);
memory_limit() returns it. An allocation that fails anyway is a ValueError naming the argument.
Integer arguments (k, m, min_covisible, gaps, width, height, tile_size) are range-checked before
they are narrowed: a ValueError names the argument.
"""
from __future__ import annotations

import collections
import contextlib
import functools
import inspect
import os
from typing import NamedTuple, Optional, Sequence, Tuple, Union

import types

import torch

from . import _C as _C_base  # noqa: E402  (after torch: the module links against libtorch)

__all__ = ["Graph", "has_cuda", "build_graph", "knn_points", "node_confidences", "carap", "arap", "lrm", "regularizers",
           "Regularizers", "dqb", "render", "version", "isa", "set_memory_limit", "memory_limit"]

version = _C_base.version


def _fast_module():
    """The AVX2 + FMA build of the energy operators (smg_torch._C_avx2) when this CPU has both and
    SMG_TORCH_ISA (auto, base or avx2; auto when unset) allows it; None for the baseline (_C)."""
    want = os.environ.get("SMG_TORCH_ISA", "auto").strip().lower() or "auto"
    if want not in ("auto", "base", "avx2"):
        raise ValueError("SMG_TORCH_ISA must be auto, base or avx2, got %r" % want)
    if want == "base":
        return None
    if not _C_base._cpu_supports_avx2_fma():
        if want == "avx2":
            raise ImportError("SMG_TORCH_ISA=avx2, but this CPU lacks AVX2 or FMA (unset it to run the baseline)")
        return None
    try:
        from . import _C_avx2
    except ImportError:
        if want == "avx2":
            raise ImportError("SMG_TORCH_ISA=avx2, but smg_torch was built without _C_avx2 "
                              "(CMake SMG_TORCH_AVX2=OFF, setup.py SMG_TORCH_NO_AVX2=1, or not x86-64)") from None
        return None
    return _C_avx2


_C_fast = _fast_module()
#: The instruction set the CPU energy operators run: "avx2+fma" (smg_torch._C_avx2) or "base"
#: (smg_torch._C, x86-64's SSE2). Chosen at import: SMG_TORCH_ISA=base forces the baseline,
#: =avx2 fails the import where AVX2 + FMA cannot run (docs/torch.md "Instruction sets").
isa = _C_fast._isa if _C_fast is not None else _C_base._isa


def _operators_from(fast):
    """The operators as the wrappers call them: each name from `fast` (_C_avx2, or None) where it
    has it (the energy operators), else from _C (skin, splat, graph, the CUDA operators). The
    memory limit is each module's own state (set_memory_limit sets both); has_cuda is _C's."""
    own = ("has_cuda", "set_memory_limit", "memory_limit")
    return types.SimpleNamespace(**{n: getattr(fast, n) if fast is not None and n not in own and hasattr(fast, n)
                                    else getattr(_C_base, n) for n in dir(_C_base) if not n.startswith("__")})


_C = _operators_from(_C_fast)


@contextlib.contextmanager
def _operators_in_use(ops):
    """Within the block the wrappers (smg_torch's and compat's) call `ops` (an _operators_from
    namespace), their own after it; nothing changes when ops is None. For tests/torch/test_isa.py
    and the benchmarks' --isa-ab, which run one build against the other in one process."""
    global _C
    if ops is None:
        yield
        return
    from . import compat
    saved = _C, compat._C
    _C = compat._C = ops
    try:
        yield
    finally:
        _C, compat._C = saved

#: True when the extension was built with its CUDA operators (smg_torch_cuda.cu): then
#: node_confidences, carap, arap, lrm, regularizers, dqb and knn_points also take CUDA tensors (all on one device) and run on the
#: device's current stream with the same equations and gradients.
has_cuda = bool(getattr(_C, "has_cuda", False))


def set_memory_limit(bytes: float) -> None:
    """The memory limit of the large outputs (module docstring), in bytes: 0 < bytes <= 2^50.
    8 GiB by default; at import, SMG_TORCH_MAX_MEMORY_GB (GiB) when set."""
    _C_base.set_memory_limit(float(bytes))
    if _C_fast is not None:
        _C_fast.set_memory_limit(float(bytes))


def memory_limit() -> float:
    """The memory limit in bytes (set_memory_limit)."""
    return _C.memory_limit()


if os.environ.get("SMG_TORCH_MAX_MEMORY_GB"):
    set_memory_limit(float(os.environ["SMG_TORCH_MAX_MEMORY_GB"]) * 2 ** 30)


class Graph(NamedTuple):
    """Semantic motion graph: indices int64 [N, K] (-1 padded), weights [N, K], features [N, C],
    distances [N, K]. Any (indices, weights) pair works where a Graph is expected."""

    indices: torch.Tensor
    weights: torch.Tensor
    features: Optional[torch.Tensor] = None
    distances: Optional[torch.Tensor] = None


GraphLike = Union[Graph, Tuple[torch.Tensor, torch.Tensor]]


def _graph(g) -> Tuple[torch.Tensor, torch.Tensor]:
    if isinstance(g, Graph):
        return g.indices, g.weights
    if isinstance(g, (tuple, list)) and len(g) == 2:
        return g[0], g[1]
    raise ValueError("graph: expected smg_torch.Graph or a tuple (indices, weights)")


def _check(**tensors) -> None:
    """Tensors or None (the extension checks devices, dtypes and shapes)."""
    for name, t in tensors.items():
        if t is not None and not isinstance(t, torch.Tensor):
            raise ValueError(f"{name}: expected a torch.Tensor, got {type(t).__name__}")


def _gap_args(gaps, gap_weights):
    gaps = [int(d) for d in gaps]
    gw = None if gap_weights is None else [float(w) for w in gap_weights]
    return gaps, gw


def build_graph(positions: torch.Tensor, visibility: Optional[torch.Tensor] = None,
                feature_samples: Optional[torch.Tensor] = None,
                features: Optional[torch.Tensor] = None, *, k: int = 16, tau: float = 0.75,
                aggregation: str = "paper", m: int = 3, rho: float = 0.5, min_covisible: int = 1,
                isolated: str = "keep_nearest", weighting: str = "uniform",
                gate: bool = True) -> Graph:
    """The semantic motion graph (docs/math/graph.md): exact trajectory KNN over positions
    [T, N, 3] (visibility [T, N] or None = all visible), gated by cos(f_i, f_j) >= tau when
    features [N, C] (or feature_samples [T, N, C], reduced to descriptors with rho) are given
    and gate is True. Returns Graph(indices int64 [N, k] -1 padded, weights [N, k],
    features [N, C] or None, distances [N, k]). No gradient.
    Devices: CPU tensors only (a CUDA tensor raises NotImplementedError)."""
    _check(positions=positions, visibility=visibility, feature_samples=feature_samples,
           features=features)
    with torch.no_grad():
        idx, w, f, d = _C.build_graph(
            positions.detach(), visibility,
            None if feature_samples is None else feature_samples.detach(),
            None if features is None else features.detach(), int(k), float(tau), str(aggregation),
            int(m), float(rho), int(min_covisible), str(isolated), str(weighting), bool(gate))
    return Graph(idx, w, f, d)


def node_confidences(positions: torch.Tensor, g: GraphLike, visibility: Optional[torch.Tensor] = None,
                     *, kappa_m: float = 2.5, kappa_r: float = 2.5, lambda_m: float = 1.0,
                     lambda_r: float = 1.0, eps: float = 1e-4, validate: bool = False) -> torch.Tensor:
    """c_{t,i} (docs/math/energy.md E2-E6), [T, N], no gradient (a constant for the energies).
    validate: as for carap (CUDA tensors only; CPU tensors are always validated).
    Devices: CPU and CUDA tensors."""
    idx, w = _graph(g)
    _check(positions=positions, indices=idx, weights=w, visibility=visibility)
    with torch.no_grad():
        return _C.node_confidences(positions.detach(), idx, w.detach(), visibility, float(kappa_m),
                                   float(kappa_r), float(lambda_m), float(lambda_r), float(eps),
                                   bool(validate))


def _scale(grad_output, g):
    return None if g is None else grad_output * g


def _first_order(op: str):
    """The backward of an smg_torch Function: smg's kernels give first derivatives only. Under
    create_graph=True (autograd runs a backward with grad mode on only then) it raises at once,
    naming the operator the caller called (`op`, or ctx.op where one Function serves several),
    instead of returning a gradient with no graph: torch's once_differentiable catches only a
    grad_output that requires grad, so a gradient penalty through smg silently lost smg's
    second-order part. Otherwise the backward runs under no_grad, as once_differentiable's does."""
    def wrap(backward):
        @functools.wraps(backward)
        def run(ctx, *grads):
            if torch.is_grad_enabled():
                raise RuntimeError(f"smg_torch.{getattr(ctx, 'op', op)}: no second-order gradient: its backward ran "
                                   "with create_graph=True (a gradient penalty or a Hessian through it); smg's "
                                   "kernels give first derivatives only, so differentiate it once (create_graph=False)")
            with torch.no_grad():
                return backward(ctx, *grads)
        return run
    return wrap


class _KnnPointsFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, points, K, radius, include_self):
        d2, idx = _C.knn_points(points.detach(), K, radius, include_self)
        ctx.save_for_backward(points.detach(), idx)
        ctx.mark_non_differentiable(idx)
        return d2, idx

    @staticmethod
    @_first_order("knn_points")
    def backward(ctx, g, _):
        # d²_ij = ‖p_i − p_j‖²: ∂/∂p_i = 2 (p_i − p_j), ∂/∂p_j = −2 (p_i − p_j); padding has none.
        points, idx = ctx.saved_tensors
        valid = idx >= 0
        j = idx.clamp(min=0)
        gi = torch.where(valid[..., None], 2 * g[..., None] * (points[:, None, :] - points[j]),
                         points.new_zeros(()))
        grad = gi.sum(1)
        grad.index_add_(0, j.reshape(-1), -gi.reshape(-1, 3))
        return grad, None, None, None


def knn_points(points: torch.Tensor, K: int, *, radius: Optional[float] = None,
               include_self: bool = True) -> Tuple[torch.Tensor, torch.Tensor]:
    """Exact K nearest neighbours of every point (docs/math/graph.md (G15)): points [N, 3]
    float32/float64 -> (squared_distances [N, K] of points' dtype, indices int64 [N, K]). Row i
    is sorted by (d², j) — ties by index, so the rows never depend on the search or the thread
    count — keeps only d² <= radius² (frnn's test; None: no bound) and j != i unless
    include_self. Entries past the last neighbour: index -1, squared distance +inf. The squared
    distances are differentiable w.r.t. points (2 (p_i − p_j) and its negative; none through the
    padding or the choice of neighbours). CPU: a bounding-box tree on torch's threads; CUDA: an
    all-pairs kernel (O(N²), the same rows bit for bit). Each codebase's own table (Open3D,
    cKDTree, frnn) comes from smg_torch.compat (open3d_knn, ckdtree_knn, frnn_knn).
    Devices: CPU and CUDA tensors."""
    if not isinstance(points, torch.Tensor):
        raise TypeError(f"points: expected a torch.Tensor, got {type(points).__name__}")
    if points.dim() == 2 and points.shape[-1] == 3 and points.is_floating_point() and points.numel() \
            and not bool(torch.isfinite(points).all()):
        bad = (~torch.isfinite(points)).nonzero()[0].tolist()
        raise ValueError(f"points[{bad[0]}, {bad[1]}] is {points[bad[0], bad[1]].item()}: "
                         "every coordinate must be finite")
    if radius is not None:
        radius = float(radius)
    return _KnnPointsFunction.apply(points, K, radius, bool(include_self))


class _CarapFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, positions, quats, idx, w, confidence, plain, alpha, lambda_c, lambda_l, gaps,
                gap_weights, normalize, validate, op=None):
        need_x, need_q = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        args = (positions.detach(), quats.detach(), idx, w.detach())
        if not plain:
            args += (None if confidence is None else confidence.detach(), alpha)
        args += (lambda_c, lambda_l, gaps, gap_weights, normalize, need_x, need_q, validate)
        e, gx, gq = (_C.arap if plain else _C.carap)(*args)
        ctx.grads = (gx, gq)
        ctx.op = op or ("arap" if plain else "carap")  # the caller's operator, for _first_order
        return e

    @staticmethod
    @_first_order("carap")
    def backward(ctx, grad_output):
        gx, gq = ctx.grads
        return (_scale(grad_output, gx), _scale(grad_output, gq)) + (None,) * 12


def carap(positions: torch.Tensor, quats: torch.Tensor, g: GraphLike,
          confidence: Optional[torch.Tensor] = None, *, alpha: float = 0.6, lambda_c: float = 1.0,
          lambda_l: float = 1.0, gaps: Sequence[int] = (1, 2, 4),
          gap_weights: Optional[Sequence[float]] = None, normalize: bool = False,
          validate: bool = False) -> torch.Tensor:
    """Confidence-aware ARAP energy (E7-E10), 0-dim; differentiable w.r.t. positions and quats.
    CPU tensors are always validated; CUDA tensors' contents only with validate=True (the CPU
    validators on a host copy, one synchronising copy per call).
    Devices: CPU and CUDA tensors."""
    idx, w = _graph(g)
    _check(positions=positions, quats=quats, indices=idx, weights=w, confidence=confidence)
    gaps, gw = _gap_args(gaps, gap_weights)
    return _CarapFunction.apply(positions, quats, idx, w, confidence, False, float(alpha),
                                float(lambda_c), float(lambda_l), gaps, gw, bool(normalize),
                                bool(validate))


def arap(positions: torch.Tensor, quats: torch.Tensor, g: GraphLike, *, lambda_c: float = 1.0,
         lambda_l: float = 1.0, gaps: Sequence[int] = (1, 2, 4),
         gap_weights: Optional[Sequence[float]] = None, normalize: bool = False,
         validate: bool = False) -> torch.Tensor:
    """Plain ARAP energy (E9 with c = 1, alpha = 1), 0-dim; differentiable like carap.
    Devices: CPU and CUDA tensors."""
    idx, w = _graph(g)
    _check(positions=positions, quats=quats, indices=idx, weights=w)
    gaps, gw = _gap_args(gaps, gap_weights)
    return _CarapFunction.apply(positions, quats, idx, w, None, True, 1.0, float(lambda_c),
                                float(lambda_l), gaps, gw, bool(normalize), bool(validate))


class _LrmFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, positions, idx, w, confidence, alpha, huber_delta, detach_omega, normalize,
                validate):
        args = (positions.detach(), idx, w.detach(),
                None if confidence is None else confidence.detach(), alpha, huber_delta,
                detach_omega, normalize, ctx.needs_input_grad[0], validate)
        e, gx = _C.lrm(*args)
        ctx.grad = gx
        return e

    @staticmethod
    @_first_order("lrm")
    def backward(ctx, grad_output):
        return (_scale(grad_output, ctx.grad),) + (None,) * 8


def lrm(positions: torch.Tensor, g: GraphLike, confidence: Optional[torch.Tensor] = None, *,
        alpha: float = 0.6, huber_delta: float = 0.01, detach_omega: bool = False,
        normalize: bool = False, validate: bool = False) -> torch.Tensor:
    """Local rigid-motion energy (E11-E16), 0-dim; differentiable w.r.t. positions.
    validate: as for carap (CUDA tensors only; CPU tensors are always validated).
    Devices: CPU and CUDA tensors."""
    idx, w = _graph(g)
    _check(positions=positions, indices=idx, weights=w, confidence=confidence)
    return _LrmFunction.apply(positions, idx, w, confidence, float(alpha), float(huber_delta),
                              bool(detach_omega), bool(normalize), bool(validate))


#: The options of each term of regularizers, with their defaults: read from the library's term
#: list (smg::for_each_term / smg::for_each_option, smg/energy/options.hpp), so they are the C++
#: defaults, which are node_confidences', carap's, arap's and lrm's. `weight` multiplies the
#: term and its gradient; a GapList is `gaps` + `gap_weights` (None = all 1), a Normalization
#: the bool `normalize`; accel's `form` is "acceleration" or "velocity", its `penalty`
#: "squared", "norm" or "sqrt_weighted" (E22, with `penalty_eps`), its `confidence_weighted`
#: uses c at the earliest frame of each term (1 otherwise).
REGULARIZER_DEFAULTS = _C._regularizer_options()
#: The terms of regularizers in the driver's order, each on (True) or off by default.
REGULARIZER_TERMS = _C._regularizer_terms()
#: The energies regularizers returns, in the order of its energies tensor.
_REGULARIZER_ENERGIES = tuple(_C._regularizer_energies())

#: The fields of Regularizers that come first, in this order, so that code unpacking the first
#: five keeps working; a legacy energy no longer on the list is left out.
_REGULARIZERS_LEGACY = tuple(n for n in ("total", "carap", "arap", "lrm", "confidence")
                             if n in ("total", "confidence") or n in _REGULARIZER_ENERGIES)

# Built from the term list (smg::for_each_term): a term with an energy has its field, so a new
# term needs no edit here. The energies after the legacy fields default to None.
_fields = _REGULARIZERS_LEGACY + tuple(n for n in _REGULARIZER_ENERGIES
                                       if n not in _REGULARIZERS_LEGACY)
Regularizers = collections.namedtuple("Regularizers", _fields, module=__name__,
                                      defaults=(None,) * (len(_fields) - len(_REGULARIZERS_LEGACY)))
Regularizers.__annotations__ = {n: Optional[torch.Tensor] for n in _fields}
del _fields
Regularizers.__doc__ = """What smg_torch.regularizers returns: `total` = the sum of the term
energies (0-dim, differentiable w.r.t. positions and quats), one field per energy of the term
list (0-dim, detached: for logging; a term that is off is 0) and `confidence`, the confidences
[T, N] (no gradient; None when off). The fields are total, carap, arap, lrm, confidence (in this
order, so that code unpacking the first five keeps working), then the other energies (accel, ...)
in the term list's order."""


def _term_options(name, value):
    """(on, options dict) of one term: False/None = off, True = defaults, a dict = these options."""
    if value is None or value is False:
        return False, dict(REGULARIZER_DEFAULTS[name])
    if value is True:
        value = {}
    if not isinstance(value, dict):
        raise ValueError(f"{name}: expected True, False or a dict of options, got {type(value).__name__}")
    out = dict(REGULARIZER_DEFAULTS[name])
    for key, v in value.items():
        if key not in out:
            raise ValueError(f"{name}: unknown option {key!r} (known: {', '.join(out)})")
        out[key] = v
    if "gaps" in out:
        out["gaps"], out["gap_weights"] = _gap_args(out["gaps"], out["gap_weights"])
    # Each option converted to its default's type (float, bool or str); gaps were above.
    for key, default in REGULARIZER_DEFAULTS[name].items():
        if isinstance(default, (bool, float, str)):
            out[key] = type(default)(out[key])
    return True, out


class _RegularizersFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, positions, quats, idx, w, visibility, terms, opts, validate, op):
        need_x, need_q = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        ctx.op = op  # the caller's operator, for _first_order's message
        e, c, gx, gq = _C.regularizers(
            positions.detach(), None if quats is None else quats.detach(), idx, w.detach(),
            visibility, terms, opts, need_x, need_q and quats is not None, validate)
        ctx.grads = (gx, gq)
        total = e.sum()
        if c is None:
            c = positions.new_zeros(0)  # autograd outputs must be tensors; mapped to None below
        ctx.mark_non_differentiable(e, c)
        return total, e, c

    @staticmethod
    @_first_order("regularizers")
    def backward(ctx, grad_total, grad_e, grad_c):
        gx, gq = ctx.grads
        return (_scale(grad_total, gx), _scale(grad_total, gq)) + (None,) * 7


def regularizers(positions: torch.Tensor, quats: Optional[torch.Tensor], g: GraphLike,
                 visibility: Optional[torch.Tensor] = None, *, validate: bool = False,
                 **terms) -> Regularizers:
    """The regulariser step fused (smg::regularizers, docs/math/energy.md "The fused regulariser
    pass"): any subset of the library's terms in one pass over the graph. Each term of
    REGULARIZER_TERMS is a keyword, False (off), True (its defaults) or a dict of its options
    (REGULARIZER_DEFAULTS; `weight` scales the term); a term not given is on or off as
    REGULARIZER_TERMS says. The terms today, for example: the confidences (confidence, E2-E6;
    visibility [T, N] or None = all visible), C-ARAP (carap, E7-E10), plain ARAP (arap), LRM
    (lrm, E11-E16), trajectory smoothness (accel, E21: squared accelerations or velocities of
    the node trajectories, as MoSca and Shape-of-Motion regularise), the rotation-angle term
    (angle, E23: MoSca's rotation velocity / acceleration, the angles of R^{t+1} R^{tT}) and
    relative-rotation consistency (relrot, E25: Dynamic 3D Gaussians' "rot", the relative
    rotations R^{t+1} R^{tT} of neighbours compared as 4-vectors). With
    confidence off, C-ARAP and LRM use c = 1. quats [T, N, 4] may be None when no term on uses
    them. Returns
    Regularizers(total, carap, arap, lrm, confidence, ...the other energies): `total` is
    differentiable w.r.t. positions and the raw quats (the confidences are constants, as with
    the separate operators); the per-term energies are detached. The same values as the separate
    operators (node_confidences + carap + arap + lrm) to rounding (1e-12 relative in float64,
    tests/torch/test_energy.py). On CUDA tensors smg::cuda::regularizers runs on the current
    stream (tests/torch/test_cuda.py; passed on an H200, docs/cuda.md).
    Devices: CPU and CUDA tensors."""
    for key in terms:
        if key not in REGULARIZER_TERMS:
            raise TypeError(f"regularizers() got an unexpected keyword argument {key!r} "
                            f"(terms: {', '.join(REGULARIZER_TERMS)})")
    return _regularizers(positions, quats, g, visibility, bool(validate), terms, "regularizers")


def _regularizers(positions, quats, g, visibility, validate, terms, op) -> Regularizers:
    """regularizers() for a caller `op` (smg_torch.compat's calls name themselves in the
    second-order refusal): terms as regularizers' keywords, already checked."""
    idx, w = _graph(g)
    _check(positions=positions, quats=quats, indices=idx, weights=w, visibility=visibility)
    on, opts = {}, {}
    for name, default in REGULARIZER_TERMS.items():
        on[name], opts[name] = _term_options(name, terms.get(name, default))
    total, e, c = _RegularizersFunction.apply(positions, quats, idx, w, visibility, on, opts,
                                              bool(validate), op)
    energies = dict(zip(_REGULARIZER_ENERGIES, e))
    return Regularizers(total=total, confidence=c if on.get("confidence") else None, **energies)


# The signature help() and inspect show: a keyword-only parameter per term of the list, with its
# default on/off, between visibility and validate.
_P = inspect.Parameter
regularizers.__signature__ = inspect.Signature(
    [_P("positions", _P.POSITIONAL_OR_KEYWORD, annotation=torch.Tensor),
     _P("quats", _P.POSITIONAL_OR_KEYWORD, annotation=Optional[torch.Tensor]),
     _P("g", _P.POSITIONAL_OR_KEYWORD, annotation=GraphLike),
     _P("visibility", _P.POSITIONAL_OR_KEYWORD, default=None, annotation=Optional[torch.Tensor])]
    + [_P(name, _P.KEYWORD_ONLY, default=on) for name, on in REGULARIZER_TERMS.items()]
    + [_P("validate", _P.KEYWORD_ONLY, default=False, annotation=bool)],
    return_annotation=Regularizers)
del _P


def _library_seconds(op: str, positions: torch.Tensor, quats: Optional[torch.Tensor], g: GraphLike,
                     confidence: Optional[torch.Tensor] = None, *, repeat: int = 5) -> float:
    """Benchmark helper (bench/torch/bench_torch.py), not API: best of `repeat` wall seconds of
    the bare C++ library call behind op "carap" (energy + position and quaternion gradients) or
    "lrm" (energy + position gradient) on these tensors, with the wrappers' defaults, timed in C++
    (std::chrono) on torch's intra-op thread count; the gradient buffers are zeroed inside the
    timed region."""
    idx, w = _graph(g)
    _check(positions=positions, quats=quats, indices=idx, weights=w, confidence=confidence)
    return _C._library_seconds(str(op), positions.detach(), None if quats is None else quats.detach(),
                               idx, w.detach(), None if confidence is None else confidence.detach(),
                               int(repeat))


class _DqbFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, node_positions, node_quats, points, point_quats, idx, w, anchor, t_ref, t_query,
                sigma, lbs, validate):
        xs, qs, ps = node_positions.detach(), node_quats.detach(), points.detach()
        pqs = None if point_quats is None else point_quats.detach()
        out_x, out_q, drivers, weights = _C.dqb_forward(xs, qs, idx, w.detach(), ps, pqs, anchor,
                                                        t_ref, t_query, sigma.detach(), lbs,
                                                        validate)
        # The backward recomputes the blend (as cheap as reading a cache, per the library).
        # saved through autograd, so that an in-place change before backward raises
        ctx.save_for_backward(node_positions, node_quats, points, point_quats)
        ctx.inputs = (t_ref, t_query, drivers, weights, lbs, validate)
        return out_x, out_q

    @staticmethod
    @_first_order("dqb")
    def backward(ctx, grad_x, grad_q):
        xs, qs, ps, pqs = (None if t is None else t.detach() for t in ctx.saved_tensors)
        t_ref, t_query, drivers, weights, lbs, validate = ctx.inputs
        nx, nq, np_, npq = ctx.needs_input_grad[:4]
        gx, gq, gp, gpq = _C.dqb_backward(xs, qs, ps, pqs, t_ref, t_query, drivers, weights, grad_x,
                                          grad_q, lbs, nx, nq, np_, npq and pqs is not None,
                                          validate)
        return (gx, gq, gp, gpq) + (None,) * 8


def dqb(node_positions: torch.Tensor, node_quats: torch.Tensor, g: GraphLike, points: torch.Tensor,
        point_quats: Optional[torch.Tensor], anchor: torch.Tensor, t_ref: torch.Tensor,
        t_query: torch.Tensor, sigma: torch.Tensor, *, lbs: bool = False,
        validate: bool = False):
    """Dual-quaternion blending (docs/math/skin.md S1-S18; LBS with lbs=True) of points [P, 3]
    (reference poses at frames t_ref [P], rotations point_quats [P, 4] or None = identity), each
    driven by its anchor node [P] and the anchor's graph neighbours with distance-aware weights
    (sigma [N]; the weights are constants for the gradient), to the frames t_query [Q].
    Returns positions [Q, P, 3] and unit quaternions [Q, P, 4]; differentiable w.r.t.
    node_positions, the raw node_quats, points and the raw point_quats.
    CUDA tensors (all on node_positions' device; index arrays of any integer dtype; the other
    float tensors of node_positions' dtype) run on the device's current stream, forward and
    backward, without reading anything back to the host (no synchronisation). Their contents
    (index ranges, sigma > 0, finite incoming gradients) are checked only with validate=True
    (one synchronising copy in forward and one in backward); without it they are the caller's
    precondition, except that a t_query entry out of range gives NaN outputs and no gradient
    instead of an out-of-bounds read. CPU tensors are always validated.
    Devices: CPU and CUDA tensors."""
    idx, w = _graph(g)
    tensors = dict(node_positions=node_positions, node_quats=node_quats, points=points,
                   point_quats=point_quats, indices=idx, weights=w, anchor=anchor, t_ref=t_ref,
                   t_query=t_query, sigma=sigma)
    _check(**tensors)
    return _DqbFunction.apply(node_positions, node_quats, points, point_quats, idx, w, anchor, t_ref,
                              t_query, sigma, bool(lbs), bool(validate))


class _RenderFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, quats, log_scales, opacity_logits, colors, viewmat, K, width, height,
                background, near, far, tile_size, radius_sigmas, eps2d, alpha_max):
        params = tuple(t.detach() for t in (means, quats, log_scales, opacity_logits, colors))
        img, alpha, depth, radii, state = _C.render_forward(
            *params, viewmat.detach(), K.detach(), width, height,
            None if background is None else background.detach(), near, far, tile_size,
            radius_sigmas, eps2d, alpha_max)
        # The forward's workspace (projections, tile lists, transmittances) is kept for backward.
        ctx.state = state
        ctx.save_for_backward(means, quats, log_scales, opacity_logits, colors)
        ctx.radii = radii
        return img, alpha, depth

    @staticmethod
    @_first_order("render")
    def backward(ctx, grad_image, grad_alpha, grad_depth):
        params = tuple(t.detach() for t in ctx.saved_tensors)
        grads = _C.render_backward(ctx.state, *params, grad_image, grad_alpha, grad_depth)
        return tuple(grads) + (None,) * 11


def render(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
           opacity_logits: torch.Tensor, colors: torch.Tensor, viewmat: torch.Tensor,
           K: torch.Tensor, width: int, height: int, *, background=None, near: float = 0.01,
           far: float = 1e10, tile_size: int = 16, radius_sigmas: float = 3.0, eps2d: float = 0.3,
           alpha_max: float = 0.99):
    """The reference CPU splatter (docs/math/splat.md; gsplat's maths): means [G, 3], raw quats
    [G, 4], log_scales [G, 3], opacity_logits [G], colors [G, C] or SH coefficients [G, K, C],
    viewmat [4, 4] (world -> camera, OpenCV axes), K [3, 3]. Returns image [H, W, C], alpha
    [H, W] and expected depth [H, W]; differentiable w.r.t. every Gaussian parameter (viewmat, K
    and background are constants).
    Devices: CPU tensors only (a CUDA tensor raises NotImplementedError)."""
    _check(means=means, quats=quats, log_scales=log_scales, opacity_logits=opacity_logits,
           colors=colors, viewmat=viewmat, K=K)
    if background is not None and not isinstance(background, torch.Tensor):
        background = torch.tensor(background, dtype=torch.float64).reshape(-1)
    _check(background=background)
    return _RenderFunction.apply(means, quats, log_scales, opacity_logits, colors, viewmat, K,
                                 int(width), int(height), background, float(near), float(far),
                                 int(tile_size), float(radius_sigmas), float(eps2d),
                                 float(alpha_max))
