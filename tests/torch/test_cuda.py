"""smg_torch's CUDA operators against its CPU operators and torch.autograd (skipped without a
CUDA device or without an smg_torch built with CUDA)."""
import pytest
import torch

import smg_torch as smg
import torch_reference as ref

pytestmark = pytest.mark.skipif(not (torch.cuda.is_available() and smg.has_cuda),
                                reason="no CUDA device or smg_torch built without CUDA")


def _scene(dtype, int64=True, T=7, N=40, K=5, seed=0):
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(T, N, 3, generator=g, dtype=torch.float64).cumsum(0) * 0.1
    q = torch.randn(T, N, 4, generator=g, dtype=torch.float64)
    graph = smg.build_graph(x.double(), k=K, gate=False)
    idx = graph.indices if int64 else graph.indices.int()
    w = graph.weights.clone()
    w[3] = 0  # a row of zero weights
    c = torch.rand(T, N, generator=g, dtype=torch.float64)
    return x.to(dtype), q.to(dtype), idx, w.to(dtype), c.to(dtype)


def _rel(a, b):
    return float((a.double() - b.double()).abs().max() / b.double().abs().max().clamp_min(1e-300))


@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-12), (torch.float32, 1e-5)])
@pytest.mark.parametrize("int64", [True, False])
def test_cuda_matches_cpu(dtype, tol, int64):
    x, q, idx, w, c = _scene(dtype, int64)
    out = {}
    for dev in ("cpu", "cuda"):
        xs = x.detach().to(dev).clone().requires_grad_()
        qs = q.detach().to(dev).clone().requires_grad_()
        g = (idx.to(dev), w.to(dev))
        conf = smg.node_confidences(xs, g)
        e = smg.carap(xs, qs, g, c.to(dev), alpha=0.3, gaps=(1, 3), gap_weights=(1.0, 0.5))
        e = e + 0.5 * smg.arap(xs, qs, g, lambda_l=0.25)
        e = e + smg.lrm(xs, g, c.to(dev))
        e.backward()
        out[dev] = (conf.cpu(), e.detach().cpu(), xs.grad.cpu(), qs.grad.cpu())
    conf_cpu, e_cpu, gx_cpu, gq_cpu = out["cpu"]
    conf_gpu, e_gpu, gx_gpu, gq_gpu = out["cuda"]
    assert _rel(e_gpu, e_cpu) <= tol
    assert _rel(gx_gpu, gx_cpu) <= tol
    assert _rel(gq_gpu, gq_cpu) <= tol
    if dtype == torch.float64:
        assert _rel(conf_gpu, conf_cpu) <= tol
    assert out["cuda"][1].dtype == dtype


def test_cuda_gradients_match_autograd():
    x, q, idx, w, c = _scene(torch.float64)
    dev = torch.device("cuda")
    x, q, idx, w, c = (t.to(dev) for t in (x, q, idx, w, c))
    xs, qs = x.clone().requires_grad_(), q.clone().requires_grad_()
    (smg.carap(xs, qs, (idx, w), c) + smg.arap(xs, qs, (idx, w))).backward()
    xr, qr = x.clone().requires_grad_(), q.clone().requires_grad_()
    (ref.carap(xr, qr, idx, w, c) + ref.arap(xr, qr, idx, w)).backward()
    assert _rel(xs.grad, xr.grad) <= 1e-10
    assert _rel(qs.grad, qr.grad) <= 1e-10


def test_cuda_deterministic_and_errors():
    x, q, idx, w, c = (t.cuda() for t in _scene(torch.float32))
    runs = []
    for _ in range(2):
        xs = x.clone().requires_grad_()
        smg.carap(xs, q, (idx, w), c).backward()
        runs.append(xs.grad)
    assert torch.equal(runs[0], runs[1])
    with pytest.raises(ValueError, match="graph.weights"):
        smg.carap(x, q, (idx, w.cpu()), c)
    with pytest.raises(ValueError, match="quats"):
        smg.carap(x, q.double(), (idx, w), c)
    with pytest.raises(NotImplementedError):
        smg.build_graph(x)


