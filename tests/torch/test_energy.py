"""smg_torch energies: gradcheck, agreement with the pure-PyTorch reference (docs/math/energy.md),
float32 vs float64, int32/int64 indices, non-contiguous inputs, threads."""
import pytest
import torch
from torch.autograd import gradcheck

import smg_torch as smg
import torch_reference as ref
from scenes import antipodal, coincident, collinear, random_scene

RTOL = 1e-10


def rel(a, b):
    """Norm-wise relative difference ‖a − b‖ / max(‖b‖, tiny)."""
    a, b = a.detach().double(), b.detach().double()
    return float((a - b).norm() / max(float(b.norm()), 1e-300))


def grads(f, *inputs):
    inputs = [t.detach().clone().requires_grad_(True) for t in inputs]
    e = f(*inputs)
    gs = torch.autograd.grad(e, inputs)
    return e.detach(), gs


# ---- the operators under test, as (smg_torch, reference) pairs over (x, q) or (x,) ----------

def carap_pair(idx, w, c, **kw):
    return (lambda x, q: smg.carap(x, q, (idx, w), c, **kw),
            lambda x, q: ref.carap(x, q, idx, w, c, **kw))


def arap_pair(idx, w, **kw):
    return (lambda x, q: smg.arap(x, q, (idx, w), **kw),
            lambda x, q: ref.arap(x, q, idx, w, **kw))


def lrm_pair(idx, w, c, **kw):
    return (lambda x: smg.lrm(x, (idx, w), c, **kw), lambda x: ref.lrm(x, idx, w, c, **kw))


CARAP_OPTIONS = [dict(), dict(alpha=0.2, lambda_c=0.7, lambda_l=1.9, gaps=(1, 3), gap_weights=(0.5, 2.0)),
                 dict(normalize=True), dict(gaps=(2, 9))]
LRM_OPTIONS = [dict(), dict(huber_delta=0.05), dict(detach_omega=True), dict(alpha=0.3, normalize=True),
               dict(huber_delta=1e3)]


def check_pair(f, r, x, q):
    """gradcheck of the operator f, then f against its torch reference r: energy and the
    gradients w.r.t. positions and quats."""
    assert gradcheck(f, (x.requires_grad_(), q.requires_grad_()))
    e1, g1 = grads(f, x, q)
    e2, g2 = grads(r, x, q)
    assert rel(e1, e2) < RTOL
    for a, b in zip(g1, g2):
        assert rel(a, b) < RTOL


@pytest.mark.parametrize("kw", CARAP_OPTIONS)
def test_carap_gradcheck_and_reference(kw):
    x, q, idx, w, c = random_scene()
    check_pair(*carap_pair(idx, w, c, **kw), x, q)


@pytest.mark.parametrize("kw", [dict(), dict(lambda_c=0.7, lambda_l=1.9, gaps=(1, 3), gap_weights=(0.5, 2.0)),
                                dict(normalize=True)])
def test_arap_gradcheck_and_reference(kw):
    x, q, idx, w, _ = random_scene()
    check_pair(*arap_pair(idx, w, **kw), x, q)


@pytest.mark.parametrize("kw", LRM_OPTIONS)
def test_lrm_gradcheck_and_reference(kw):
    x, _, idx, w, c = random_scene()
    f, r = lrm_pair(idx, w, c, **kw)
    if not kw.get("detach_omega"):  # detach_omega is not the gradient of the energy, on purpose
        assert gradcheck(f, (x.requires_grad_(),))
    e1, (g1,) = grads(f, x)
    e2, (g2,) = grads(r, x)
    assert rel(e1, e2) < RTOL
    assert rel(g1, g2) < RTOL


