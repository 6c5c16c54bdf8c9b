"""smg_torch.render: agreement with tests/reference/gsplat_reference.py (a pure-PyTorch
restatement of gsplat's projection and rasterisation, autograd for the gradients), gradcheck
w.r.t. every Gaussian parameter, a Gaussian at the near plane, float32, errors."""
import math
import os
import sys

import numpy as np
import pytest
import torch
from torch.autograd import gradcheck

import smg_torch as smg

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "reference"))
import gsplat_reference as gref  # noqa: E402

NAMES = ("means", "quats", "scales", "opacities", "colors")


def rel(a, b):
    a, b = a.detach().double(), b.detach().double()
    return float((a - b).norm() / max(float(b.norm()), 1e-300))


def scene(seed, G, W, H, C, sh):
    arrays, bg = gref.random_scene(np.random.default_rng(seed), G, W, H, C, sh)
    t = {k: torch.tensor(v) for k, v in arrays.items()}
    return t, torch.tensor(bg)


def smg_render(t, bg, W, H, tile=16, **kw):
    return smg.render(t["means"], t["quats"], t["scales"], t["opacities"], t["colors"], t["viewmat"],
                      t["K"], W, H, background=bg, tile_size=tile, **kw)


@pytest.mark.parametrize("case", [(1, 200, 40, 30, 3, -1, 16), (2, 120, 33, 25, 3, 2, 8),
                                  (3, 100, 30, 20, 2, -1, 32), (4, 80, 24, 20, 3, 3, 16)])
def test_render_matches_gsplat_reference(case):
    seed, G, W, H, C, sh, tile = case
    t, bg = scene(seed, G, W, H, C, sh)
    gen = torch.Generator().manual_seed(seed)
    g_img, g_a, g_d = torch.randn(H, W, C, generator=gen), torch.randn(H, W, generator=gen), \
        0.2 * torch.randn(H, W, generator=gen)
    outs = {}
    for name, fn in (("smg", lambda p: smg_render(p, bg, W, H, tile)),
                     ("ref", lambda p: gref.render(p["means"], p["quats"], p["scales"], p["opacities"],
                                                   p["colors"], p["viewmat"], p["K"], W, H, bg, sh,
                                                   tile=tile)[:3])):
        p = {k: (v.clone().requires_grad_() if k in NAMES else v) for k, v in t.items()}
        img, acc, depth = fn(p)
        ((img * g_img).sum() + (acc * g_a).sum() + (depth * g_d).sum()).backward()
        outs[name] = (img.detach(), acc.detach(), depth.detach(), [p[k].grad for k in NAMES])
    a, b = outs["smg"], outs["ref"]
    for u, v in zip(a[:3], b[:3]):
        assert rel(u, v) < 1e-10
    for n, u, v in zip(NAMES, a[3], b[3]):
        assert rel(u, v) < 1e-10, n


def small_scene(near_plane=False):
    """A few Gaussians well inside a 14x11 image, alphas below the clamp."""
    gen = torch.Generator().manual_seed(7)
    G, W, H = 5, 14, 11
    f = 12.0
    K = torch.tensor([[f, 0, W / 2 + 0.2], [0, f * 1.1, H / 2 - 0.3], [0, 0, 1.0]])
    viewmat = torch.eye(4)
    ang = 0.2
    viewmat[:3, :3] = torch.tensor([[math.cos(ang), 0, math.sin(ang)], [0, 1, 0],
                                    [-math.sin(ang), 0, math.cos(ang)]])
    viewmat[:3, 3] = torch.tensor([0.1, -0.05, 0.2])
    zc = 2.0 + torch.rand(G, generator=gen)
    if near_plane:
        zc[0] = 0.01 + 0.02  # just in front of the near plane (near = 0.01)
    uv = torch.stack([W * (0.25 + 0.5 * torch.rand(G, generator=gen)),
                      H * (0.25 + 0.5 * torch.rand(G, generator=gen))], 1)
    pc = torch.stack([(uv[:, 0] - K[0, 2]) / K[0, 0] * zc, (uv[:, 1] - K[1, 2]) / K[1, 1] * zc, zc], 1)
    means = (pc - viewmat[:3, 3]) @ viewmat[:3, :3]
    quats = torch.randn(G, 4, generator=gen)
    scales = torch.log(zc[:, None] / f * (1.5 + 2 * torch.rand(G, 3, generator=gen)))
    if near_plane:
        scales[0] = math.log(0.002)
    logits = torch.randn(G, generator=gen) * 0.5 - 0.5
    colors = torch.rand(G, 3, generator=gen)
    return dict(means=means, quats=quats, scales=scales, opacities=logits, colors=colors,
                viewmat=viewmat, K=K), W, H


@pytest.mark.parametrize("near_plane", [False, True])
def test_render_gradcheck(near_plane):
    t, W, H = small_scene(near_plane)
    bg = torch.tensor([0.1, 0.5, 0.9])
    gen = torch.Generator().manual_seed(3)
    g_a, g_d = torch.randn(H, W, generator=gen), 0.1 * torch.randn(H, W, generator=gen)

    def f(means, quats, scales, opacities, colors):
        img, acc, depth = smg.render(means, quats, scales, opacities, colors, t["viewmat"], t["K"], W, H,
                                     background=bg, radius_sigmas=4.0)
        return img, (acc * g_a).sum() + (depth * g_d).sum()

    inputs = tuple(t[k].clone().requires_grad_() for k in NAMES)
    assert gradcheck(f, inputs, atol=1e-6, rtol=1e-5)
    if near_plane:  # the Gaussian at the near plane is visible and gets a gradient
        img, loss = f(*inputs)
        (img.sum() + loss).backward()
        assert float(inputs[0].grad[0].abs().sum()) > 0


def test_render_float32_and_sh():
    t, bg = scene(5, 100, 30, 24, 3, 1)
    a = smg_render(t, bg, 30, 24)
    t32 = {k: v.float() for k, v in t.items()}
    b = smg_render(t32, bg.float(), 30, 24)
    assert b[0].dtype == torch.float32
    assert rel(b[0], a[0]) < 1e-4 and rel(b[1], a[1]) < 1e-4


def test_render_errors():
    t, bg = scene(6, 20, 16, 12, 3, -1)
    before = {k: v.clone() for k, v in t.items()}
    bad = [dict(means=t["means"][:, :2]), dict(quats=t["quats"].float()),
           dict(quats=t["quats"].index_put((torch.tensor(0),), torch.zeros(4))),
           dict(means=t["means"].index_put((torch.tensor(1),), torch.tensor([float("nan")] * 3))),
           dict(colors=t["colors"][:10]), dict(viewmat=t["viewmat"][:3]),
           dict(K=t["K"].index_put((torch.tensor(0), torch.tensor(1)), torch.tensor(0.5)))]
    for change in bad:
        p = dict(t, **change)
        with pytest.raises(ValueError):
            smg_render(p, bg, 16, 12)
    with pytest.raises(ValueError):
        smg_render(t, bg, 16, 12, tile=7)
    with pytest.raises(ValueError):
        smg_render(t, torch.ones(2), 16, 12)
    assert all(torch.equal(before[k], t[k]) for k in t)
