"""pytorch3d's rotation conversions (pytorch3d/transforms/rotation_conversions.py:
quaternion_to_matrix, matrix_to_quaternion with standardize_quaternion, quaternion_to_axis_angle),
written here as MoSca calls them (pytorch3d is not a Debian package), with MoSca's angles built on
them; shared by the tests that compare smg with MoSca's losses (test_angle.py, test_compat.py)."""
import torch
import torch.nn.functional as F


def quaternion_to_matrix(q):
    r, i, j, k = torch.unbind(q, -1)
    two_s = 2.0 / (q * q).sum(-1)
    o = torch.stack((1 - two_s * (j * j + k * k), two_s * (i * j - k * r), two_s * (i * k + j * r),
                     two_s * (i * j + k * r), 1 - two_s * (i * i + k * k), two_s * (j * k - i * r),
                     two_s * (i * k - j * r), two_s * (j * k + i * r), 1 - two_s * (i * i + j * j)), -1)
    return o.reshape(q.shape[:-1] + (3, 3))


def _sqrt_positive_part(x):
    ret = torch.zeros_like(x)
    positive = x > 0
    ret[positive] = torch.sqrt(x[positive])
    return ret


def matrix_to_quaternion(m):
    batch = m.shape[:-2]
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = torch.unbind(m.reshape(batch + (9,)), dim=-1)
    q_abs = _sqrt_positive_part(torch.stack([1.0 + m00 + m11 + m22, 1.0 + m00 - m11 - m22,
                                             1.0 - m00 + m11 - m22, 1.0 - m00 - m11 + m22], dim=-1))
    by_rijk = torch.stack([
        torch.stack([q_abs[..., 0] ** 2, m21 - m12, m02 - m20, m10 - m01], dim=-1),
        torch.stack([m21 - m12, q_abs[..., 1] ** 2, m10 + m01, m02 + m20], dim=-1),
        torch.stack([m02 - m20, m10 + m01, q_abs[..., 2] ** 2, m12 + m21], dim=-1),
        torch.stack([m10 - m01, m20 + m02, m21 + m12, q_abs[..., 3] ** 2], dim=-1)], dim=-2)
    flr = torch.tensor(0.1).to(dtype=q_abs.dtype, device=q_abs.device)
    candidates = by_rijk / (2.0 * q_abs[..., None].max(flr))
    out = candidates[F.one_hot(q_abs.argmax(dim=-1), num_classes=4) > 0.5, :].reshape(batch + (4,))
    return torch.where(out[..., 0:1] < 0, -out, out)  # standardize_quaternion


def quaternion_to_axis_angle(q):
    norms = torch.norm(q[..., 1:], p=2, dim=-1, keepdim=True)
    half = torch.atan2(norms, q[..., :1])
    angles = 2 * half
    eps = 1e-6
    small = angles.abs() < eps
    ratio = torch.empty_like(angles)
    ratio[~small] = torch.sin(half[~small]) / angles[~small]
    ratio[small] = 0.5 - (angles[small] * angles[small]) / 48
    return q[..., 1:] / ratio


def mosca_angles(q):
    """θ [T−1, N]: ‖axis_angle(R^{t+1} R^{tT})‖, MoSca's ang_vel per node and frame."""
    R = quaternion_to_matrix(F.normalize(q, dim=-1))
    rel_R = torch.einsum("tnij,tnkj->tnik", R[1:], R[:-1])
    return quaternion_to_axis_angle(matrix_to_quaternion(rel_R)).norm(dim=-1)


