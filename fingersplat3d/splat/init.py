"""Initial Gaussians from a fused Open3D point cloud (the Open3D adapter of :mod:`fingersplat3d.splat`).

One Gaussian per point, as 3DGS initialises from SfM points:

* mean = the point;
* scale = ``scale_factor`` x the mean distance to the point's 3 nearest neighbours, found with
  Open3D's vectorised KNN (``open3d.core.nns.NearestNeighborSearch``, ~0.1 s for 100k points on
  the project's 2-core machine; a per-point ``KDTreeFlann`` loop is ~50x slower);
* rotation = identity (isotropic Gaussians), or, with ``flatten``, a frame whose third axis is the
  cloud normal and whose scale along it is ``flatten`` x the in-plane scale: the finger is a
  surface, so flat discs tangent to it start closer to the answer than balls;
* colour = the cloud colours (no colours: mid gray); a grayscale model takes the channel mean;
* opacity = ``logit(opacity)`` (3DGS starts at 0.1).

This module imports Open3D; the rest of :mod:`fingersplat3d.splat` does not.
"""
from __future__ import annotations

import math

import numpy as np
import open3d as o3d
import torch

from ..errors import input_error
from .gaussians import Gaussians, rgb_to_sh
from ..rotations import matrix_to_quaternion

__all__ = ["gaussians_from_cloud", "knn_mean_distance"]

NEIGHBOURS = 3
_NORMAL_NEIGHBOURS = 16  # for clouds without normals when ``flatten`` asks for them


def knn_mean_distance(points: np.ndarray, neighbours: int = NEIGHBOURS) -> np.ndarray:
    """``[N]`` mean distance from each of ``points [N, 3]`` to its ``neighbours`` nearest others.

    Uses Open3D's vectorised KNN. With fewer than ``neighbours + 1`` points, all others are used.
    Duplicate points give distance 0 (the caller floors it).
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    count = len(points)
    if count < 2:
        raise ValueError("nearest-neighbour distances need at least 2 points")
    k = min(neighbours, count - 1) + 1  # the query point finds itself (or a duplicate) first
    tensor = o3d.core.Tensor(points)
    search = o3d.core.nns.NearestNeighborSearch(tensor)
    search.knn_index()
    _, squared = search.knn_search(tensor, k)
    squared = squared.numpy().astype(np.float64)  # [N, k] ascending, column 0 = self (0)
    # The sort puts the point itself first, or a duplicate at the same distance 0: dropping the
    # first column drops exactly one zero either way.
    return np.sqrt(np.maximum(squared[:, 1:], 0.0)).mean(axis=1)


def gaussians_from_cloud(cloud: o3d.geometry.PointCloud, channels: int, *, opacity: float = 0.1,
                         scale_factor: float = 1.0, flatten: float | None = None,
                         device: torch.device | str = "cpu") -> Gaussians:
    """One float32 Gaussian per point of ``cloud`` (points, optional colours and normals).

    ``channels``: 1 (grayscale, the colour channel mean) or 3. ``opacity`` in (0, 1) is stored as
    a logit. ``scale_factor`` multiplies the 3-NN mean distance. ``flatten`` None keeps isotropic
    Gaussians with the identity rotation; a value in (0, 1] aligns each Gaussian's third axis with
    the cloud normal (estimated from 16 neighbours when the cloud has none) and scales that axis
    by ``flatten``.
    """
    if channels not in (1, 3):
        raise ValueError(f"channels must be 1 or 3, got {channels}")
    if not 0.0 < opacity < 1.0:
        raise ValueError(f"opacity must be in (0, 1), got {opacity}")
    if not scale_factor > 0.0:
        raise ValueError(f"scale_factor must be positive, got {scale_factor}")
    if flatten is not None and not 0.0 < flatten <= 1.0:
        raise ValueError(f"flatten must be None or in (0, 1], got {flatten}")
    points = np.asarray(cloud.points, dtype=np.float64)  # [N, 3]
    if len(points) < 2:
        raise input_error(None, f"the point cloud has {len(points)} point(s); initial Gaussians need at least 2")
    if not np.all(np.isfinite(points)):
        raise input_error(None, "the point cloud contains NaN or Inf points")

    distance = knn_mean_distance(points)  # [N]
    positive = distance[distance > 0]
    # Duplicated points would get log(0); floor them at a small fraction of the typical spacing.
    floor = 1e-3 * float(np.median(positive)) if len(positive) else 1e-6 * max(float(np.ptp(points, axis=0).max()), 1.0)
    scale = np.maximum(distance, floor) * scale_factor  # [N]
    scales = np.repeat(scale[:, None], 3, axis=1)  # [N, 3]

    if flatten is None:
        quats = np.zeros((len(points), 4))
        quats[:, 0] = 1.0
    else:
        normals = _normals(cloud)
        rotations = _frames_from_normals(normals)  # [N, 3, 3], third column = normal
        quats = matrix_to_quaternion(torch.from_numpy(rotations)).numpy()
        scales[:, 2] *= flatten

    colours = _colours(cloud, channels)  # [N, C] in [0, 1]
    logit = math.log(opacity / (1.0 - opacity))

    def tensor(values: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(values), dtype=torch.float32, device=device)

    return Gaussians(tensor(points), tensor(quats), tensor(np.log(scales)),
                     torch.full((len(points),), logit, dtype=torch.float32, device=device),
                     rgb_to_sh(tensor(colours)))


def _colours(cloud: o3d.geometry.PointCloud, channels: int) -> np.ndarray:
    count = len(cloud.points)
    if not cloud.has_colors():
        return np.full((count, channels), 0.5)
    colours = np.clip(np.asarray(cloud.colors, dtype=np.float64), 0.0, 1.0)  # [N, 3]
    if not np.all(np.isfinite(colours)):
        raise input_error(None, "the point cloud contains NaN colours")
    return colours.mean(axis=1, keepdims=True) if channels == 1 else colours


def _normals(cloud: o3d.geometry.PointCloud) -> np.ndarray:
    if cloud.has_normals():
        normals = np.asarray(cloud.normals, dtype=np.float64)
    else:
        estimated = o3d.geometry.PointCloud(cloud.points)
        estimated.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(_NORMAL_NEIGHBOURS))
        normals = np.asarray(estimated.normals, dtype=np.float64)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    good = np.isfinite(length[:, 0]) & (length[:, 0] > 1e-12)
    unit = np.zeros_like(normals)
    unit[:, 2] = 1.0  # a missing normal falls back to +z (identity rotation)
    unit[good] = normals[good] / length[good]
    return unit


def _frames_from_normals(normals: np.ndarray) -> np.ndarray:
    """Right-handed rotations ``[N, 3, 3]`` with columns (tangent, bitangent, normal)."""
    # Helper axis: the world axis least aligned with the normal, so the cross product is well conditioned.
    helper = np.eye(3)[np.argmin(np.abs(normals), axis=1)]  # [N, 3]
    tangent = np.cross(helper, normals)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(normals, tangent)
    return np.stack([tangent, bitangent, normals], axis=2)
