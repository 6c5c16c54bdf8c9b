"""Pure-PyTorch autograd implementations of smg's energies, written from docs/math/energy.md
(E1)-(E14) only (independent of the C++ kernels). Used by tests/torch to check values and
gradients of smg_torch, and by bench/torch/bench_torch.py as the "PyTorch autograd" baseline.

Graph: indices [N, K] (-1 padded), weights [N, K] (0 on padding). Quaternions (w, x, y, z),
raw (normalised here, so autograd gives the raw-coordinate gradient).
"""
from __future__ import annotations

import torch


def _graph(indices, weights, dtype):
    valid = indices >= 0
    j = indices.clamp(min=0).long()
    mask = valid.to(dtype)
    return j, weights.to(dtype) * mask, mask


def velocities(x):
    """(E1) u^t = x^{t+1} - x^t, the last frame repeats the previous pair; 0 when T = 1."""
    if x.shape[0] == 1:
        return torch.zeros_like(x)
    d = x[1:] - x[:-1]
    return torch.cat([d, d[-1:]], 0)


def safe_norm(v):
    """‖v‖ over the last axis with derivative 0 at v = 0 (the pinned convention)."""
    s = (v * v).sum(-1)
    pos = s > 0
    return torch.where(pos, torch.sqrt(torch.where(pos, s, torch.ones_like(s))), torch.zeros_like(s))


def rotation_matrices(q):
    """R(q / |q|) for raw quaternions q [..., 4] (w, x, y, z)."""
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    rows = [
        torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ]
    return torch.stack(rows, -2)


def node_confidences(x, indices, weights, visibility=None, kappa_m=2.5, kappa_r=2.5, lambda_m=1.0,
                     lambda_r=1.0, eps=1e-4):
    """(E2)-(E6)."""
    x = x.detach()
    T, N = x.shape[:2]
    j, w, mask = _graph(indices, weights, x.dtype)
    W = w.sum(1, keepdim=True)
    wh = torch.where(W > 0, w / torch.where(W > 0, W, torch.ones_like(W)), torch.zeros_like(w))
    u = velocities(x)
    uj = u[:, j]                                               # [T, N, K, 3]
    vbar = (wh[None, :, :, None] * uj).sum(2)                  # (E2)
    rv = (u - vbar).norm(dim=-1)
    sv = (wh[None] * (uj - vbar[:, :, None]).norm(dim=-1)).sum(2)
    a = rv / (kappa_m * (sv + eps))                            # (E3)
    ell = (x[:, j] - x[:, :, None]).norm(dim=-1)               # [T, N, K]
    if T == 1:
        eij = torch.zeros_like(ell)
    else:
        plus = torch.cat([ell[1:], ell[-1:]], 0)
        minus = torch.cat([ell[:-1], ell[-2:-1]], 0)
        eij = (plus - minus).abs()                             # (E4)
    ei = (wh[None] * eij).sum(2)
    ebar = (wh[None] * ei[:, j]).sum(2)
    rl = (ei - ebar).abs()
    sl = (wh[None] * (ei[:, j] - ebar[:, :, None]).abs()).sum(2)
    b = rl / (kappa_r * (sl + eps))                            # (E5)
    c = torch.exp(-lambda_m * a * a - lambda_r * b * b)        # (E6)
    if visibility is not None:
        c = c * visibility.to(c.dtype)
    return c