def test_cuda_validate_gives_the_cpu_messages():
    x, q, idx, w, c = _scene(torch.float64)
    x[2, 5, 1] = float("nan")
    with pytest.raises(ValueError) as cpu:
        smg.carap(x, q, (idx, w), c)
    with pytest.raises(ValueError) as gpu:
        smg.carap(x.cuda(), q.cuda(), (idx.cuda(), w.cuda()), c.cuda(), validate=True)
    assert str(gpu.value) == str(cpu.value)
    x, q, idx, w, c = _scene(torch.float64)
    idx = idx.clone()
    idx[4, 0] = 10 ** 6
    for op in (lambda d: smg.node_confidences(x.to(d), (idx.to(d), w.to(d)), validate=True),
               lambda d: smg.arap(x.to(d), q.to(d), (idx.to(d), w.to(d)), validate=True)):
        with pytest.raises(ValueError) as cpu:
            op("cpu")
        with pytest.raises(ValueError) as gpu:
            op("cuda")
        assert str(gpu.value) == str(cpu.value)


def test_cuda_mean_normalization():
    x, q, idx, w, c = _scene(torch.float64)
    e = [float(smg.carap(x.to(d), q.to(d), (idx.to(d), w.to(d)), c.to(d), normalize=True))
         for d in ("cpu", "cuda")]
    assert abs(e[1] - e[0]) <= 1e-12 * abs(e[0])


def _skin_scene(dtype, int64=True, T=5, N=30, K=6, P=200, Q=4, seed=3, antipodal=False):
    g = torch.Generator().manual_seed(seed)
    x0 = torch.randn(N, 3, generator=g, dtype=torch.float64)
    x = x0[None] + 0.2 * torch.randn(T, N, 3, generator=g, dtype=torch.float64).cumsum(0)
    q = torch.randn(T, N, 4, generator=g, dtype=torch.float64)
    if antipodal:  # drivers of one point on both hemispheres (and across frames)
        q[1::2] = -q[1::2]
        q[:, ::3] = -q[:, ::3]
    graph = smg.build_graph(x, k=K, gate=False)
    idx = graph.indices.clone()
    idx[2, K - 2:] = -1  # padding
    idx[4, :] = -1  # a node that drives its points alone
    w = graph.weights.clone()
    w[idx < 0] = 0
    anchor = torch.randint(0, N, (P,), generator=g)
    anchor[:10] = 4
    t_ref = torch.randint(0, T, (P,), generator=g)
    pts = x[t_ref, anchor] + 0.3 * torch.randn(P, 3, generator=g, dtype=torch.float64)
    pq = torch.randn(P, 4, generator=g, dtype=torch.float64)
    t_query = torch.randint(0, T, (Q,), generator=g)
    sigma = 0.3 + torch.rand(N, generator=g, dtype=torch.float64)
    idx = idx if int64 else idx.int()
    return (x.to(dtype), q.to(dtype), idx, w.to(dtype), pts.to(dtype), pq.to(dtype), anchor,
            t_ref.int(), t_query, sigma.to(dtype))


def _dqb_run(scene, dev, lbs, gx, gq, with_pq=True):
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = (t.to(dev) for t in scene)
    leaves = [t.detach().clone().requires_grad_() for t in (x, q, pts, pq)]
    px, pqo = smg.dqb(leaves[0], leaves[1], (idx, w), leaves[2], leaves[3] if with_pq else None,
                      anchor, t_ref, t_query, sigma, lbs=lbs)
    loss = (px * gx.to(dev)).sum() + (pqo * gq.to(dev)).sum()
    loss.backward()
    grads = [None if t.grad is None else t.grad.cpu() for t in leaves]
    return px.detach().cpu(), pqo.detach().cpu(), grads


@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-12), (torch.float32, 1e-5)])
@pytest.mark.parametrize("int64", [True, False])
@pytest.mark.parametrize("lbs", [False, True])
@pytest.mark.parametrize("antipodal", [False, True])
def test_cuda_dqb_matches_cpu(dtype, tol, int64, lbs, antipodal):
    scene = _skin_scene(dtype, int64, antipodal=antipodal)
    Q, P = scene[8].numel(), scene[4].shape[0]
    g = torch.Generator().manual_seed(5)
    gx = torch.randn(Q, P, 3, generator=g, dtype=torch.float64).to(dtype)
    gq = torch.randn(Q, P, 4, generator=g, dtype=torch.float64).to(dtype)
    for with_pq in (True, False):
        cpu = _dqb_run(scene, "cpu", lbs, gx, gq, with_pq)
        gpu = _dqb_run(scene, "cuda", lbs, gx, gq, with_pq)
        assert gpu[0].dtype == dtype and gpu[1].dtype == dtype
        assert _rel(gpu[0], cpu[0]) <= tol
        assert _rel(gpu[1], cpu[1]) <= tol
        # A node gradient is a sum over points whose terms can cancel: its round-off is relative
        # to the terms, so every gradient is compared against the largest of the four (as
        # tests/cuda/test_cuda_dqb.cu).
        scale = max(float(b.double().abs().max()) for b in cpu[2] if b is not None)
        for name, a, b in zip(("node_positions", "node_quats", "points", "point_quats"), gpu[2],
                              cpu[2]):
            if not with_pq and name == "point_quats":
                assert a is None and b is None
                continue
            assert a.dtype == dtype
            assert float((a.double() - b.double()).abs().max()) <= tol * scale, name


