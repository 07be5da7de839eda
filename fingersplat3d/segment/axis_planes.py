"""The finger's axis in 3D where the planes its silhouettes span meet.

A photo shows the finger's axis as a line (:func:`~fingersplat3d.segment.silhouette.finger_axis`); that line and the
camera's centre span a plane holding the axis in 3D. Views turned about the finger give planes that meet in it: the
axis direction is the unit vector most nearly in every plane, the right singular vector of the planes' stacked unit
normals with the least singular value. Planes that nearly coincide (views from one place, or turned about the line
of sight) leave it open. Used by the rolled print's frame (:mod:`~fingersplat3d.prints.skin_chart`) and by the
tilt the prior is drawn with (:mod:`~fingersplat3d.align.axis_tilt`). Pure numpy.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..scene import Camera

__all__ = ["axis_plane_normal", "planes_meet"]


def axis_plane_normal(camera: Camera, origin: Sequence[float], direction: Sequence[float]) -> np.ndarray | None:
    """The world unit normal of the plane through ``camera``'s centre and the image line through pixel ``origin``
    along ``direction``; None where the line passes through the camera's own axis point in a degenerate way (a
    zero normal)."""
    origin, direction = np.asarray(origin, np.float64), np.asarray(direction, np.float64)
    rays = camera.pixel_directions(np.array([origin, origin + 50.0 * direction])) @ camera.rotation
    normal = np.cross(rays[0], rays[1])
    length = np.linalg.norm(normal)
    return normal / length if length > 0 and np.isfinite(length) else None


def planes_meet(normals: Sequence[np.ndarray], min_spread: float) -> np.ndarray | None:
    """The unit direction most nearly in every plane of unit ``normals`` (sign arbitrary), or None where they are
    fewer than two or their second singular value is under ``min_spread`` times the first (two planes ``2 atan(s)``
    apart give ``s``)."""
    normals = [np.asarray(n, np.float64) for n in normals if n is not None and np.isfinite(n).all()]
    if len(normals) < 2:
        return None
    _, values, vectors = np.linalg.svd(np.array(normals))
    return vectors[-1] if values[1] > min_spread * values[0] else None