def carap(x, q, indices, weights, confidence=None, alpha=0.6, lambda_c=1.0, lambda_l=1.0,
          gaps=(1, 2, 4), gap_weights=None, normalize=False):
    """(E7)-(E9); autograd gives (E10) for positions and raw quaternions."""
    T, N = x.shape[:2]
    j, w, mask = _graph(indices, weights, x.dtype)
    R = rotation_matrices(q)                                   # [T, N, 3, 3]
    e = x[:, j] - x[:, :, None]                                # [T, N, K, 3]
    d = torch.einsum("tnba,tnkb->tnka", R, e)                  # (E8) d = Rᵀ e
    L = safe_norm(e)                                           # ‖d‖ = ‖e‖
    c = torch.ones(T, N, dtype=x.dtype, device=x.device) if confidence is None else confidence.detach()
    wt = w[None] * (alpha + (1 - alpha) * c[:, j])             # (E7) at the earlier frame
    gw = [1.0] * len(gaps) if gap_weights is None else list(gap_weights)
    E = x.new_zeros(())
    for delta, g in zip(gaps, gw):
        if delta >= T:
            continue
        dd = d[delta:] - d[:-delta]
        dl = L[delta:] - L[:-delta]
        E = E + g * (wt[:-delta] * (lambda_c * (dd * dd).sum(-1) + lambda_l * dl * dl)).sum()
    if normalize:
        count = sum(max(0, T - d) for d in gaps) * int(mask.sum().item())
        E = E / count if count > 0 else E * 0
    return E


def arap(x, q, indices, weights, lambda_c=1.0, lambda_l=1.0, gaps=(1, 2, 4), gap_weights=None,
         normalize=False):
    """Plain ARAP: (E9) with c = 1, alpha = 1."""
    return carap(x, q, indices, weights, None, 1.0, lambda_c, lambda_l, gaps, gap_weights, normalize)


def _cross(a, b):
    return torch.cross(a, b, dim=-1)


def lrm(x, indices, weights, confidence=None, alpha=0.6, huber_delta=0.01, detach_omega=False,
        normalize=False):
    """(E11)-(E14); autograd gives (E15)-(E16), including omega's dependence on the positions."""
    T, N = x.shape[:2]
    j, w, mask = _graph(indices, weights, x.dtype)
    c = torch.ones(T, N, dtype=x.dtype, device=x.device) if confidence is None else confidence.detach()
    wt = w[None] * (alpha + (1 - alpha) * c[:, j])             # [T, N, K]
    S = wt.sum(2, keepdim=True)
    wh = torch.where(S > 0, wt / torch.where(S > 0, S, torch.ones_like(S)), torch.zeros_like(wt))
    u = velocities(x)
    xj, uj = x[:, j], u[:, j]                                  # [T, N, K, 3]
    g = (wh[..., None] * xj).sum(2)
    vbar = (wh[..., None] * uj).sum(2)
    xt = xj - g[:, :, None]                                    # (E11)
    ut = uj - vbar[:, :, None]
    eye = torch.eye(3, dtype=x.dtype, device=x.device)
    n2 = (xt * xt).sum(-1)
    A = (wh[..., None, None] * (n2[..., None, None] * eye - xt[..., :, None] * xt[..., None, :])).sum(2)
    b = (wh[..., None] * _cross(xt, ut)).sum(2)                # (E12)
    tr = A.diagonal(dim1=-2, dim2=-1).sum(-1)
    c_mu = 1e-10 if x.dtype == torch.float64 else 1e-5
    M = A + (c_mu * tr)[..., None, None] * eye
    has = tr > 0
    Ms = torch.where(has[..., None, None], M, eye.expand_as(M))
    omega = torch.linalg.solve(Ms, b[..., None])[..., 0]
    omega = torch.where(has[..., None], omega, torch.zeros_like(omega))
    if detach_omega:
        omega = omega.detach()
    r = ut - _cross(omega[:, :, None].expand_as(xt), xt)       # (E13)
    r2 = (r * r).sum(-1)
    quad = r2 <= huber_delta * huber_delta
    rn = torch.sqrt(torch.where(quad, torch.ones_like(r2), r2))
    rho = torch.where(quad, 0.5 * r2, huber_delta * (rn - 0.5 * huber_delta))
    E = (wh * rho).sum()                                       # (E14)
    if normalize:
        count = T * int(mask.sum().item())
        E = E / count if count > 0 else E * 0
    return E


# ---- skinning: docs/math/skin.md (S1)-(S13) -------------------------------------------------------

