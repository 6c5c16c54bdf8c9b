"""smg_torch.compat against plain-torch implementations of the upstream losses, written here from
their reading (docs/compat.md): values and autograd gradients, float64 and float32, the inputs
where torch's gradient is exactly 0, bad arguments, and CUDA (skipped without a device)."""
import pytest
import torch

import smg_torch as smg
from smg_torch.compat import som_accel

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
    (lambda: torch.full((4, 5, 3), float("nan")), ValueError, "positions"),
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
