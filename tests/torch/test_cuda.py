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
        if hasattr(smg._C, "cuda_lrm"):
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
