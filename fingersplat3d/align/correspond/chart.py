"""Cylinder charts: a view's finger pixels in surface coordinates (distance from the tip, angle).

A finger is close to a surface of revolution about its axis. Two cameras turned about that axis
see one skin point at the same distance ``sigma`` from the fingertip and at surface angles
``theta`` that differ by the turn. So each view's ridge texture, resampled on a
``(sigma, theta)`` grid ("unwrapped"), shows the other view's texture shifted by the turn, with the
foreshortening toward the silhouette undone. That is what makes views 45 degrees apart
comparable at all, where keypoint descriptors fail (see :mod:`fingersplat3d.align.chart_shift`).

The chart of a view comes from its silhouette alone (:mod:`fingersplat3d.segment.silhouette`):
the pixel at axis coordinate ``s`` and across coordinate ``t`` has ``sigma = s_tip - s`` and
``theta = asin((t - c(s)) / w(s))`` (orthographic circle of the chord's half-width; 0 faces the
camera). It is only a first guess of the surface: the guided matching after it
(:mod:`fingersplat3d.align.guided`) absorbs its errors.

Pure numpy/OpenCV: no Open3D, no files.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ...segment.silhouette import SilhouetteFrame, silhouette_frame

__all__ = ["CylinderChart", "Unwrapped", "MAX_CHART_ANGLE"]

MAX_CHART_ANGLE = np.radians(75.0)
"""Surface angles beyond this (toward the silhouette) are left out: foreshortened past use."""
_MIN_RELATIVE_WIDTH = 0.3  # stations narrower than this fraction of the median chord (the tip cap's end) are left out


@dataclass(frozen=True, eq=False)
class Unwrapped:
    """A texture resampled on the chart grid: rows are arc length ``r = radius * theta``, columns ``sigma``."""

    image: np.ndarray  # [R, S] float32, 0 where not valid
    valid: np.ndarray  # [R, S] bool
    radius: float
    """Median chord half-width of the view (pixels): arc length per radian."""
    step: float
    """Grid spacing (pixels of arc length and of sigma)."""

    def angle(self, row: np.ndarray | float) -> np.ndarray | float:
        """Surface angle (radians) of a (fractional) row; the middle row is 0."""
        return (np.asarray(row, np.float64) - (self.image.shape[0] - 1) / 2.0) * self.step / self.radius


@dataclass(frozen=True, eq=False)
class CylinderChart:
    """The surface-coordinate chart of one view (see the module docstring)."""

    frame: SilhouetteFrame
    radius: float  # median chord half-width, pixels

    @classmethod
    def from_mask(cls, mask: np.ndarray) -> "CylinderChart":
        return cls.from_frame(silhouette_frame(mask))

    @classmethod
    def from_frame(cls, frame: SilhouetteFrame) -> "CylinderChart":
        """The chart of a silhouette frame (e.g. one of :func:`~fingersplat3d.segment.silhouette.orient_frames`)."""
        return cls(frame, float(np.median(frame.sections.half_width)))

    def surface(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(sigma, theta)`` of pixels ``uv [..., 2]`` (theta clipped to +-90 degrees off the chord)."""
        s, t = self.frame.coordinates(uv)
        width, centre = self.frame.sections.at(s)
        theta = np.arcsin(np.clip((t - centre) / np.maximum(width, 1e-6), -1.0, 1.0))
        return self.frame.s_tip - s, theta

    def pixels(self, sigma: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Pixels ``[..., 2]`` of surface coordinates ``sigma``, ``theta``."""
        s = self.frame.s_tip - np.asarray(sigma, np.float64)
        width, centre = self.frame.sections.at(s)
        return self.frame.pixels(s, centre + width * np.sin(theta))

    def unwrap(self, texture: np.ndarray, mask: np.ndarray, step: float = 1.0,
               max_angle: float = MAX_CHART_ANGLE) -> Unwrapped:
        """``texture`` resampled on a ``(r, sigma)`` grid of ``step`` pixels, from the tip to the far end."""
        length = float(self.frame.s_tip - self.frame.sections.start)
        sigma = np.arange(0.0, length, step)
        half = int(np.floor(np.pi / 2 * self.radius / step))
        rows = np.arange(-half, half + 1) * step
        grid_sigma, grid_r = np.meshgrid(sigma, rows)
        theta = grid_r / self.radius
        uv = self.pixels(grid_sigma, theta).astype(np.float32)
        image = cv2.remap(np.asarray(texture, np.float32), uv[..., 0], uv[..., 1], cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        inside = cv2.remap(np.asarray(mask, np.uint8), uv[..., 0], uv[..., 1], cv2.INTER_NEAREST,
                           borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0
        width, _ = self.frame.sections.at(self.frame.s_tip - grid_sigma)
        valid = inside & (np.abs(theta) < max_angle) & (width > _MIN_RELATIVE_WIDTH * self.radius)
        return Unwrapped(np.where(valid, image, 0.0).astype(np.float32), valid, self.radius, step)