def qmul(a, b):
    """Hamilton product of [..., 4] (w, x, y, z)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([aw * bw - ax * bx - ay * by - az * bz,
                        aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx,
                        aw * bz + ax * by - ay * bx + az * bw], -1)


def qconj(q):
    return torch.cat([q[..., :1], -q[..., 1:]], -1)


def pure(v):
    return torch.cat([torch.zeros_like(v[..., :1]), v], -1)


def skin_drivers(indices, anchor):
    """(S1) [P, K+1]: the anchor, then its valid neighbours in graph order, -1 padded."""
    return torch.cat([anchor.long()[:, None], indices.long()[anchor.long()]], 1)


def skinning_weights(node_positions, drivers, t_ref, points, sigma):
    """(S2)-(S3), constants (no gradient)."""
    x = node_positions.detach()
    valid = drivers >= 0
    d = drivers.clamp(min=0)
    xk = x[t_ref.long()[:, None], d]                           # [P, D, 3]
    sg = sigma.detach()[d]
    l = -((points.detach()[:, None] - xk) ** 2).sum(-1) / (2 * sg * sg)
    l = torch.where(valid, l, torch.full_like(l, -float("inf")))
    return torch.softmax(l, 1) * valid


def dqb(node_positions, node_quats, indices, points, point_quats, anchor, t_ref, t_query, sigma,
        lbs=False):
    """(S6)-(S13) with autograd; returns ([Q, P, 3], [Q, P, 4])."""
    drivers = skin_drivers(indices, anchor)
    w = skinning_weights(node_positions, drivers, t_ref, points, sigma)  # [P, D]
    d = drivers.clamp(min=0)
    q = node_quats / node_quats.norm(dim=-1, keepdim=True)
    qp = (torch.tensor([1.0, 0, 0, 0], dtype=points.dtype, device=points.device).expand(points.shape[0], 4)
          if point_quats is None else point_quats / point_quats.norm(dim=-1, keepdim=True))
    tr = t_ref.long()[:, None]
    x_ref, q_ref = node_positions[tr, d], q[tr, d]                        # [P, D, ...]
    outs_x, outs_q = [], []
    for t in t_query.long().tolist():
        x_t, q_t = node_positions[t][d], q[t][d]
        r = qmul(q_t, qconj(q_ref))                                      # (S6)
        s = 0.5 * (qmul(pure(x_t), r) - qmul(r, pure(x_ref)))            # (S7)
        # (S8) signs relative to the pivot (largest weight, first on ties) in canonical sign
        with torch.no_grad():
            piv = w.argmax(1)
            rp = r[torch.arange(r.shape[0], device=r.device), piv]
            sign_p = torch.where(rp[:, 0] != 0, rp[:, 0].sign(), torch.zeros_like(rp[:, 0]))
            for c in (1, 2, 3):
                sign_p = torch.where(sign_p == 0, rp[:, c].sign(), sign_p)
            rt = rp * sign_p[:, None]
            sk = torch.where((r * rt[:, None]).sum(-1) >= 0, 1.0, -1.0).to(r.dtype)
        a = (w * sk)[..., None]
        br, bs = (a * r).sum(1), (a * s).sum(1)                         # (S9)
        n = br.norm(dim=-1, keepdim=True)
        c0, ce = br / n, bs / n                                          # (S10)
        R0 = rotation_matrices(c0)
        if lbs:                                                          # (S13)
            Rk = rotation_matrices(r)
            px = (w[..., None] * (torch.einsum("pdab,pdb->pda", Rk, points[:, None] - x_ref) + x_t)).sum(1)
        else:                                                            # (S11)
            px = torch.einsum("pab,pb->pa", R0, points) + 2 * qmul(ce, qconj(c0))[..., 1:]
        outs_x.append(px)
        outs_q.append(qmul(c0, qp))                                      # (S12)
    return torch.stack(outs_x), torch.stack(outs_q)
