"""The two builds of the CPU energy operators (issue 59 item 2; docs/torch.md "Instruction sets"):
smg_torch._C (x86-64's baseline, SSE2) and smg_torch._C_avx2 (-mavx2 -mfma -ffp-contract=off),
chosen at import by the CPU and SMG_TORCH_ISA. Every smg_torch operator of the hostile suite's list
(_operators: the energy operators, dqb, render and every compat call) runs through both on the same
inputs and agrees to the rounding that Eigen's FMA packets and the vector width change (and keeps
the exact zeros test_angle.py and test_compat.py check, on whichever build runs); the choice is reported
(smg_torch.isa) and the environment variable is obeyed or refused by name."""
import os
import subprocess
import sys

import pytest
import torch
import torch.nn.functional as F

import smg_torch as smg
import smg_torch.compat as compat
from test_compat_hostile import _operators
from test_compat_d3dgs import scene as d3dgs_scene
from scenes import random_scene

try:
    from smg_torch import _C_avx2 as FAST
except ImportError:  # built with SMG_TORCH_AVX2=OFF / SMG_TORCH_NO_AVX2=1, or not x86-64
    FAST = None
RUNS_FAST = FAST is not None and smg._C_base._cpu_supports_avx2_fma()
needs_fast = pytest.mark.skipif(not RUNS_FAST, reason="no smg_torch._C_avx2 or no AVX2 + FMA on this CPU")


def _rel(a, b):
    m, d = float(b.abs().max()), float((a - b).abs().max())
    return d / m if m > 0 else d


def _run(fast, f):
    """f() with the wrappers calling _C_avx2 (fast) or only _C (fast None)."""
    with smg._operators_in_use(smg._operators_from(fast)):
        return f()


def test_the_modules_report_what_they_were_compiled_for():
    assert smg._C_base._isa == "base"
    assert smg.isa in ("base", "avx2+fma")
    if FAST is not None:
        assert FAST._isa == "avx2+fma"
    if RUNS_FAST and os.environ.get("SMG_TORCH_ISA", "auto") in ("auto", "avx2", ""):
        assert smg.isa == "avx2+fma"
        assert smg._C.regularizers is FAST.regularizers and smg._C.carap is FAST.carap
    else:
        assert smg._C.regularizers is smg._C_base.regularizers
    # Operators _C_avx2 does not build, and the module's own state, stay _C's.
    assert smg._C.render_forward is smg._C_base.render_forward
    assert smg._C.has_cuda is smg._C_base.has_cuda


@needs_fast
@pytest.mark.parametrize("name", list(_operators()))
def test_both_builds_agree_in_float64(name):
    def once():
        torch.manual_seed(7)  # _operators() draws its scenes: the same ones for both builds
        leaves, loss = _operators()[name]()
        loss.backward()
        return loss.detach(), [a.grad for a in leaves]
    e0, g0 = _run(None, once)
    e1, g1 = _run(FAST, once)
    assert _rel(e1, e0) <= 1e-13, name
    for a, b in zip(g1, g0):
        assert _rel(a, b) <= 1e-12, name


@needs_fast
@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-13), (torch.float32, 2e-6)])
def test_both_builds_agree_on_the_fused_step_and_d3dgs(dtype, tol):
    x, q, idx, w, c = random_scene(T=11, N=40, K=6, dtype=dtype)
    d3 = [t.to(dtype) if t.is_floating_point() else t for t in d3dgs_scene(N=200, K=8, seed=5)]

    def once():
        a, b = x.clone().requires_grad_(), q.clone().requires_grad_()
        r = smg.regularizers(a, b, (idx, w.to(dtype)))
        p, u = d3[0].clone().requires_grad_(), F.normalize(d3[1], dim=-1).requires_grad_()
        losses = compat.d3dgs_losses(p, u, *d3[2:])
        (r.total + sum(losses)).backward()
        return [r.total.detach()] + [v.detach() for v in losses], [a.grad, b.grad, p.grad, u.grad]
    e0, g0 = _run(None, once)
    e1, g1 = _run(FAST, once)
    for a, b in zip(e1 + g1, e0 + g0):
        assert a.dtype == dtype
        assert _rel(a, b) <= tol


def _import_isa(value):
    env = dict(os.environ, SMG_TORCH_ISA=value)
    return subprocess.run([sys.executable, "-c", "import smg_torch; print(smg_torch.isa)"], env=env,
                          capture_output=True, text=True, timeout=120)


def test_the_environment_forces_the_baseline_and_bad_values_are_refused_by_name():
    r = _import_isa("base")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "base"
    r = _import_isa("avx512")
    assert r.returncode != 0
    assert "SMG_TORCH_ISA must be auto, base or avx2, got 'avx512'" in r.stderr.strip().splitlines()[-1]
    r = _import_isa("avx2")
    if RUNS_FAST:
        assert r.returncode == 0 and r.stdout.strip() == "avx2+fma", r.stderr
    else:
        assert r.returncode != 0 and "SMG_TORCH_ISA=avx2" in r.stderr