def test_cuda_dqb_internals_and_determinism():
    """The driver table equals the CPU's; the weights match; two runs are bit-identical."""
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = _skin_scene(torch.float64)
    cpu = smg._C.dqb_forward(x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma, False)
    d = [t.cuda() for t in (x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma)]
    runs = [smg._C.dqb_forward(*d, False) for _ in range(2)]  # CUDA tensors: the CUDA operator
    assert runs[0][2].dtype == torch.int32
    assert torch.equal(runs[0][2].cpu(), cpu[2])
    assert _rel(runs[0][3].cpu(), cpu[3]) <= 1e-12
    for a, b in zip(runs[0], runs[1]):
        assert torch.equal(a, b)
    # on a side stream (the current stream of the device), forward and backward
    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        xs = d[0].clone().requires_grad_()
        px, pqo = smg.dqb(xs, d[1], (d[2], d[3]), d[4], d[5], d[6], d[7], d[8], d[9])
        (px.sum() + pqo.sum()).backward()
    torch.cuda.current_stream().wait_stream(side)
    xc = x.clone().requires_grad_()
    px_c, pqo_c = smg.dqb(xc, q, (idx, w), pts, pq, anchor, t_ref, t_query, sigma)
    (px_c.sum() + pqo_c.sum()).backward()
    assert _rel(px.cpu(), px_c.detach()) <= 1e-12
    assert _rel(xs.grad.cpu(), xc.grad) <= 1e-12


def test_cuda_dqb_errors():
    scene = [t.cuda() for t in _skin_scene(torch.float32)]
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = scene

    def call(**kw):
        a = dict(node_positions=x, node_quats=q, g=(idx, w), points=pts, point_quats=pq,
                 anchor=anchor, t_ref=t_ref, t_query=t_query, sigma=sigma)
        a.update(kw)
        return smg.dqb(**a)

    with pytest.raises(ValueError, match="points"):
        call(points=pts.cpu())
    with pytest.raises(ValueError, match="sigma"):
        call(sigma=sigma.cpu())
    with pytest.raises(ValueError, match="anchor"):
        call(anchor=anchor.cpu())
    with pytest.raises(ValueError, match="graph.indices"):
        call(g=(idx.cpu(), w))
    with pytest.raises(ValueError, match="node_positions"):  # CPU positions, a CUDA input
        call(node_positions=x.cpu(), node_quats=q.cpu(), points=pts.cpu(), point_quats=pq.cpu(),
             g=(idx.cpu(), w.cpu()), anchor=anchor.cpu(), t_ref=t_ref.cpu(),
             t_query=t_query.cpu(), sigma=sigma)
    with pytest.raises(ValueError, match="node_quats"):
        call(node_quats=q.double())
    # contents: the CPU operator's messages
    cpu = [t.cpu() for t in scene]
    names = ("node_positions", "node_quats", "g", "points", "point_quats", "anchor", "t_ref",
             "t_query", "sigma")

    def args(ts):
        return dict(zip(names, (ts[0], ts[1], (ts[2], ts[3])) + tuple(ts[4:])))

    def with_value(t, i, v):
        t = t.clone()
        t[i] = v
        return t

    # (CUDA tensors' contents are checked with validate=True; CPU tensors' always)
    bad = [(6, 7, 10 ** 6), (8, 1, -1), (7, 3, 99), (9, 2, -1.0), (2, 0, 10 ** 4)]
    for k, i, v in bad:
        ts_cpu, ts_gpu = list(cpu), list(scene)
        ts_cpu[k], ts_gpu[k] = with_value(cpu[k], i, v), with_value(scene[k], i, v)
        with pytest.raises(ValueError) as e_cpu:
            smg.dqb(**args(ts_cpu))
        with pytest.raises(ValueError) as e_gpu:
            smg.dqb(**args(ts_gpu), validate=True)
        assert str(e_gpu.value) == str(e_cpu.value)
    # the backward's checks (t_query, finite incoming gradients), with validate=True
    _, _, drivers, weights = smg._C.dqb_forward(x, q, idx, w, pts, pq, anchor, t_ref, t_query,
                                                sigma, False)
    gx = torch.ones(t_query.numel(), pts.shape[0], 3, dtype=x.dtype, device=x.device)
    for needle, tq, g in [("t_query", t_query + 100, gx), ("grad_positions", t_query, gx * float("nan"))]:
        with pytest.raises(ValueError, match=needle):
            smg._C.dqb_backward(x, q, pts, pq, t_ref, tq, drivers, weights, g, None, False, True, True,
                                True, True, True)