def test_confidence_reference():
    x, _, idx, w, _ = random_scene(T=9)
    x[4, 3] += 0.5  # a glitch
    vis = torch.rand(9, 12) > 0.2
    for kw in [dict(), dict(kappa_m=1.5, kappa_r=3.0, lambda_m=0.5, lambda_r=2.0, eps=1e-3)]:
        c1 = smg.node_confidences(x, (idx, w), vis, **kw)
        c2 = ref.node_confidences(x, idx, w, vis, **kw)
        assert c1.shape == (9, 12) and not c1.requires_grad
        assert rel(c1, c2) < RTOL
    assert float(c1.min()) >= 0 and float(c1.max()) <= 1
    # Graph-object form, T = 1 and a rigid translation (c = 1 exactly).
    g = smg.Graph(idx, w)
    assert torch.equal(smg.node_confidences(x, g), smg.node_confidences(x, (idx, w)))
    assert rel(smg.node_confidences(x[:1], g), ref.node_confidences(x[:1], idx, w)) < RTOL
    rigid = x[:1] + torch.linspace(0, 1, 5)[:, None, None] * torch.tensor([0.3, -0.1, 0.2])
    cr = smg.node_confidences(rigid, g)
    others = torch.arange(12) != 5  # node 5 has no neighbour: c^m = exp(-(|u| / (kappa_m eps))^2)
    assert float((cr[:, others] - 1).abs().max()) < 1e-12 and float(cr[:, 5].max()) < 1e-12


# ---- hard cases --------------------------------------------------------------------------------

def test_antipodal_quaternions():
    x, q, idx, w, c = random_scene()
    qa = antipodal(q)
    for f, r in [carap_pair(idx, w, c), arap_pair(idx, w)]:
        assert gradcheck(f, (x.clone().requires_grad_(), qa.clone().requires_grad_()))
        e1, g1 = grads(f, x, q)
        e2, g2 = grads(f, x, qa)
        assert rel(e1, e2) < 1e-13 and rel(g1[0], g2[0]) < 1e-13
        # the raw gradient flips with q (a function of q/|q| that is even in q)
        sign = torch.where((q * qa).sum(-1, keepdim=True) < 0, -1.0, 1.0)
        assert rel(g2[1], sign * g1[1]) < 1e-13
        e3, g3 = grads(r, x, qa)
        assert rel(e2, e3) < RTOL and rel(g2[1], g3[1]) < RTOL


def test_coincident_neighbours():
    x, q, idx, w, c = random_scene()
    xc = coincident(x, idx)
    for f, r in [carap_pair(idx, w, c), arap_pair(idx, w), lrm_pair(idx, w, c)]:
        inputs = (xc.clone().requires_grad_(),) if f.__code__.co_argcount == 1 else \
                 (xc.clone().requires_grad_(), q.clone().requires_grad_())
        assert gradcheck(f, inputs)
        e1, g1 = grads(f, *inputs)
        e2, g2 = grads(r, *inputs)
        assert rel(e1, e2) < RTOL
        for a, b in zip(g1, g2):
            assert rel(a, b) < RTOL


def test_collinear_neighbourhoods():
    x, q, idx, w = collinear()
    c = torch.rand(x.shape[0], x.shape[1])
    for f, r in [carap_pair(idx, w, c), arap_pair(idx, w)]:
        assert gradcheck(f, (x.clone().requires_grad_(), q.clone().requires_grad_()))
        e1, g1 = grads(f, x, q)
        e2, g2 = grads(r, x, q)
        assert rel(e1, e2) < RTOL and all(rel(a, b) < RTOL for a, b in zip(g1, g2))
    # LRM: ω is ill-determined along the line (the μ regulariser decides it); the energy and the
    # gradient stay finite and match the reference, and gradcheck passes in Huber's quadratic zone.
    f, r = lrm_pair(idx, w, c, huber_delta=10.0)
    assert gradcheck(f, (x.clone().requires_grad_(),))
    e1, (g1,) = grads(f, x)
    e2, (g2,) = grads(r, x)
    assert torch.isfinite(g1).all() and rel(e1, e2) < 1e-8 and rel(g1, g2) < 1e-6


