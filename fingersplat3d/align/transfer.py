"""Carry pixel positions and images from one view to another through the 3D model.

A pixel of view A is lifted onto the finger's surface with A's depth map and A's camera, then
projected into view B. What cannot be carried is marked, not dropped:

* ``off_surface``: A has no depth at that pixel (off the finger, or outside A's image);
* ``outside``: the surface point projects outside B's image (or behind B's camera);
* ``hidden``: B sees something else in front of it (B's depth there is nearer by more than the
  tolerance);
* ``mapped``: carried.

The warp of image A into B's frame is the same relation read the other way: every pixel of B
with depth is lifted with B's depth, projected into A and sampled there (bilinear), and kept only
where A's depth agrees (the point is visible in A). Pure numpy + OpenCV; no files.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..sampling import sample_nearest
from ..scene import Camera

__all__ = ["STATUSES", "MIN_PARALLAX_DEG", "distinct_viewpoints", "transfer_points", "warp_image", "surface_tolerance", "multi_view_backing", "backed_shares",
           "backing_on", "multi_view_support"]

STATUSES = ("mapped", "off_surface", "outside", "hidden")
TOLERANCE_FRACTION = 0.02
"""Depths agree when they differ by less than this fraction of the median depth (a ridge is
~0.5 mm at ~60 mm: 2 % leaves room for the depth maps' own error, not for the far side of a finger)."""


def surface_tolerance(depth: np.ndarray) -> float:
    """The depth agreement tolerance for a view (:data:`TOLERANCE_FRACTION` of its median depth)."""
    finite = depth[np.isfinite(depth)]
    return TOLERANCE_FRACTION * float(np.median(finite)) if finite.size else 0.0


def transfer_points(uv_a: np.ndarray, depth_a: np.ndarray, camera_a: Camera, depth_b: np.ndarray,
                    camera_b: Camera, tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``uv_a`` [N, 2] of view A -> ``(uv_b [N, 2], status [N] str)``; ``uv_b`` is NaN
    where the status is ``off_surface`` or ``outside`` (``hidden`` points keep their projection)."""
    uv_a = np.asarray(uv_a, np.float64).reshape(-1, 2)
    z_a = sample_nearest(depth_a, uv_a)
    status = np.full(len(uv_a), "mapped", dtype=object)
    status[~np.isfinite(z_a)] = "off_surface"
    uv_b = np.full_like(uv_a, np.nan)
    lifted = np.isfinite(z_a)
    if lifted.any():
        points = camera_a.unproject(uv_a[lifted], z_a[lifted])
        projected, z_b = camera_b.project(points)
        h, w = depth_b.shape
        inside = (np.isfinite(projected).all(1) & (projected[:, 0] > -0.5) & (projected[:, 0] < w - 0.5)
                  & (projected[:, 1] > -0.5) & (projected[:, 1] < h - 0.5) & (z_b > 0))
        seen = sample_nearest(depth_b, np.where(inside[:, None], projected, np.nan))
        tol = surface_tolerance(depth_b) if tolerance is None else tolerance
        hidden = inside & np.isfinite(seen) & (seen < z_b - tol)
        index = np.flatnonzero(lifted)
        status[index[~inside]] = "outside"
        status[index[hidden]] = "hidden"
        uv_b[index[inside]] = projected[inside]
    return uv_b, status.astype(str)


def warp_image(image_a: np.ndarray, depth_a: np.ndarray, camera_a: Camera, depth_b: np.ndarray,
               camera_b: Camera, tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Image A seen from B: ``(warped [H_b, W_b, ...] like image_a, valid [H_b, W_b] bool)``, zero
    where B has no depth or A does not see the point."""
    h, w = depth_b.shape
    grid = camera_b.pixel_grid().reshape(-1, 2)
    z_b = depth_b.reshape(-1)
    valid = np.isfinite(z_b)
    map_uv = np.full((h * w, 2), -1.0, np.float32)
    if valid.any():
        uv_a, z_a = camera_a.project(camera_b.unproject(grid[valid], z_b[valid]))
        seen = sample_nearest(depth_a, uv_a)
        tol = surface_tolerance(depth_a) if tolerance is None else tolerance
        visible = np.isfinite(seen) & (np.abs(seen - z_a) <= tol)
        index = np.flatnonzero(valid)
        valid[index[~visible]] = False
        map_uv[index[visible]] = uv_a[visible].astype(np.float32)
    map_uv = map_uv.reshape(h, w, 2)
    warped = cv2.remap(image_a, map_uv[..., 0], map_uv[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                       borderValue=0)
    valid = valid.reshape(h, w)
    warped[~valid] = 0
    return warped, valid


MIN_PARALLAX_DEG = 5.0
"""The least angle between two cameras' rays to a point for the second to back its depth. Two views from one place
(the same photo moved, a burst from a tripod) see the same skin but say nothing of its depth; at 5 degrees, with
0.3 px of matching error, a real capture's depth (60 mm away, focal 1660 px) is pinned to ~0.12 mm, the synthetic
target's order."""


def distinct_viewpoints(world_to_cam, views) -> int:
    """How many of ``views`` see the finger from distinct places: each counts unless its optical axis lies within
    :data:`MIN_PARALLAX_DEG` (the parallax that backs a depth) of a view counted before
    (a turn about the optical axis alone, a portrait-stored photo, is the same place)."""
    cosine = np.cos(np.radians(MIN_PARALLAX_DEG))
    counted: list[np.ndarray] = []
    for v in views:
        axis = np.asarray(world_to_cam[v], np.float64)[2, :3]  # the camera's viewing direction in the world
        axis = axis / np.linalg.norm(axis)
        if all(float(axis @ other) < cosine for other in counted):
            counted.append(axis)
    return len(counted)


def multi_view_backing(depths: list[np.ndarray], cameras: list[Camera], aligned: list[bool], stride: int = 4,
                       min_parallax_deg: float = MIN_PARALLAX_DEG) -> list[np.ndarray | None]:
    """Per view, on every ``stride``-th row and column: ``1`` where its surface (a pixel with depth) is also seen by
    another aligned view (:func:`transfer_points` says ``mapped`` and the other view has depth there) from
    ``min_parallax_deg`` or more away (the angle between the two cameras' rays to the point), ``0`` where only this
    view sees it (its shape there is the pointmap's guess, not the photos'), ``-1`` where it has no surface. int8
    ``[ceil(H / stride), ceil(W / stride)]``; None for a view that is not aligned."""
    maps: list[np.ndarray | None] = []
    least = np.cos(np.radians(min_parallax_deg))
    for a, (depth_a, camera_a) in enumerate(zip(depths, cameras)):
        if not aligned[a]:
            maps.append(None)
            continue
        sampled = depth_a[::stride, ::stride]
        rows, cols = np.nonzero(np.isfinite(sampled))
        uv = np.stack([cols, rows], 1).astype(np.float64) * stride
        points = camera_a.unproject(uv, depth_a[rows * stride, cols * stride])
        ray_a = points - camera_a.center
        ray_a /= np.maximum(np.linalg.norm(ray_a, axis=1, keepdims=True), 1e-300)
        seen = np.zeros(len(uv), bool)
        for b, (depth_b, camera_b) in enumerate(zip(depths, cameras)):
            if b == a or not aligned[b] or not len(uv):
                continue
            uv_b, status = transfer_points(uv, depth_a, camera_a, depth_b, camera_b)
            mapped = status == "mapped"
            mapped[mapped] = np.isfinite(sample_nearest(depth_b, uv_b[mapped]))
            ray_b = points - camera_b.center
            ray_b /= np.maximum(np.linalg.norm(ray_b, axis=1, keepdims=True), 1e-300)
            seen |= mapped & (np.sum(ray_a * ray_b, axis=1) <= least)
        backing = np.full(sampled.shape, -1, np.int8)
        backing[rows, cols] = seen
        maps.append(backing)
    return maps


def backed_shares(backing: list[np.ndarray | None]) -> list[float | None]:
    """Per view: the share of its surface a second view backs, from :func:`multi_view_backing`'s maps (0 for a view
    with no surface); None for a view that is not aligned."""
    shares: list[float | None] = []
    for view in backing:
        surface = None if view is None else view[view >= 0]
        shares.append(None if view is None else float(surface.mean()) if surface.size else 0.0)
    return shares


def backing_on(backing: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A :func:`multi_view_backing` map (any stride) on a grid of ``shape`` (rows, cols) covering the same image, by
    the nearest of its cells: int8, ``1`` backed by a second view, ``0`` seen by this view alone, ``-1`` no surface."""
    return cv2.resize(np.asarray(backing, np.int8), (int(shape[1]), int(shape[0])), interpolation=cv2.INTER_NEAREST)


def multi_view_support(depths: list[np.ndarray], cameras: list[Camera], aligned: list[bool],
                       stride: int = 4, min_parallax_deg: float = MIN_PARALLAX_DEG) -> list[float | None]:
    """Per view: the share of its surface that a second view backs (:func:`multi_view_backing`,
    :func:`backed_shares`); None for a view that is not aligned."""
    return backed_shares(multi_view_backing(depths, cameras, aligned, stride, min_parallax_deg))
