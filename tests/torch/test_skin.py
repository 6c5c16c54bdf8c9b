"""smg_torch.dqb: gradcheck w.r.t. node positions, raw node quaternions, points and raw point
quaternions (DQB and LBS), agreement with the pure-PyTorch reference (docs/math/skin.md),
float32 vs float64, hard cases, errors."""
import pytest
import torch
from torch.autograd import gradcheck

import smg_torch as smg
import torch_reference as ref
from scenes import knn_graph

RTOL = 1e-10


def rel(a, b):
    a, b = a.detach().double(), b.detach().double()
    return float((a - b).norm() / max(float(b.norm()), 1e-300))


def skin_scene(T=5, N=8, K=3, P=6, Q=3, dtype=torch.float64):
    x0 = torch.randn(N, 3, dtype=dtype)
    x = x0[None] + 0.2 * torch.randn(T, N, 3, dtype=dtype).cumsum(0)
    q = torch.randn(T, N, 4, dtype=dtype)
    idx, w = knn_graph(x0, K, pad_rows=(2,), dtype=dtype)
    anchor = torch.randint(0, N, (P,))
    t_ref = torch.randint(0, T, (P,))
    pts = x[t_ref, anchor] + 0.3 * torch.randn(P, 3, dtype=dtype)
    pq = torch.randn(P, 4, dtype=dtype)
    t_query = torch.randint(0, T, (Q,))
    sigma = 0.5 + torch.rand(N, dtype=dtype)
    return x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma


def run(scene, lbs=False, f=smg):
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = scene
    if f is smg:
        return lambda a, b, c, d: smg.dqb(a, b, (idx, w), c, d, anchor, t_ref, t_query, sigma, lbs=lbs)
    return lambda a, b, c, d: ref.dqb(a, b, idx, c, d, anchor, t_ref, t_query, sigma, lbs=lbs)


def wide(scene):
    """sigma = 1e6: the weights (constants for the gradient, but functions of the node positions
    and points) no longer move under gradcheck's perturbations (their derivative is ~1e-12)."""
    scene = list(scene)
    scene[9] = torch.full_like(scene[9], 1e6)
    return scene


def gradcheck_dqb(scene, lbs=False):
    # every input, with weights that do not move; the quaternions also at the given sigma
    assert gradcheck(run(wide(scene), lbs), tuple(leaves(scene)))
    x, q, _, _, pts, pq, *_ = scene
    f = run(scene, lbs)
    assert gradcheck(lambda a, b: f(x, a, pts, b), (q.clone().requires_grad_(), pq.clone().requires_grad_()))


def leaves(scene):
    x, q, _, _, pts, pq, *_ = scene
    return [t.clone().requires_grad_() for t in (x, q, pts, pq)]


def loss_grads(f, inputs, gx, gq):
    inputs = [t.detach().clone().requires_grad_() for t in inputs]
    px, pq = f(*inputs)
    grads = torch.autograd.grad((px * gx).sum() + (pq * gq).sum(), inputs)
    return px.detach(), pq.detach(), grads


@pytest.mark.parametrize("lbs", [False, True])
def test_dqb_gradcheck_and_reference(lbs):
    scene = skin_scene()
    f, r = run(scene, lbs), run(scene, lbs, ref)
    gradcheck_dqb(scene, lbs)
    Q, P = scene[8].numel(), scene[4].shape[0]
    gx, gq = torch.randn(Q, P, 3), torch.randn(Q, P, 4)
    a = loss_grads(f, leaves(scene), gx, gq)
    b = loss_grads(r, leaves(scene), gx, gq)
    assert rel(a[0], b[0]) < RTOL and rel(a[1], b[1]) < RTOL
    for u, v in zip(a[2], b[2]):
        assert rel(u, v) < RTOL
    assert torch.allclose(a[1].norm(dim=-1), torch.ones(Q, P))


def test_dqb_antipodal_and_large_angles():
    scene = list(skin_scene())
    q = scene[1]
    q[1::2] = -q[1::2]  # antipodal node quaternions: outputs identical
    flipped = list(scene)
    flipped[1] = -q
    f = run(scene)
    a = f(*leaves(scene))
    b = run(flipped)(*leaves(flipped))
    assert rel(a[0], b[0]) < 1e-13 and rel(a[1], b[1]) < 1e-13
    gradcheck_dqb(scene)
    r = run(scene, False, ref)
    c = r(*leaves(scene))
    assert rel(a[0], c[0]) < RTOL and rel(a[1], c[1]) < RTOL


def test_dqb_point_quats_none_and_graph_object():
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = skin_scene()
    px, pqo = smg.dqb(x, q, smg.Graph(idx, w), pts, None, anchor, t_ref, t_query, sigma)
    ident = torch.tensor([1.0, 0, 0, 0]).expand_as(pq)
    px2, pq2 = smg.dqb(x, q, (idx.int(), w), pts, ident, anchor.int(), t_ref.int(), t_query.int(), sigma)
    assert torch.equal(px, px2) and torch.equal(pqo, pq2)
    xs = x.clone().requires_grad_()
    smg.dqb(xs, q, (idx, w), pts, None, anchor, t_ref, t_query, sigma)[0].sum().backward()
    assert xs.grad is not None and torch.isfinite(xs.grad).all()