def test_all_confidences_zero():
    x, q, idx, w, _ = random_scene()
    zero = torch.zeros(x.shape[0], x.shape[1])
    f, r = carap_pair(idx, w, zero, alpha=0.4)
    assert gradcheck(f, (x.clone().requires_grad_(), q.clone().requires_grad_()))
    # C-ARAP = alpha * ARAP exactly when every confidence is 0
    e1, g1 = grads(f, x, q)
    ea, ga = grads(arap_pair(idx, w)[0], x, q)
    assert rel(e1, 0.4 * ea) < 1e-14 and rel(g1[0], 0.4 * ga[0]) < 1e-14
    f, r = lrm_pair(idx, w, zero)
    assert gradcheck(f, (x.clone().requires_grad_(),))
    e1, (g1,) = grads(f, x)
    e2, (g2,) = grads(r, x)
    assert rel(e1, e2) < RTOL and rel(g1, g2) < RTOL
    # alpha = 0 with zero confidences: every LRM weight vanishes -> energy 0, gradient 0
    e0, (g0,) = grads(lrm_pair(idx, w, zero, alpha=0.0)[0], x)
    assert float(e0) == 0.0 and float(g0.abs().max()) == 0.0


# ---- precision, layouts, threads ---------------------------------------------------------------

def test_float32_matches_float64():
    x, q, idx, w, c = random_scene(T=12, N=40, K=6)
    for f, f32 in [(carap_pair(idx, w, c)[0], carap_pair(idx, w.float(), c.float())[0]),
                   (arap_pair(idx, w)[0], arap_pair(idx, w.float())[0])]:
        e64, g64 = grads(f, x, q)
        e32, g32 = grads(f32, x.float(), q.float())
        assert e32.dtype == torch.float32 and g32[0].dtype == torch.float32
        assert rel(e32, e64) < 1e-5
        assert rel(g32[0], g64[0]) < 1e-4 and rel(g32[1], g64[1]) < 1e-4
    f = lambda a: smg.lrm(a, (idx, w), c.to(a.dtype), huber_delta=0.05)
    e64, (g64,) = grads(f, x)
    e32, (g32,) = grads(f, x.float())
    assert rel(e32, e64) < 1e-4 and rel(g32, g64) < 1e-3
    c64 = smg.node_confidences(x, (idx, w))
    c32 = smg.node_confidences(x.float(), (idx, w.float()))
    assert c32.dtype == torch.float32 and float((c32.double() - c64).abs().max()) < 1e-4


def test_int32_indices_noncontiguous_and_mixed_weight_dtype():
    x, q, idx, w, c = random_scene()
    e1, g1 = grads(carap_pair(idx, w, c)[0], x, q)
    e2, g2 = grads(carap_pair(idx.int(), w, c)[0], x, q)
    assert torch.equal(e1, e2) and all(torch.equal(a, b) for a, b in zip(g1, g2))
    # non-contiguous positions / quaternions / confidences / graph: same result
    xt = x.transpose(0, 1).contiguous().transpose(0, 1)
    qt = q.transpose(0, 1).contiguous().transpose(0, 1)
    ct = c.t().contiguous().t()
    it = idx.t().contiguous().t()
    assert not xt.is_contiguous() and not qt.is_contiguous() and not it.is_contiguous()
    e3, g3 = grads(carap_pair(it, w, ct)[0], xt, qt)
    assert torch.equal(e1, e3) and all(torch.equal(a, b) for a, b in zip(g1, g3))
    # float32 weights with float64 positions are converted
    e4, _ = grads(carap_pair(idx, w.float(), c)[0], x, q)
    e5, _ = grads(carap_pair(idx, w.float().double(), c)[0], x, q)
    assert torch.equal(e4, e5)


