#!/usr/bin/env python3
"""Independent check of smg's splatter against gsplat's maths, in PyTorch (CPU, float64).

usage: gsplat_reference.py --cli PATH/TO/smg_cli [--workdir DIR] [--seed N]

A dense re-statement of gsplat's pure-PyTorch reference (gsplat/cuda/_torch_impl.py:
_quat_scale_to_covar_preci, _world_to_cam, _persp_proj, _fully_fused_projection,
_isect_tiles, and the compositing of rasterize_to_pixels with the CUDA kernels' constants),
written here from the equations, not copied: every pixel against every depth-sorted Gaussian,
masked by tile binning, the 1/255 skip, the 0.99 clamp and the exclusive 1e-4 transmittance
rule; autograd supplies the reference gradients. Random scenes are written as case
directories, rendered by `smg_cli render` (double and --float), and images, alphas, expected
depths and every gradient are compared. Prints one line per comparison; exits 1 when a
tolerance is exceeded, 0 otherwise. Needs numpy and torch (Debian: python3-torch).
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np
import torch

torch.set_default_dtype(torch.float64)

ALPHA_MIN = 1.0 / 255.0
T_MIN = 1e-4

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396]
SH_C3 = [-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435]


def rotmat(q):
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).reshape(-1, 3, 3)


def sh_colors(degree, coeffs, dirs):
    """coeffs [G, K, C]; dirs [G, 3] (unnormalised). gsplat: max(SH + 0.5, 0)."""
    d = dirs / dirs.norm(dim=-1, keepdim=True)
    x, y, z = d.unbind(-1)
    basis = [torch.full_like(x, SH_C0)]
    if degree >= 1:
        basis += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree >= 2:
        basis += [SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2 * z * z - x * x - y * y),
                  SH_C2[3] * x * z, SH_C2[4] * (x * x - y * y)]
    if degree >= 3:
        basis += [SH_C3[0] * y * (3 * x * x - y * y), SH_C3[1] * x * y * z,
                  SH_C3[2] * y * (4 * z * z - x * x - y * y),
                  SH_C3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y),
                  SH_C3[4] * x * (4 * z * z - x * x - y * y), SH_C3[5] * z * (x * x - y * y),
                  SH_C3[6] * x * (x * x - 3 * y * y)]
    B = torch.stack(basis, -1)  # [G, K]
    return torch.clamp_min((B[:, :, None] * coeffs).sum(1) + 0.5, 0.0)


def project(means, quats, log_scales, viewmat, K, W, H, eps2d):
    """gsplat's pinhole EWA projection: 2D means, conics (a, b, c), depths, dilated 2D cov."""
    R_cam, t_cam = viewmat[:3, :3], viewmat[:3, 3]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    Rg = rotmat(quats)
    M = Rg * torch.exp(log_scales)[:, None, :]
    cov = M @ M.transpose(-1, -2)
    pc = means @ R_cam.T + t_cam
    covc = R_cam @ cov @ R_cam.T
    x, y, z = pc.unbind(-1)
    tan_fx, tan_fy = 0.5 * W / fx, 0.5 * H / fy
    tx = z * torch.clamp(x / z, min=-(cx / fx + 0.3 * tan_fx), max=(W - cx) / fx + 0.3 * tan_fx)
    ty = z * torch.clamp(y / z, min=-(cy / fy + 0.3 * tan_fy), max=(H - cy) / fy + 0.3 * tan_fy)
    O = torch.zeros_like(z)
    J = torch.stack([fx / z, O, -fx * tx / z ** 2, O, fy / z, -fy * ty / z ** 2], -1).reshape(-1, 2, 3)
    cov2 = J @ covc @ J.transpose(-1, -2) + eps2d * torch.eye(2)
    det = cov2[:, 0, 0] * cov2[:, 1, 1] - cov2[:, 0, 1] * cov2[:, 1, 0]
    conic = torch.stack([cov2[:, 1, 1] / det, -0.5 * (cov2[:, 0, 1] + cov2[:, 1, 0]) / det,
                         cov2[:, 0, 0] / det], -1)
    m2 = torch.stack([fx * x / z + cx, fy * y / z + cy], -1)
    return m2, conic, z, cov2, det


