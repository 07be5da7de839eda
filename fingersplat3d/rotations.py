"""Rotations in torch: axis-angle (Rodrigues) and quaternions (wxyz, as in the 3DGS PLY format).

The one home of rotation math for the torch code (global alignment, pose corrections, Gaussians);
numpy code uses :class:`scipy.spatial.transform.Rotation`. Pure math: no Open3D, no files.
Quaternions need not be normalised; a zero quaternion is read as the identity rotation (finite
values and gradients), so a degenerate parameter never poisons a fit. Axis-angle is finite, with
finite gradients, at zero.
"""
from __future__ import annotations

import torch

__all__ = ["axis_angle_to_matrix", "skew", "left_jacobian", "normalize_quaternions", "quaternion_to_matrix",
           "matrix_to_quaternion", "rotation_angle"]

_TINY = 1e-12


def normalize_quaternions(quats: torch.Tensor) -> torch.Tensor:
    """``[..., 4]`` wxyz -> unit wxyz; a (near-)zero quaternion becomes the identity ``(1, 0, 0, 0)``."""
    norm2 = (quats * quats).sum(-1, keepdim=True)
    small = norm2 < _TINY
    identity = torch.zeros_like(quats)
    identity[..., 0] = 1.0
    safe = torch.where(small, identity, quats)
    return safe / torch.sqrt(torch.where(small, torch.ones_like(norm2), norm2))


def quaternion_to_matrix(quats: torch.Tensor) -> torch.Tensor:
    """``[..., 4]`` wxyz (any norm) -> ``[..., 3, 3]`` rotation matrices."""
    w, x, y, z = normalize_quaternions(quats).unbind(-1)
    return torch.stack([
        torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def matrix_to_quaternion(matrices: torch.Tensor) -> torch.Tensor:
    """``[..., 3, 3]`` rotations -> ``[..., 4]`` unit wxyz with ``w >= 0`` (Shepperd's method)."""
    m = matrices
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    candidates = torch.stack([
        torch.stack([1 + trace, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        torch.stack([m[..., 2, 1] - m[..., 1, 2], 1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
                     m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0]], -1),
        torch.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0],
                     1 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2], m[..., 1, 2] + m[..., 2, 1]], -1),
        torch.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1],
                     1 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2]], -1),
    ], -2)  # [..., 4 candidates, 4]; candidate k is 4*q*q_k, best conditioned where its k-th entry is largest
    diagonal = torch.diagonal(candidates, dim1=-2, dim2=-1)
    best = diagonal.argmax(-1, keepdim=True)
    chosen = torch.gather(candidates, -2, best[..., None].expand(*best.shape, 4)).squeeze(-2)
    quats = normalize_quaternions(chosen)
    return torch.where(quats[..., :1] < 0, -quats, quats)


def axis_angle_to_matrix(omega: torch.Tensor) -> torch.Tensor:
    """Batched Rodrigues ``[..., 3] -> [..., 3, 3]``, with finite values and gradients at zero."""
    theta2 = (omega * omega).sum(-1, keepdim=True)[..., None]  # [..., 1, 1]
    small = theta2 < 1e-12
    safe = torch.where(small, torch.ones_like(theta2), theta2)  # keeps sqrt's gradient finite
    theta = torch.sqrt(safe)
    a = torch.where(small, 1.0 - theta2 / 6.0, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24.0, (1.0 - torch.cos(theta)) / safe)
    cross = skew(omega)
    eye = torch.eye(3, dtype=omega.dtype, device=omega.device).expand(cross.shape)
    return eye + a * cross + b * (cross @ cross)


def skew(v: torch.Tensor) -> torch.Tensor:
    """``[..., 3] -> [..., 3, 3]`` with ``skew(v) u = v x u``."""
    x, y, z = v.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack([torch.stack([zero, -z, y], -1), torch.stack([z, zero, -x], -1),
                        torch.stack([-y, x, zero], -1)], -2)


def left_jacobian(omega: torch.Tensor) -> torch.Tensor:
    """``[..., 3] -> [..., 3, 3]``: SO(3)'s left Jacobian, ``Exp(omega + d) ~ Exp(J_l(omega) d) Exp(omega)``:
    ``I + (1 - cos t) / t^2 [w]_x + (t - sin t) / t^3 [w]_x^2`` (series below ``t^2 = 1e-8``, where the closed form
    loses its digits)."""
    theta2 = (omega * omega).sum(-1)[..., None, None]
    small = theta2 < 1e-8
    safe = torch.where(small, torch.ones_like(theta2), theta2)
    theta = torch.sqrt(safe)
    b = torch.where(small, 0.5 - theta2 / 24.0, (1.0 - torch.cos(theta)) / safe)
    c = torch.where(small, 1.0 / 6.0 - theta2 / 120.0, (theta - torch.sin(theta)) / (safe * theta))
    cross = skew(omega)
    eye = torch.eye(3, dtype=omega.dtype, device=omega.device).expand(cross.shape)
    return eye + b * cross + c * (cross @ cross)


def rotation_angle(R_a: torch.Tensor, R_b: torch.Tensor) -> torch.Tensor:
    """Geodesic angle in radians, in [0, pi], between rotations ``R_a`` and ``R_b`` (``[..., 3, 3]``, broadcast).

    The angle of ``R = R_a R_b^T`` is ``atan2(|skew(R)|, trace(R) - 1)`` where ``skew(R)`` is
    ``(R32 - R23, R13 - R31, R21 - R12)`` (= ``2 sin(theta) axis``) and ``trace(R) - 1 = 2 cos(theta)``.
    Unlike ``arccos((trace - 1) / 2)``, which loses half the digits near 0 and pi and needs
    clipping, this is accurate to rounding over the whole range and accepts slightly
    non-orthonormal input. Differentiable away from 0 (the norm's gradient is undefined there).
    """
    R = R_a @ R_b.transpose(-1, -2)
    skew = torch.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    return torch.atan2(torch.linalg.vector_norm(skew, dim=-1), R.diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0)
