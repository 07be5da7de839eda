"""The finger's axis in 3D from the registered cameras, and how far it runs off each photo's plane (its tilt in depth).

One silhouette shows the finger's axis as a line in the image, not whether the finger points toward the camera or
away from it: the prior (:mod:`~fingersplat3d.pointmaps.prior`) sweeps its sections along a level axis. A finger
pitched toward a ring of cameras is tilted in depth in every view, and where one view alone sees the skin that level
guess stays: measured on another make's fingers pitched ±12° (3 views ±45°), the skin one view alone sees read 0.43 mm
off against 0.18 mm level (docs/measurements.md).

Registered views fix the tilt. A photo's axis line and its camera's centre span a plane that holds the finger's axis;
two or more views turned about the finger give planes that meet in it: the axis direction is the unit vector most
nearly in every plane (:mod:`~fingersplat3d.segment.axis_planes`, as the rolled print's frame finds it). Its direction in each camera gives that view's depth gradient along the image: depth units per pixel,
where the prior puts the finger at a depth of one focal (about one unit a pixel), so it is the tangent of the tilt.
Only the cameras' rotations, centres and focal enter, and the axes the silhouettes give: neither the relief nor the
depth maps. Planes that nearly coincide (views from one place, or a finger seen end on) leave the direction open: no
tilt then. Pure numpy.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..scene import Camera
from ..segment.axis_planes import axis_plane_normal, planes_meet

__all__ = ["view_tilts", "tilt_deg", "MIN_PLANE_SPREAD", "MAX_TILT_DEG"]

MAX_TILT_DEG = 45.0
"""A view whose axis the planes put further out of its photo's plane is given no tilt (drawn level): a finger is not
photographed pointing that far toward a camera (the CFPose-style shots pitch it up to 15°, the real rig 0-6°), and a
swept-section prior tilted so steeply would stand on a wrong registration."""

MIN_PLANE_SPREAD = math.tan(math.radians(5.0))
"""The planes' second singular value over their first under which they are taken to coincide (two planes 10° apart
give this): their meeting line is then a guess."""


def view_tilts(cam_to_world: Sequence[np.ndarray], focals: Sequence[float], sizes: Sequence[tuple[int, int]],
               axes: Sequence[tuple[np.ndarray, np.ndarray]], aligned: Sequence[bool]) -> list[np.ndarray | None]:
    """Per view, the finger surface's depth gradient along the image ``[d depth / du, d depth / dv]`` (units per pixel
    at the depth of one focal) that the 3D axis of the ``aligned`` views gives (module docstring); None for a view
    not aligned or tilted beyond :data:`MAX_TILT_DEG`, and for all where the axis is open. ``axes``: :func:`~fingersplat3d.segment.silhouette.capture_finger_axes`; ``sizes``: (width, height)."""
    views = [i for i, ok in enumerate(aligned) if ok and math.isfinite(focals[i]) and focals[i] > 0]  # a lost focal: none
    cameras = {i: Camera.from_focal(float(focals[i]), *sizes[i], np.linalg.inv(cam_to_world[i])) for i in views}
    normals = [axis_plane_normal(cameras[i], axes[i][1], axes[i][0]) for i in views]
    direction = planes_meet(normals, MIN_PLANE_SPREAD)
    if direction is None:
        return [None] * len(aligned)
    tilts: list[np.ndarray | None] = [None] * len(aligned)
    for i in views:
        local = np.asarray(cam_to_world[i], np.float64)[:3, :3].T @ direction
        axis = np.asarray(axes[i][0], np.float64)
        along = float(local[:2] @ axis)
        if abs(along) < 1e-6:  # the finger seen end on: no line in the image to tilt along
            continue
        gradient = (local[2] / along) * axis  # depth per pixel stepped along the image axis, as a gradient
        tilts[i] = gradient if tilt_deg(gradient) <= MAX_TILT_DEG else None
    return tilts


def tilt_deg(gradient: np.ndarray | None) -> float | None:
    """The tilt of a view's axis out of the photo's plane, degrees, from its depth gradient (None: none)."""
    return None if gradient is None else float(np.degrees(np.arctan(np.linalg.norm(gradient))))