def test_threads_bit_identical_and_backward_scaling():
    x, q, idx, w, c = random_scene(T=40, N=60, K=8)
    old = torch.get_num_threads()
    try:
        out = []
        for n in (1, 2):
            torch.set_num_threads(n)
            out.append(grads(lambda a, b: smg.carap(a, b, (idx, w), c) + smg.lrm(a, (idx, w), c), x, q))
    finally:
        torch.set_num_threads(old)
    (e1, g1), (e2, g2) = out
    assert torch.equal(e1, e2) and all(torch.equal(a, b) for a, b in zip(g1, g2))
    # backward is linear in grad_output
    xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
    (3.5 * smg.carap(xs, qs, (idx, w), c)).backward()
    assert rel(xs.grad, 3.5 * g1[0] - 3.5 * grads(lambda a: smg.lrm(a, (idx, w), c), x)[1][0]) < 1e-13


def test_no_grad_inputs():
    x, q, idx, w, c = random_scene()
    e = smg.carap(x, q, (idx, w), c)
    assert e.dim() == 0 and not e.requires_grad
    xs = x.clone().requires_grad_()
    e = smg.carap(xs, q, (idx, w), c)  # gradient for the positions only
    e.backward()
    assert xs.grad is not None and q.grad is None


# ---- the benchmark helper behind bench_torch.py's overhead rows ------------------------------

@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_library_seconds_times_the_bare_call(dtype):
    x, q, idx, w, c = random_scene(dtype=dtype)
    for op in ("carap", "lrm"):
        s = smg._library_seconds(op, x, q, (idx, w), c, repeat=3)
        assert isinstance(s, float) and 0 < s < 10
    with pytest.raises(ValueError, match="op must be"):
        smg._library_seconds("arap", x, q, (idx, w), c)
    with pytest.raises(ValueError, match="repeat"):
        smg._library_seconds("lrm", x, q, (idx, w), c, repeat=0)
    with pytest.raises(ValueError, match="quats"):
        smg._library_seconds("carap", x, None, (idx, w), c)


# ---- regularizers: the fused step against the separate operators, and gradcheck ----------------

def separate_regularizers(x, q, idx, w, vis, on, opts):
    """node_confidences + carap + arap + lrm with the same options, as the fused step computes."""
    g = (idx, w)
    c = smg.node_confidences(x, g, vis, **opts.get("confidence", {})) if on["confidence"] else None
    e = {"carap": x.new_zeros(()), "arap": x.new_zeros(()), "lrm": x.new_zeros(())}
    if on["carap"]:
        o = dict(opts.get("carap", {}))
        wt = o.pop("weight", 1.0)
        e["carap"] = wt * smg.carap(x, q, g, c, **o)
    if on["arap"]:
        o = dict(opts.get("arap", {}))
        wt = o.pop("weight", 1.0)
        e["arap"] = wt * smg.arap(x, q, g, **o)
    if on["lrm"]:
        o = dict(opts.get("lrm", {}))
        wt = o.pop("weight", 1.0)
        e["lrm"] = wt * smg.lrm(x, g, c, **o)
    return e, c


REG_OPTIONS = [dict(), dict(carap=dict(alpha=0.3, gaps=(1, 3), gap_weights=(0.5, 2.0), weight=0.7),
                            arap=dict(lambda_l=0.4, gaps=(2,), normalize=True),
                            lrm=dict(huber_delta=0.05, weight=3.0, detach_omega=True),
                            confidence=dict(kappa_m=1.5, lambda_r=0.5))]