def render(means, quats, log_scales, logits, colors, viewmat, K, W, H, bg, sh_degree,
           tile=16, eps2d=0.3, near=0.01, far=1e10, alpha_max=0.99, ksig=3.0):
    # Culling and binning (not differentiated), on every Gaussian.
    with torch.no_grad():
        m2, conic, z, cov2, det = project(means, quats, log_scales, viewmat, K, W, H, eps2d)
        opac = torch.sigmoid(logits)
        b = 0.5 * (cov2[:, 0, 0] + cov2[:, 1, 1])
        lam = b + torch.sqrt(torch.clamp(b * b - det, min=0.01))
        radius = torch.ceil(ksig * torch.sqrt(lam))
        visible = (z >= near) & (z <= far) & (det > 0) & (opac >= ALPHA_MIN)
        visible &= (m2[:, 0] + radius > 0) & (m2[:, 0] - radius < W) & \
                   (m2[:, 1] + radius > 0) & (m2[:, 1] - radius < H)
        radius = torch.where(visible, radius, torch.zeros_like(radius))
        tw, th = (W + tile - 1) // tile, (H + tile - 1) // tile
        t_x0 = torch.clamp(torch.floor(m2[:, 0] / tile - radius / tile), 0, tw)
        t_x1 = torch.clamp(torch.ceil(m2[:, 0] / tile + radius / tile), 0, tw)
        t_y0 = torch.clamp(torch.floor(m2[:, 1] / tile - radius / tile), 0, th)
        t_y1 = torch.clamp(torch.ceil(m2[:, 1] / tile + radius / tile), 0, th)
        # visible Gaussians in depth order, ties by index (a stable sort)
        vis_idx = torch.nonzero(visible).flatten()
        order = vis_idx[torch.from_numpy(np.argsort(z[vis_idx].numpy(), kind="stable"))]
    # The differentiable part, on the visible Gaussians only (culled ones get zero gradients).
    o_ = order
    m2, conic, z, _, _ = project(means[o_], quats[o_], log_scales[o_], viewmat, K, W, H, eps2d)
    opac = torch.sigmoid(logits[o_])
    R_cam, t_cam = viewmat[:3, :3], viewmat[:3, 3]
    if sh_degree >= 0:
        col = sh_colors(sh_degree, colors[o_], means[o_] - (-R_cam.T @ t_cam))
    else:
        col = colors[o_]
    py, px = torch.meshgrid(torch.arange(H, dtype=torch.float64) + 0.5,
                            torch.arange(W, dtype=torch.float64) + 0.5, indexing="ij")
    px, py = px.reshape(-1, 1), py.reshape(-1, 1)
    dx = m2[:, 0][None, :] - px
    dy = m2[:, 1][None, :] - py
    sigma = 0.5 * (conic[:, 0] * dx * dx + conic[:, 2] * dy * dy) + conic[:, 1] * dx * dy
    alpha = torch.clamp_max(opac[None, :] * torch.exp(-sigma), alpha_max)
    with torch.no_grad():
        ptx = (px // tile).long()
        pty = (py // tile).long()
        binned = (ptx >= t_x0[o_][None, :]) & (ptx < t_x1[o_][None, :]) & \
                 (pty >= t_y0[o_][None, :]) & (pty < t_y1[o_][None, :])
        valid = binned & (sigma >= 0) & (alpha >= ALPHA_MIN)
        a_valid = torch.where(valid, alpha, torch.zeros_like(alpha))
        t_next = torch.cumprod(1 - a_valid, dim=1)
        keep = valid & (t_next > T_MIN)  # exclusive: the Gaussian reaching <= 1e-4 is dropped
        stats = dict(terminated=int((valid & ~keep).any(1).sum()),
                     clamped=int((keep & (opac[None, :] * torch.exp(-sigma) > alpha_max)).sum()))
    a = torch.where(keep, alpha, torch.zeros_like(alpha))
    one_minus = 1 - a
    T = torch.cat([torch.ones_like(one_minus[:, :1]), torch.cumprod(one_minus, 1)[:, :-1]], 1)
    w = a * T
    T_final = torch.prod(one_minus, 1)
    image = w @ col + T_final[:, None] * bg[None, :]
    acc = 1 - T_final
    depth = (w @ z) / torch.clamp(acc, min=1e-10)
    C = col.shape[1]
    return image.reshape(H, W, C), acc.reshape(H, W), depth.reshape(H, W), radius, stats


def random_scene(rng, G, W, H, C, sh_degree):
    ang = rng.normal(size=3) * 0.3
    th = np.linalg.norm(ang)
    k = ang / th
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    Rc = np.eye(3) + math.sin(th) * Kx + (1 - math.cos(th)) * Kx @ Kx
    viewmat = np.eye(4)
    viewmat[:3, :3] = Rc
    viewmat[:3, 3] = rng.normal(size=3) * 0.2
    f = 0.9 * W
    Kmat = np.array([[f, 0, W / 2 + 0.3], [0, f * 1.05, H / 2 - 0.2], [0, 0, 1.0]])
    # camera-space positions mostly in the frustum, some outside or behind
    zc = rng.uniform(1.5, 6.0, size=G)
    zc[G // 20: G // 5] = rng.uniform(2.0, 2.5, size=G // 5 - G // 20)  # a dense layer
    zc[: G // 20] = rng.uniform(-1.0, 0.005, size=G // 20)  # behind / inside the near plane
    u = rng.uniform(-0.3 * W, 1.3 * W, size=G)
    v = rng.uniform(-0.3 * H, 1.3 * H, size=G)
    pc = np.stack([(u - Kmat[0, 2]) / Kmat[0, 0] * zc, (v - Kmat[1, 2]) / Kmat[1, 1] * zc, zc], 1)
    means = (pc - viewmat[:3, 3]) @ Rc  # R^T (p - t)
    quats = rng.normal(size=(G, 4)) * rng.uniform(0.5, 2.0, size=(G, 1))
    sig_px = rng.uniform(0.6, 5.0, size=(G, 1)) * rng.uniform(0.4, 1.6, size=(G, 3))
    sig_px[G // 20: G // 5] *= 2.5  # the dense layer is wide...
    log_scales = np.log(sig_px * np.abs(zc)[:, None] / f + 1e-6)
    logits = rng.normal(size=G) * 1.5 + 0.3
    logits[G // 20: G // 5] = rng.uniform(3.0, 7.0, size=G // 5 - G // 20)  # ...and opaque
    if sh_degree >= 0:
        Kb = (sh_degree + 1) ** 2
        colors = rng.normal(size=(G, Kb, C)) * 0.3
        colors[:, 0, :] = rng.uniform(-0.5, 1.5, size=(G, C))
    else:
        colors = rng.uniform(0, 1, size=(G, C))
    bg = rng.uniform(0, 1, size=C)
    return dict(means=means, quats=quats, scales=log_scales, opacities=logits, colors=colors,
                viewmat=viewmat, K=Kmat), bg


def run_case(cli, workdir, name, rng, G, W, H, C, sh_degree, use_float, tile):
    arrays, bg = random_scene(rng, G, W, H, C, sh_degree)
    case = os.path.join(workdir, name)
    out = os.path.join(workdir, name + "_out")
    os.makedirs(case, exist_ok=True)
    for k, v in arrays.items():
        np.save(os.path.join(case, k + ".npy"), v)
    g_img = rng.normal(size=(H, W, C))
    g_alpha = rng.normal(size=(H, W))
    g_depth = rng.normal(size=(H, W)) * 0.2
    np.save(os.path.join(case, "grad_image.npy"), g_img)
    np.save(os.path.join(case, "grad_alpha.npy"), g_alpha)
    np.save(os.path.join(case, "grad_depth.npy"), g_depth)
    cmd = [cli, "render", case, out, "--width", str(W), "--height", str(H), "--threads", "2",
           "--tile-size", str(tile), "--background", ",".join(repr(float(b)) for b in bg)]
    if use_float:
        cmd.append("--float")
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        print(f"{name}: smg_cli failed: {res.stderr.strip()}")
        return False
    summary = json.loads(res.stdout)

    t = {k: torch.tensor(v, requires_grad=k in ("means", "quats", "scales", "opacities", "colors"))
         for k, v in arrays.items()}
    image, acc, depth, radius, stats = render(t["means"], t["quats"], t["scales"], t["opacities"],
                                       t["colors"], t["viewmat"], t["K"], W, H, torch.tensor(bg),
                                       sh_degree, tile=tile)
    loss = (image * torch.tensor(g_img)).sum() + (acc * torch.tensor(g_alpha)).sum() + \
           (depth * torch.tensor(g_depth)).sum()
    loss.backward()

    def load(n):
        return np.load(os.path.join(out, n + ".npy")).astype(np.float64)

    ok = True
    tol_img = 2e-5 if use_float else 1e-10
    tol_grad = 5e-3 if use_float else 1e-8
    report = [f"{name} (G={G}, {W}x{H}, C={C}, sh={sh_degree}, tile={tile}, "
              f"{'float' if use_float else 'double'}, visible={summary['visible']}, "
              f"terminated pixels={stats['terminated']}, clamped pairs={stats['clamped']})"]
    rad_ref = radius.numpy().astype(np.int64)
    rad = np.load(os.path.join(out, "radii.npy")).astype(np.int64)
    same_radii = int((rad == rad_ref).sum())
    report.append(f"radii equal {same_radii}/{G}")
    ok &= same_radii == G or use_float
    for n, ref in (("image", image), ("alpha", acc), ("depth", depth)):
        err = float(np.abs(load(n) - ref.detach().numpy()).max())
        report.append(f"{n} max|diff| {err:.2e}")
        ok &= err <= tol_img * (50 if n == "depth" else 1)
    for n, ref in (("means", t["means"]), ("quats", t["quats"]), ("scales", t["scales"]),
                   ("opacities", t["opacities"]), ("colors", t["colors"])):
        g = ref.grad.numpy()
        err = float(np.linalg.norm(load("grad_" + n) - g) / max(np.linalg.norm(g), 1e-12))
        report.append(f"grad_{n} rel {err:.2e}")
        ok &= err <= tol_grad
    # right-tangent gradient = J(q̂)ᵀ (dL/dq̂), J = ½ L(q̂)[:, 1:], dL/dq̂ = |q| dL/dq (tangential)
    q = arrays["quats"]
    qn = q / np.linalg.norm(q, axis=1, keepdims=True)
    gq = t["quats"].grad.numpy() * np.linalg.norm(q, axis=1, keepdims=True)
    w_, x_, y_, z_ = qn.T
    Lr = np.stack([np.stack([-x_, -y_, -z_], 1), np.stack([w_, -z_, y_], 1),
                   np.stack([z_, w_, -x_], 1), np.stack([-y_, x_, w_], 1)], 1)  # [G, 4, 3]
    tan_ref = 0.5 * np.einsum("gij,gi->gj", Lr, gq)
    err = float(np.linalg.norm(load("grad_quats_tangent") - tan_ref) / max(np.linalg.norm(tan_ref), 1e-12))
    report.append(f"grad_quats_tangent rel {err:.2e}")
    ok &= err <= tol_grad
    print(("ok   " if ok else "FAIL ") + "; ".join(report))
    return ok


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", required=True)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--seed", type=int, default=2024)
    args = ap.parse_args()
    workdir = args.workdir or tempfile.mkdtemp(prefix="smg_gsplat_ref_")
    rng = np.random.default_rng(args.seed)
    cases = [("rgb", 300, 64, 48, 3, -1, False, 16),
             ("rgb_tile8", 300, 61, 43, 3, -1, False, 8),
             ("sh3", 150, 48, 40, 3, 3, False, 16),
             ("sh1_c2", 150, 40, 33, 2, 1, False, 32),
             ("gray", 200, 50, 30, 1, -1, False, 16),
             ("rgb_float", 300, 64, 48, 3, -1, True, 16),
             ("sh3_float", 150, 48, 40, 3, 3, True, 16)]
    ok = True
    for c in cases:
        ok &= run_case(args.cli, workdir, c[0], rng, *c[1:])
    print("all comparisons within tolerance" if ok else "some comparisons FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
