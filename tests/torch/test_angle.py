"""smg_torch.regularizers' rotation-angle term (angle, docs/math/terms/angle.md (E23)) against an
independent plain-torch implementation of MoSca's rotation velocity / acceleration
(`compute_vel_acc`): F.normalize, quaternion -> matrix, R^{t+1} R^{tT}, matrix -> quaternion
(standardised, w >= 0) -> axis-angle, its norm, all as pytorch3d's rotation_conversions compute
them (written here: pytorch3d is not a dependency), differentiated by torch's autograd."""
import math

import pytest
import torch

import smg_torch as smg
from pytorch3d_reference import mosca_angles
from scenes import antipodal, random_scene


def rel(a, b):
    a, b = a.detach().double(), b.detach().double()
    return float((a - b).norm() / max(float(b.norm()), 1e-300))


def angle_reference(q, c, form, weighted, normalize, weight):
    th = mosca_angles(q)
    per = th if form == "velocity" else (th[1:] - th[:-1]).abs()
    if weighted:
        per = per * c[: per.shape[0]]
    return weight * (per.mean() if normalize else per.sum())


# ---- the comparison ----------------------------------------------------------------------------

@pytest.mark.parametrize("form", ["acceleration", "velocity"])
@pytest.mark.parametrize("normalize", [True, False])
@pytest.mark.parametrize("weighted", [False, True])
def test_angle_equals_mosca_torch_autograd(form, normalize, weighted):
    x, q, idx, w, _ = random_scene(T=20, N=64, K=4)
    q = q * 1.3  # unnormalised: the term normalises on entry
    vis = torch.rand(x.shape[0], x.shape[1]) > 0.2
    opts = dict(form=form, normalize=normalize, confidence_weighted=weighted, weight=0.7)
    qs = q.clone().requires_grad_()
    r = smg.regularizers(x, qs, (idx, w), vis, carap=False, lrm=False, angle=opts)
    qr = q.clone().requires_grad_()
    e = angle_reference(qr, r.confidence, form, weighted, normalize, 0.7)
    assert float(e) > 0
    assert rel(r.angle, e) < 1e-9 and rel(r.total, e) < 1e-9
    r.total.backward()
    e.backward()
    assert rel(qs.grad, qr.grad) < 1e-7
    # The positions get no gradient from this term.
    xs = x.clone().requires_grad_()
    r2 = smg.regularizers(xs, q, (idx, w), vis, carap=False, lrm=False, angle=opts)
    r2.total.backward()
    assert xs.grad is None or float(xs.grad.abs().max()) == 0.0


def test_angle_agreement_figures(capsys):
    """The agreement figures of the mean forms (MoSca's photometric stage), printed with -s."""
    x, q, idx, w, _ = random_scene(T=20, N=64, K=4)
    q = q * 1.3
    for form in ("velocity", "acceleration"):
        qs, qr = q.clone().requires_grad_(), q.clone().requires_grad_()
        r = smg.regularizers(x, qs, (idx, w), confidence=False, carap=False, lrm=False,
                             angle=dict(form=form, normalize=True))
        e = angle_reference(qr, None, form, False, True, 1.0)
        r.total.backward()
        e.backward()
        with capsys.disabled():
            print("angle %s: energy rel %.2e, gradient rel %.2e" % (form, rel(r.angle, e), rel(qs.grad, qr.grad)))
        assert rel(r.angle, e) < 1e-9 and rel(qs.grad, qr.grad) < 1e-7


def test_angle_antipodal_and_constant():
    x, q, idx, w, _ = random_scene(T=8)
    a = smg.regularizers(x, q, (idx, w), carap=False, lrm=False, angle=True)
    b = smg.regularizers(x, antipodal(q), (idx, w), carap=False, lrm=False, angle=True)
    assert float(a.angle) > 0 and abs(float(a.angle) - float(b.angle)) <= 1e-12 * float(a.angle)
    # The same (unnormalised) quaternion in every frame: energy 0, gradient exactly 0.
    still = (1.3 * q[:1]).repeat(q.shape[0], 1, 1).requires_grad_()
    for form in ("velocity", "acceleration"):
        r = smg.regularizers(x, still, (idx, w), carap=False, lrm=False, angle=dict(form=form))
        assert float(r.angle) == 0.0
        (g,) = torch.autograd.grad(r.total, still)
        assert float(g.abs().max()) == 0.0


def test_angle_known_angle_and_needs_quats():
    # Node rotations about z by 0.4 rad per frame: θ = 0.4 exactly, the acceleration 0.
    T, N = 6, 3
    x, _, idx, w, _ = random_scene(T=T, N=N, K=2, empty_rows=())
    half = 0.2 * torch.arange(T, dtype=torch.float64)
    q = torch.stack([torch.cos(half), 0 * half, 0 * half, torch.sin(half)], -1)[:, None].repeat(1, N, 1)
    r = smg.regularizers(x, q, (idx, w), carap=False, lrm=False, angle=dict(form="velocity"))
    assert math.isclose(float(r.angle), 0.4 * (T - 1) * N, rel_tol=1e-13)
    with pytest.raises(ValueError, match="quats"):
        smg.regularizers(x, None, (idx, w), carap=False, lrm=False, angle=True)


def test_angle_gradcheck():
    from torch.autograd import gradcheck
    x, q, idx, w, _ = random_scene(T=6, N=7, K=2)
    f = lambda b: smg.regularizers(x, b, (idx, w), confidence=False, carap=False, lrm=False,
                                   angle=dict(form="acceleration")).total
    assert gradcheck(f, (q.clone().requires_grad_(),))
