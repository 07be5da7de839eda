"""Predict where view b sees view a's pixels through the current 3D model (poses, focal, depth maps).

After a global alignment, a pixel of a lifts to the surface through a's depth map and projects
into b. It counts as seen by b when it lands on b's surface at b's own depth there (within
``occlusion`` of the median depth): points on the far side of the finger are hidden. Pure numpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sampling import sample_bilinear

__all__ = ["ModelPredictor"]


@dataclass(frozen=True, eq=False)
class ModelPredictor:
    """Pixels of view a to view b through two posed pinholes and a's and b's depth maps."""

    cam_to_world_a: np.ndarray  # [4, 4]
    cam_to_world_b: np.ndarray  # [4, 4]
    focal_a: float
    focal_b: float
    centre_a: np.ndarray  # [2] principal point of a
    centre_b: np.ndarray  # [2]
    depth_a: np.ndarray  # [Ha, Wa] NaN off the surface
    depth_b: np.ndarray  # [Hb, Wb]
    occlusion: float = 0.01

    @classmethod
    def from_alignment(cls, alignment, a: int, b: int) -> "ModelPredictor":
        """The predictor between views ``a`` and ``b`` of a :class:`~fingersplat3d.align.global_opt.GlobalAlignment`."""
        def centre(depth):
            return np.array([(depth.shape[1] - 1) / 2.0, (depth.shape[0] - 1) / 2.0])

        depths = alignment.depths
        return cls(alignment.cam_to_world[a], alignment.cam_to_world[b], alignment.focals[a], alignment.focals[b],
                   centre(depths[a]), centre(depths[b]), depths[a], depths[b])

    def __call__(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        depth = sample_bilinear(self.depth_a, uv)
        rays = np.concatenate([(uv - self.centre_a) / self.focal_a, np.ones((len(uv), 1))], axis=1)
        world = (depth[:, None] * rays) @ self.cam_to_world_a[:3, :3].T + self.cam_to_world_a[:3, 3]
        camera = (world - self.cam_to_world_b[:3, 3]) @ self.cam_to_world_b[:3, :3]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv_b = camera[:, :2] / np.where(camera[:, 2:] > 0, camera[:, 2:], np.nan) * self.focal_b + self.centre_b
        surface = sample_bilinear(self.depth_b, uv_b)
        finite = self.depth_b[np.isfinite(self.depth_b)]
        tolerance = self.occlusion * (float(np.median(finite)) if finite.size else 1.0)
        with np.errstate(invalid="ignore"):
            seen = np.isfinite(uv_b).all(1) & (np.abs(surface - camera[:, 2]) < tolerance)
        return uv_b, seen
