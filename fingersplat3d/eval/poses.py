"""Camera pose errors that do not depend on the world frame or its scale.

A reconstruction from uncalibrated photos fixes its world frame and scale arbitrarily, so poses
are compared pair by pair: for views ``i < j`` the relative pose ``T_i T_j^-1`` (``world_to_cam``
4x4, so it maps camera ``j`` coordinates to camera ``i`` coordinates) has rotation
``R_ij = R_i R_j^T`` and translation ``t_ij = t_i - R_ij t_j``. Both are unchanged by a rigid
change of world frame; ``t_ij`` scales with the world, so only its direction is compared.

Pairs are ordered ``(0, 1), (0, 2), ..., (0, N-1), (1, 2), ...`` (see :func:`view_pairs`).
Pure numpy: no Open3D, no files.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

__all__ = ["ROLL_NOTED_DEG", "rotation_angle_deg", "vector_angle_deg", "view_turn_deg", "view_pairs",
           "relative_rotation_errors", "translation_direction_errors", "world_similarity"]


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray | float:
    """Geodesic angle in degrees, in [0, 180], between rotations ``R_a`` and ``R_b`` (``[..., 3, 3]``).

    The formula is :func:`fingersplat3d.rotations.rotation_angle`'s (accurate to rounding over the whole
    range: 1e-8 rad comes back as 1e-8 rad; slightly non-orthonormal input is accepted), in float64.
    A scalar for single matrices, an array for stacks (broadcasting over leading axes).
    """
    import torch

    from ..rotations import rotation_angle

    R_a = np.asarray(R_a, np.float64)
    R_b = np.asarray(R_b, np.float64)
    if R_a.shape[-2:] != (3, 3) or R_b.shape[-2:] != (3, 3):
        raise ValueError(f"rotations must be [..., 3, 3], got {R_a.shape} and {R_b.shape}")
    angle = np.degrees(rotation_angle(torch.from_numpy(R_a), torch.from_numpy(R_b)).numpy())
    return float(angle) if angle.ndim == 0 else angle


def vector_angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray | float:
    """Angle in degrees between vectors ``[..., 3]`` via ``atan2(|a x b|, a . b)``; NaN if either is zero."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    zero = (np.linalg.norm(a, axis=-1) == 0) | (np.linalg.norm(b, axis=-1) == 0)
    angle = np.where(zero, np.nan, np.degrees(np.arctan2(cross, dot)))
    return float(angle) if angle.ndim == 0 else angle


ROLL_NOTED_DEG = 5.0
"""A roll between two cameras about the optical axis (:func:`view_turn_deg`) that the commands name beside the turn:
cameras on one ring, or one camera turning about a finger, roll less."""


def view_turn_deg(R_a: np.ndarray, R_b: np.ndarray) -> tuple[float, float]:
    """How far camera b is turned from camera a (``world_to_cam`` rotations ``[3, 3]``), in degrees: the angle between
    their optical axes (the turn about the finger, what a rig's "cameras 45° apart" means) and the roll about b's
    axis that is left (a photo stored portrait, a phone held turned: -180 to 180, swing-twist about the axis).

    The rotation's own angle mixes the two: a side camera 45° off whose photo is stored portrait turns 97°.
    """
    from scipy.spatial.transform import Rotation

    R_a, R_b = np.asarray(R_a, np.float64), np.asarray(R_b, np.float64)
    turn = vector_angle_deg(R_a[2], R_b[2])
    x, y, z, w = Rotation.from_matrix(R_b @ R_a.T).as_quat()  # camera a's coordinates into b's
    roll = math.degrees(2.0 * math.atan2(z, w))
    return float(turn), float((roll + 180.0) % 360.0 - 180.0)


def view_pairs(count: int) -> np.ndarray:
    """``[P, 2]`` index pairs ``i < j`` for ``count`` views, in the order the error functions use."""
    i, j = np.triu_indices(count, k=1)
    return np.stack([i, j], axis=1)


def _poses(poses: Sequence[np.ndarray] | np.ndarray, name: str) -> np.ndarray:
    stack = np.asarray(poses, np.float64)
    if stack.ndim != 3 or stack.shape[1:] != (4, 4):
        raise ValueError(f"{name} must be a list of 4x4 world_to_cam matrices, got shape {stack.shape}")
    if not np.all(np.isfinite(stack)):
        raise ValueError(f"{name} contains NaN or Inf")
    return stack


