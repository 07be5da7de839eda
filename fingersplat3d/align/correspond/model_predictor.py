"""Predict where view b sees view a's pixels through the current 3D model (poses, focal, depth maps).

After a global alignment, a pixel of a lifts to the surface through a's depth map and projects
into b. It counts as seen by b when it lands on b's surface at b's own depth there (within
``occlusion`` of b's median depth): points on the far side of the finger are hidden. Pure numpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...sampling import sample_bilinear
from ...scene import Camera

__all__ = ["ModelPredictor"]

OCCLUSION = 0.01
"""A projected point deeper than b's surface there by more than this share of b's median depth is hidden."""


@dataclass(frozen=True, eq=False)
class ModelPredictor:
    """Pixels of view a to view b through two posed cameras and a's and b's depth maps."""

    camera_a: Camera
    camera_b: Camera
    depth_a: np.ndarray  # [Ha, Wa] NaN off the surface
    depth_b: np.ndarray  # [Hb, Wb]
    tolerance: float
    """Depth difference (b's units) beyond which a projected point is hidden."""

    @classmethod
    def from_alignment(cls, alignment, a: int, b: int) -> "ModelPredictor":
        """The predictor between views ``a`` and ``b`` of a :class:`~fingersplat3d.align.global_opt.GlobalAlignment`."""
        depths, poses = alignment.depths, alignment.world_to_cam
        cameras = [Camera.from_focal(alignment.focals[v], depths[v].shape[1], depths[v].shape[0], poses[v]) for v in (a, b)]
        finite = depths[b][np.isfinite(depths[b])]
        return cls(cameras[0], cameras[1], depths[a], depths[b], OCCLUSION * (float(np.median(finite)) if finite.size else 1.0))

    def __call__(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        uv_b, depth = self.camera_b.project(self.camera_a.unproject(uv, sample_bilinear(self.depth_a, uv)))
        surface = sample_bilinear(self.depth_b, uv_b)
        with np.errstate(invalid="ignore"):
            seen = np.isfinite(uv_b).all(1) & (np.abs(surface - depth) < self.tolerance)
        return uv_b, seen