def test_dqb_float32():
    scene = skin_scene(P=40, Q=4)
    s32 = [t.float() if t.is_floating_point() else t for t in scene]
    a = run(scene)(*leaves(scene))
    b = run(s32)(*leaves(s32))
    assert b[0].dtype == torch.float32
    assert rel(b[0], a[0]) < 1e-5 and rel(b[1], a[1]) < 1e-5


def test_dqb_errors_leave_inputs_untouched():
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = skin_scene()
    before = [t.clone() for t in (x, q, pts, pq)]
    g = (idx, w)
    cases = [
        (lambda: smg.dqb(x[..., :2], q, g, pts, pq, anchor, t_ref, t_query, sigma), "node_positions"),
        (lambda: smg.dqb(x, q.float(), g, pts, pq, anchor, t_ref, t_query, sigma), "node_quats"),
        (lambda: smg.dqb(x, q[:, :4], g, pts, pq, anchor, t_ref, t_query, sigma), "node_quats"),
        (lambda: smg.dqb(x, q, g, pts, pq, anchor, t_ref, t_query, sigma[:3]), "sigma"),
        (lambda: smg.dqb(x, q, g, pts, pq, anchor, t_ref[:2], t_query, sigma), "t_ref"),
        (lambda: smg.dqb(x, q, (idx, w[:, :1]), pts, pq, anchor, t_ref, t_query, sigma), "graph"),
        (lambda: smg.dqb(x, q, g, pts[:, :2], pq, anchor, t_ref, t_query, sigma), "points"),
        (lambda: smg.dqb(x, q, g, pts, pq[:3], anchor, t_ref, t_query, sigma), "point_quats"),
        (lambda: smg.dqb(x, q, g, pts, pq, anchor + 100, t_ref, t_query, sigma), "anchor"),
        (lambda: smg.dqb(x, q, g, pts, pq, anchor, t_ref, t_query + 100, sigma), "t_query"),
        (lambda: smg.dqb(x, q, g, pts, pq, anchor, t_ref, t_query, -sigma), "sigma"),
        (lambda: smg.dqb(x, q.index_put((torch.tensor(0), torch.tensor(1)), torch.zeros(4)), g, pts, pq,
                         anchor, t_ref, t_query, sigma), "zero quaternion"),
        (lambda: smg.dqb(x, q, g, pts, pq.index_put((torch.tensor(0),), torch.zeros(4)), anchor, t_ref,
                         t_query, sigma), "point"),
        (lambda: smg.dqb(x.index_put((torch.tensor(1), torch.tensor(1)), torch.tensor([float("nan")] * 3)),
                         q, g, pts, pq, anchor, t_ref, t_query, sigma), "positions"),
    ]
    for f, needle in cases:
        with pytest.raises(ValueError) as info:
            f()
        assert needle in str(info.value), str(info.value)
    assert all(torch.equal(a, b) for a, b in zip(before, (x, q, pts, pq)))


def test_dqb_validate_flag_on_cpu():
    """CPU tensors are always validated: validate=False turns no check off (forward and the
    backward's own checks), and validate=True changes no result."""
    scene = skin_scene(P=12, Q=3)
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = scene
    for validate in (False, True):
        for f, needle in [
                (lambda: smg.dqb(x, q, (idx, w), pts, pq, anchor, t_ref, t_query + 100, sigma,
                                 validate=validate), "t_query"),
                (lambda: smg.dqb(x, q, (idx, w), pts, pq, anchor + 100, t_ref, t_query, sigma,
                                 validate=validate), "anchor"),
                (lambda: smg.dqb(x, q, (idx, w), pts, pq, anchor, t_ref, t_query, -sigma,
                                 validate=validate), "sigma")]:
            with pytest.raises(ValueError, match=needle):
                f()
    _, _, drivers, weights = smg._C.dqb_forward(x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma,
                                                False)
    Q, P = t_query.numel(), pts.shape[0]
    gx = torch.randn(Q, P, 3, dtype=x.dtype)
    for validate in (False, True):
        with pytest.raises(ValueError, match="t_query"):
            smg._C.dqb_backward(x, q, pts, pq, t_ref, t_query - 100, drivers, weights, gx, None,
                                False, True, True, True, True, validate)
        with pytest.raises(ValueError, match="grad_positions"):
            smg._C.dqb_backward(x, q, pts, pq, t_ref, t_query, drivers, weights, gx * float("nan"),
                                None, False, True, True, True, True, validate)
    a = loss_grads(run(scene), leaves(scene), gx, torch.ones(Q, P, 4, dtype=x.dtype))

    def validated(a_, b_, c_, d_):
        return smg.dqb(a_, b_, (idx, w), c_, d_, anchor, t_ref, t_query, sigma, validate=True)

    b = loss_grads(validated, leaves(scene), gx, torch.ones(Q, P, 4, dtype=x.dtype))
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    assert all(torch.equal(u, v) for u, v in zip(a[2], b[2]))