def _relative(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Relative rotations ``[P, 3, 3]`` and translations ``[P, 3]`` of every pair ``i < j``."""
    pairs = view_pairs(len(poses))
    R, t = poses[:, :3, :3], poses[:, :3, 3]
    R_i, R_j = R[pairs[:, 0]], R[pairs[:, 1]]
    R_ij = R_i @ np.swapaxes(R_j, -1, -2)
    t_ij = t[pairs[:, 0]] - np.einsum("pab,pb->pa", R_ij, t[pairs[:, 1]])
    return R_ij, t_ij


def _both(pred_world_to_cam, gt_world_to_cam) -> tuple[np.ndarray, np.ndarray]:
    pred = _poses(pred_world_to_cam, "pred_world_to_cam")
    gt = _poses(gt_world_to_cam, "gt_world_to_cam")
    if len(pred) != len(gt):
        raise ValueError(f"{len(pred)} predicted poses but {len(gt)} ground-truth poses")
    return pred, gt


def relative_rotation_errors(pred_world_to_cam: Sequence[np.ndarray] | np.ndarray,
                             gt_world_to_cam: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
    """``[P]`` degrees: for each pair ``i < j`` the angle between predicted and true ``R_i R_j^T``.

    Inputs are ``N`` ``world_to_cam`` 4x4 matrices each (lists or ``[N, 4, 4]``), in the same
    view order. Zero when the prediction equals the truth up to any similarity of the world.
    """
    pred, gt = _both(pred_world_to_cam, gt_world_to_cam)
    if len(pred) < 2:
        return np.zeros(0)
    return np.atleast_1d(rotation_angle_deg(_relative(pred)[0], _relative(gt)[0]))


def translation_direction_errors(pred_world_to_cam: Sequence[np.ndarray] | np.ndarray,
                                 gt_world_to_cam: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
    """``[P]`` degrees: for each pair ``i < j`` the angle between predicted and true ``t_ij`` directions.

    Scale-free (the direction of the baseline seen from camera ``i``). A pair whose cameras
    coincide (zero baseline) in either input has no direction: its entry is NaN.
    """
    pred, gt = _both(pred_world_to_cam, gt_world_to_cam)
    if len(pred) < 2:
        return np.zeros(0)
    baselines = []
    for poses in (pred, gt):
        t_ij = _relative(poses)[1]
        # A baseline at rounding level of the camera distances is a zero baseline, not a direction.
        size = max(1.0, float(np.linalg.norm(poses[:, :3, 3], axis=1).max()))
        t_ij[np.linalg.norm(t_ij, axis=1) <= 1e-9 * size] = 0.0
        baselines.append(t_ij)
    return np.atleast_1d(vector_angle_deg(*baselines))


def world_similarity(pred_world_to_cam: Sequence[np.ndarray] | np.ndarray,
                     gt_world_to_cam: Sequence[np.ndarray] | np.ndarray):
    """The :class:`~fingersplat3d.align.solve.procrustes.Similarity` taking the predicted world onto the true one.

    Its rotation is the chordal mean of ``R_gt_i^T R_pred_i`` over the views; its scale and shift the least-squares
    fit of the camera centres under that rotation (a world is a similarity away from the other: two views or more with
    distinct centres fix it). For scoring what a reconstruction made (a print's points, a surface) in the true frame.
    """
    from scipy.spatial.transform import Rotation

    from ..align.solve.procrustes import Similarity

    pred, gt = _both(pred_world_to_cam, gt_world_to_cam)
    if len(pred) < 2:
        raise ValueError("a world's scale needs two views or more")
    rotation = Rotation.from_matrix(np.swapaxes(gt[:, :3, :3], 1, 2) @ pred[:, :3, :3]).mean().as_matrix()
    centres = [-np.einsum("nba,nb->na", poses[:, :3, :3], poses[:, :3, 3]) for poses in (pred, gt)]
    turned = (centres[0] - centres[0].mean(0)) @ rotation.T
    spread = float((turned ** 2).sum())
    if not spread > 0:
        raise ValueError("the predicted cameras share one centre: the world's scale is undetermined")
    scale = float((turned * (centres[1] - centres[1].mean(0))).sum() / spread)
    return Similarity(scale, rotation, centres[1].mean(0) - scale * rotation @ centres[0].mean(0))
