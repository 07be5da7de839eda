"""Camera pose corrections for joint pose refinement (InstantSplat-style) and test-view alignment.

A correction is a left-multiplied rigid motion of the camera frame: ``world_to_cam' = exp(delta)
@ world_to_cam`` with ``delta = (axis-angle [3], translation [3])``; zero is the identity, so a
correction starts at zero and stays small. Pure torch.
"""
from __future__ import annotations

import torch

from ..rotations import axis_angle_to_matrix

__all__ = ["apply_pose_correction", "correction_matrix"]


def correction_matrix(rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """``[..., 3]`` axis-angle and ``[..., 3]`` translation -> ``[..., 4, 4]`` rigid transform."""
    top = torch.cat([axis_angle_to_matrix(rotation), translation[..., :, None]], dim=-1)
    bottom = torch.zeros(*top.shape[:-2], 1, 4, dtype=top.dtype, device=top.device)
    bottom[..., 0, 3] = 1.0
    return torch.cat([top, bottom], dim=-2)


def apply_pose_correction(world_to_cam: torch.Tensor, rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """``[4, 4]`` pose corrected by ``exp(rotation, translation)`` applied in the camera frame."""
    return correction_matrix(rotation, translation) @ world_to_cam