def test_cuda_dqb_reads_nothing_back_without_validate():
    """Without validate=True the CUDA dqb, forward and backward, makes no synchronising torch call
    (torch's sync debug mode raises on one: .cpu(), .item(), ...); with validate=True it does."""
    scene = [t.cuda() for t in _skin_scene(torch.float32)]
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = scene

    def fwd_bwd(validate):
        leaves = [t.clone().requires_grad_() for t in (x, q, pts, pq)]
        px, pqo = smg.dqb(leaves[0], leaves[1], (idx, w), leaves[2], leaves[3], anchor, t_ref,
                          t_query, sigma, validate=validate)
        (px.sum() + pqo.sum()).backward()
        return px, leaves[0].grad

    torch.cuda.synchronize()
    torch.cuda.set_sync_debug_mode("error")
    try:
        px, gx = fwd_bwd(False)
        with pytest.raises(RuntimeError):
            fwd_bwd(True)
    finally:
        torch.cuda.set_sync_debug_mode("default")
    px_v, gx_v = fwd_bwd(True)
    assert torch.equal(px, px_v) and torch.equal(gx, gx_v)


def test_cuda_dqb_query_frames_out_of_range_without_validate():
    """Without validate=True a t_query entry out of range is not caught, but the kernels do not
    read out of bounds: that query's outputs are NaN and it adds nothing to the gradients (the
    rest equals the CPU run without it)."""
    scene = _skin_scene(torch.float64)
    x, q, idx, w, pts, pq, anchor, t_ref, t_query, sigma = scene
    T, Q, P = x.shape[0], t_query.numel(), pts.shape[0]
    bad_tq = torch.cat([t_query[:1], torch.tensor([T, -1]), t_query[1:]])
    good = torch.tensor([0] + list(range(3, Q + 2)))
    g = torch.Generator().manual_seed(3)
    gx = torch.randn(Q + 2, P, 3, generator=g, dtype=torch.float64)
    gq = torch.randn(Q + 2, P, 4, generator=g, dtype=torch.float64)
    cpu = _dqb_run(scene, "cpu", False, gx[good], gq[good])
    bad_scene = list(scene)
    bad_scene[8] = bad_tq
    gpu = _dqb_run(bad_scene, "cuda", False, gx, gq)
    assert torch.isnan(gpu[0][1:3]).all() and torch.isnan(gpu[1][1:3]).all()
    assert _rel(gpu[0][good], cpu[0]) <= 1e-12 and _rel(gpu[1][good], cpu[1]) <= 1e-12
    scale = max(float(b.abs().max()) for b in cpu[2])
    for a, b in zip(gpu[2], cpu[2]):
        assert float((a - b).abs().max()) <= 1e-12 * scale



@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-11), (torch.float32, 1e-5)])
@pytest.mark.parametrize("int64", [True, False])
def test_cuda_regularizers_match_cpu(dtype, tol, int64):
    """The fused step on CUDA (smg::cuda::regularizers) against the CPU fused step, every term on
    (trajectory smoothness too): energies, confidences and both gradients; two CUDA runs
    bitwise."""
    x, q, idx, w, _ = _scene(dtype, int64, T=12, N=60, K=6)
    vis = (torch.rand(x.shape[:2], generator=torch.Generator().manual_seed(3)) < 0.9).to(torch.uint8)
    out = {}
    for dev in ("cpu", "cuda", "cuda2"):
        d = dev[:4]
        xs = x.detach().to(d).clone().requires_grad_()
        qs = q.detach().to(d).clone().requires_grad_()
        r = smg.regularizers(xs, qs, (idx.to(d), w.to(d)), vis.to(d), arap=True,
                             lrm={"huber_delta": 0.05},
                             accel={"confidence_weighted": True, "weight": 0.5})
        r.total.backward()
        out[dev] = (torch.stack([r.carap, r.arap, r.lrm, r.accel]).detach().cpu(), r.confidence.cpu(),
                    xs.grad.cpu(), qs.grad.cpu())
    for a, b in zip(out["cuda"], out["cpu"]):
        assert _rel(a, b) <= tol
    for a, b in zip(out["cuda"], out["cuda2"]):
        assert torch.equal(a, b)
