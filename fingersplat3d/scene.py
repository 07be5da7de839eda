"""The data model: ``Camera``, ``View`` and ``Capture``.

Conventions (written once, here, and followed everywhere):

* Cameras are OpenCV pinholes: x right, y down, z forward. ``K`` is 3x3 and pixel ``(u, v)`` has
  its centre at integer coordinates, so the image spans ``[-0.5, W-0.5] x [-0.5, H-0.5]``.
* Poses are ``world_to_cam`` 4x4 rigid transforms: ``x_cam = R @ x_world + t``.
* Depth is camera-frame z (not ray length).
* Images are float32 in [0, 1], ``H x W`` for grayscale (one channel all the way through) or
  ``H x W x 3`` for RGB. Masks are ``H x W`` bool.

This module is pure numpy; Open3D point clouds are built from it in :mod:`fingersplat3d.geometry`.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["Camera", "View", "Capture", "depth_normals", "look_at", "scaled_size"]


def _as_matrix(value: Any, shape: tuple[int, int], name: str) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or Inf")
    return array


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera: intrinsics ``K`` (3x3), pose ``world_to_cam`` (4x4), image size."""

    K: np.ndarray  # [3, 3]
    world_to_cam: np.ndarray  # [4, 4]
    width: int
    height: int

    def __post_init__(self) -> None:
        K = _as_matrix(self.K, (3, 3), "K")
        pose = _as_matrix(self.world_to_cam, (4, 4), "world_to_cam")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError("focal lengths in K must be positive")
        if int(self.width) < 1 or int(self.height) < 1:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        rotation = pose[:3, :3]
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) or np.linalg.det(rotation) < 0:
            raise ValueError("world_to_cam must be a rigid transform (orthonormal, det +1)")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "world_to_cam", pose)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @classmethod
    def from_focal(cls, focal: float, width: int, height: int,
                   world_to_cam: np.ndarray | None = None) -> "Camera":
        """A camera with square pixels and the principal point at the image centre."""
        K = np.array([[focal, 0.0, (width - 1) / 2.0], [0.0, focal, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
        return cls(K, np.eye(4) if world_to_cam is None else world_to_cam, width, height)

    @property
    def rotation(self) -> np.ndarray:
        return self.world_to_cam[:3, :3]

    @property
    def translation(self) -> np.ndarray:
        return self.world_to_cam[:3, 3]

    @property
    def cam_to_world(self) -> np.ndarray:
        inverse = np.eye(4)
        inverse[:3, :3] = self.rotation.T
        inverse[:3, 3] = -self.rotation.T @ self.translation
        return inverse

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, ``[3]``."""
        return -self.rotation.T @ self.translation

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return self.width, self.height

    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        """``[..., 3]`` world points to camera-frame points."""
        return np.asarray(points, np.float64) @ self.rotation.T + self.translation

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points ``[..., 3]`` to pixels ``[..., 2]`` and depth ``[...]``.

        Points at or behind the camera plane get NaN pixels (their depth is returned as is).
        """
        cam = self.world_to_camera(points)
        depth = cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = cam[..., :2] / np.where(depth > 0, depth, np.nan)[..., None]
        uv = xy @ self.K[:2, :2].T + self.K[:2, 2]
        return uv, depth

    def unproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Pixels ``[..., 2]`` with camera-frame depth ``[...]`` to world points ``[..., 3]``."""
        return self.cam_to_world_points(self.pixel_directions(uv) * np.asarray(depth, np.float64)[..., None])

    def pixel_directions(self, uv: np.ndarray) -> np.ndarray:
        """Camera-frame ray directions ``[..., 3]`` with z = 1 (so ray length t equals depth)."""
        uv = np.asarray(uv, np.float64)
        K_inv = np.linalg.inv(self.K)
        homogeneous = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)
        return homogeneous @ K_inv.T

    def cam_to_world_points(self, points_cam: np.ndarray) -> np.ndarray:
        return (np.asarray(points_cam, np.float64) - self.translation) @ self.rotation

    def pixel_grid(self) -> np.ndarray:
        """Integer pixel centres ``[H, W, 2]`` as (u, v)."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        return np.stack([u, v], axis=-1)

    def depth_to_points(self, depth: np.ndarray) -> np.ndarray:
        """A depth map ``[H, W]`` to world points ``[H, W, 3]`` (NaN where depth is NaN)."""
        depth = np.asarray(depth)
        if depth.shape != (self.height, self.width):
            raise ValueError(f"depth map is {depth.shape[1]}x{depth.shape[0]}, camera is {self.width}x{self.height}")
        return self.unproject(self.pixel_grid(), depth)

    def scaled(self, factor: float) -> "Camera":
        """The same camera for an image resized by ``factor`` (pixel centres stay consistent)."""
        return self.resized(scaled_size(self.size, factor))

    def resized(self, size: tuple[int, int]) -> "Camera":
        """The same camera (same pose) for its image resampled to ``size`` = (width, height): pixel centres at
        integer coordinates, so a pixel ``x`` of the new grid is ``(x + 0.5) * W / w - 0.5`` of the old one."""
        sx, sy = size[0] / self.width, size[1] / self.height
        onto = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
        return Camera(onto @ self.K, self.world_to_cam, int(size[0]), int(size[1]))


def scaled_size(size: tuple[int, int], factor: float) -> tuple[int, int]:
    """An image's ``(width, height)`` scaled by ``factor`` and rounded (never below one pixel)."""
    return max(1, round(size[0] * factor)), max(1, round(size[1] * factor))


def depth_normals(camera: Camera, depth: np.ndarray) -> np.ndarray:
    """``[H, W, 3]`` unit world-frame normals of a depth map (camera-frame z per pixel, NaN where none), each
    facing its camera. With the surface ``P = z (x, y, 1)``, ``x = (u - cx) / fx``, ``y = (v - cy) / fy`` (no skew),
    ``dP/du x dP/dv`` is parallel to ``(fx z_u, fy z_v, -(fx z_u x + fy z_v y + z))``, which faces the camera; ``z_u``
    and ``z_v`` are central differences on the map's grid. A pixel whose neighbours have no depth (the map's rim)
    takes the normal of the nearest pixel that has one; NaN where the map has no depth, and everywhere when no
    pixel has a normal.

    The map's own grid gives each point its neighbours, which an unorganised cloud has to search for (Open3D's
    ``estimate_normals``: ~1 s for a real capture's fused cloud).
    """
    from scipy.ndimage import distance_transform_edt

    depth = np.asarray(depth, np.float64)
    normals = np.full(depth.shape + (3,), np.nan)
    rows, cols = np.nonzero(np.isfinite(depth))
    if len(rows) == 0 or min(depth.shape) < 2:
        return normals
    top, bottom = max(rows.min() - 1, 0), min(rows.max() + 2, depth.shape[0])
    left, right = max(cols.min() - 1, 0), min(cols.max() + 2, depth.shape[1])
    z = depth[top:bottom, left:right]
    if min(z.shape) < 2:
        return normals
    z_v, z_u = np.gradient(z)
    (fx, _, cx), (_, fy, cy) = camera.K[0], camera.K[1]
    x = (np.arange(left, right) - cx) / fx
    y = (np.arange(top, bottom)[:, None] - cy) / fy
    along_u, along_v = fx * z_u, fy * z_v
    local = np.stack([along_u, along_v, -(along_u * x + along_v * y + z)], -1)
    with np.errstate(invalid="ignore", divide="ignore"):
        local /= np.linalg.norm(local, axis=-1, keepdims=True)
    good = np.isfinite(local).all(-1)
    if not good.any():
        return normals
    if (np.isfinite(z) & ~good).any():
        nearest = distance_transform_edt(~good, return_distances=False, return_indices=True)
        local = local[nearest[0], nearest[1]]
    local[~np.isfinite(z)] = np.nan
    normals[top:bottom, left:right] = local @ camera.rotation  # camera frame -> world: R^T n, row vectors
    return normals


def look_at(eye: Sequence[float], target: Sequence[float], up: Sequence[float]) -> np.ndarray:
    """``world_to_cam`` of a camera at ``eye`` looking at ``target``; ``up`` maps to image -y."""
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("look_at: up is parallel to the viewing direction")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack([right, down, forward])
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = -rotation @ eye
    return pose


@dataclass(frozen=True, eq=False)
class View:
    """One photo: a name, the image, and optionally its mask, camera and ground-truth depth."""

    name: str
    image: np.ndarray  # [H, W] or [H, W, 3] float32 in [0, 1]
    mask: np.ndarray | None = None  # [H, W] bool
    camera: Camera | None = None
    depth: np.ndarray | None = None  # [H, W] float32 camera-frame z, NaN = none

    def __post_init__(self) -> None:
        image = np.asarray(self.image)
        if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3)):
            raise ValueError(f"view {self.name!r}: image must be HxW or HxWx3, got shape {image.shape}")
        if image.ndim == 3 and image.shape[2] == 1:
            image = image[..., 0]
        object.__setattr__(self, "image", image.astype(np.float32, copy=False))
        height, width = image.shape[:2]
        if self.mask is not None:
            mask = np.asarray(self.mask)
            if mask.shape != (height, width):
                raise ValueError(f"view {self.name!r}: mask is {mask.shape[1]}x{mask.shape[0]}, image is {width}x{height}")
            object.__setattr__(self, "mask", mask.astype(bool, copy=False))
        if self.depth is not None:
            depth = np.asarray(self.depth, np.float32)
            if depth.shape != (height, width):
                raise ValueError(f"view {self.name!r}: depth is {depth.shape[1]}x{depth.shape[0]}, image is {width}x{height}")
            object.__setattr__(self, "depth", depth)
        if self.camera is not None and self.camera.size != (width, height):
            raise ValueError(f"view {self.name!r}: camera is {self.camera.width}x{self.camera.height}, image is {width}x{height}")

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    @property
    def height(self) -> int:
        return int(self.image.shape[0])

    @property
    def channels(self) -> int:
        return 1 if self.image.ndim == 2 else 3

    def with_(self, **changes: Any) -> "View":
        """A copy with some fields replaced (validated again)."""
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class Capture:
    """Several views of one finger plus free-form metadata (rig, seed, units, source...)."""

    views: tuple[View, ...]
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        views = tuple(self.views)
        names = [view.name for view in views]
        if len(set(names)) != len(names):
            raise ValueError(f"view names must be unique, got {names}")
        object.__setattr__(self, "views", views)
        object.__setattr__(self, "metadata", dict(self.metadata))

    def __len__(self) -> int:
        return len(self.views)

    def __getitem__(self, name: str) -> View:
        for view in self.views:
            if view.name == name:
                return view
        raise KeyError(name)

    @property
    def names(self) -> list[str]:
        return [view.name for view in self.views]

    @property
    def has_cameras(self) -> bool:
        return all(view.camera is not None for view in self.views)