@pytest.mark.parametrize("kw", REG_OPTIONS)
@pytest.mark.parametrize("mask", range(16))
def test_regularizers_equal_separate_operators(kw, mask):
    x, q, idx, w, _ = random_scene(T=9)
    vis = (torch.rand(x.shape[0], x.shape[1]) > 0.2)
    on = {"confidence": bool(mask & 1), "carap": bool(mask & 2), "arap": bool(mask & 4), "lrm": bool(mask & 8)}
    args = {k: (kw.get(k, True) if on[k] else False) for k in on}
    xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
    r = smg.regularizers(xs, qs, (idx, w), vis, **args)
    xr, qr = x.clone().requires_grad_(), q.clone().requires_grad_()
    e, c = separate_regularizers(xr, qr, idx, w, vis, on, kw)
    for name in ("carap", "arap", "lrm"):
        assert rel(getattr(r, name), e[name]) < 1e-12, name
        assert not getattr(r, name).requires_grad
    if on["confidence"]:
        assert torch.equal(r.confidence, c)  # the same element functions in the same order
    else:
        assert r.confidence is None
    total = e["carap"] + e["arap"] + e["lrm"]
    assert rel(r.total, total) < 1e-12
    with torch.no_grad():  # energies only: no gradient buffers in the fused pass
        r0 = smg.regularizers(x, q, (idx, w), vis, **args)
    for name in ("total", "carap", "arap", "lrm"):
        assert rel(getattr(r0, name), getattr(r, name)) < 1e-12, name
    if not r.total.requires_grad:  # no term on
        assert float(r.total) == 0.0
        return
    (2.5 * r.total).backward()
    if total.requires_grad:
        (2.5 * total).backward()
        assert rel(xs.grad, xr.grad) < 1e-12
        qr_grad = qr.grad if qr.grad is not None else torch.zeros_like(q)
        qs_grad = qs.grad if qs.grad is not None else torch.zeros_like(q)
        assert rel(qs_grad, qr_grad) < 1e-12 or float(qr_grad.norm()) == float(qs_grad.norm()) == 0.0


def test_regularizers_follow_the_term_list():
    """smg_torch.regularizers is built from the library's term list (smg::for_each_term): every
    term has its keyword with the library's default on/off, its Regularizers field when it has an
    energy, and its options dict with the C++ defaults; a term on the list without one of these
    fails here."""
    import inspect
    params = inspect.signature(smg.regularizers).parameters
    for term, on in smg.REGULARIZER_TERMS.items():
        assert term in params and params[term].kind == inspect.Parameter.KEYWORD_ONLY, term
        assert params[term].default is on, term
        assert term in smg.REGULARIZER_DEFAULTS, term
    assert set(smg.REGULARIZER_DEFAULTS) == set(smg.REGULARIZER_TERMS)
    names = list(params)
    assert names[:4] == ["positions", "quats", "g", "visibility"] and names[-1] == "validate"
    assert names[4:-1] == list(smg.REGULARIZER_TERMS)  # the term keywords, in the list's order
    energies = smg._REGULARIZER_ENERGIES
    assert set(smg.Regularizers._fields) == {"total", "confidence"} | set(energies)
    # The legacy five first (code unpacks them), then the other energies in the list's order.
    legacy = ("total", "carap", "arap", "lrm", "confidence")
    assert smg.Regularizers._fields == legacy + tuple(e for e in energies if e not in legacy)
    # The C++ defaults, as the separate operators' wrappers have them.
    assert smg.REGULARIZER_DEFAULTS["carap"] == dict(alpha=0.6, lambda_c=1.0, lambda_l=1.0, gaps=(1, 2, 4),
                                                   gap_weights=None, normalize=False, weight=1.0,
                                                   penalty="squared", stop_gradient="none", penalty_eps=1e-20,
                                                   frame="row")
    assert smg.REGULARIZER_DEFAULTS["angle"]["penalty"] == "norm"
    assert smg.REGULARIZER_DEFAULTS["accel"]["form"] == "acceleration"
    assert smg.REGULARIZER_DEFAULTS["accel"]["penalty"] == "squared"
    assert smg.REGULARIZER_DEFAULTS["accel"]["penalty_eps"] == 1e-20
    x, q, idx, w, _ = random_scene(T=6)
    # A keyword that is not a term: TypeError, as Python's for an unknown keyword, naming it.
    with pytest.raises(TypeError, match="unexpected keyword argument 'smoothness'"):
        smg.regularizers(x, q, (idx, w), smoothness=True)
    # Every option given explicitly at its default gives the defaults' result, bitwise.
    every = {t: dict(d) for t, d in smg.REGULARIZER_DEFAULTS.items()}
    r1 = smg.regularizers(x, q, (idx, w), **{t: True for t in every})
    r2 = smg.regularizers(x, q, (idx, w), **every)
    for name in energies:
        assert torch.equal(getattr(r1, name), getattr(r2, name)), name
        assert float(getattr(r1, name)) != 0.0, name  # every term on contributes


