"""Evaluation against ground truth: depth errors, pose errors."""
from .depth import DepthErrors, align_scale, align_scale_shift, depth_errors
from .poses import relative_rotation_errors, rotation_angle_deg, translation_direction_errors

__all__ = ["DepthErrors", "align_scale", "align_scale_shift", "depth_errors",
           "relative_rotation_errors", "rotation_angle_deg", "translation_direction_errors"]