def test_regularizers_gradcheck():
    x, q, idx, w, _ = random_scene()
    # The confidences are constants for the gradient (stop-gradient): gradcheck differentiates
    # numerically, so it runs with them off (c = 1; alpha < 1 still weights C-ARAP).
    f = lambda a, b: smg.regularizers(a, b, (idx, w), confidence=False, arap=True,
                                      lrm=dict(huber_delta=0.05), accel=True).total
    assert gradcheck(f, (x.requires_grad_(), q.requires_grad_()))


def test_regularizers_threads_bitwise():
    x, q, idx, w, _ = random_scene(T=40, N=30, K=6)
    threads = torch.get_num_threads()
    out = []
    try:
        for n in (1, 2, 3):
            torch.set_num_threads(n)
            xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
            r = smg.regularizers(xs, qs, (idx, w), arap=True)
            r.total.backward()
            out.append((r.total.detach(), r.confidence, xs.grad, qs.grad))
    finally:
        torch.set_num_threads(threads)
    for o in out[1:]:
        for a, b in zip(o, out[0]):
            assert torch.equal(a, b)


# ---- trajectory smoothness (accel, E21) against torch's own arithmetic and autograd ------------

def accel_reference(x, c, form, weighted, weight, penalty="squared", eps=1e-20):
    """(E21)-(E22) written in torch: the penalty of the second (or first) differences of every
    node trajectory, weighted by c at the earliest frame of each term when weighted."""
    d = x[2:] - 2 * x[1:-1] + x[:-2] if form == "acceleration" else x[1:] - x[:-1]
    sq = (d * d).sum(-1)
    w = c[: sq.shape[0]] if weighted else torch.ones_like(sq)
    if penalty == "squared":
        per = w * sq
    elif penalty == "norm":
        per = w * d.norm(dim=-1)
    else:
        per = torch.sqrt(w * sq + eps)
    return weight * per.sum()


@pytest.mark.parametrize("form", ["acceleration", "velocity"])
@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.parametrize("penalty", ["squared", "norm", "sqrt_weighted"])
def test_regularizers_accel_equals_torch_autograd(form, weighted, penalty):
    x, q, idx, w, _ = random_scene(T=9)
    vis = torch.rand(x.shape[0], x.shape[1]) > 0.2
    opts = dict(form=form, confidence_weighted=weighted, weight=0.7, penalty=penalty, penalty_eps=1e-4)
    xs = x.clone().requires_grad_()
    r = smg.regularizers(xs, q, (idx, w), vis, carap=False, lrm=False, accel=opts)
    xr = x.clone().requires_grad_()
    e = accel_reference(xr, r.confidence, form, weighted, 0.7, penalty, 1e-4)
    assert float(e) > 0
    assert rel(r.accel, e) < 1e-12 and rel(r.total, e) < 1e-12
    assert float(r.carap) == float(r.lrm) == 0.0
    r.total.backward()
    e.backward()
    assert rel(xs.grad, xr.grad) < 1e-12
    # With the other terms: accel adds its energy and gradient to theirs.
    both = smg.regularizers(x, q, (idx, w), vis, accel=opts)
    alone = smg.regularizers(x, q, (idx, w), vis)
    assert rel(both.total, alone.total + r.accel) < 1e-12
    assert float(alone.accel) == 0.0
