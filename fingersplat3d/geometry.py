"""Open3D adapters: depth maps and views to ``open3d.geometry.PointCloud``, the geometry every stage hands on.

Pure numpy camera math lives in :mod:`fingersplat3d.scene`; this module is the layer above it
that knows Open3D (imported lazily so that the pure-math modules never load it).
"""
from __future__ import annotations

import sys
import types
from typing import TYPE_CHECKING

import numpy as np

from .scene import Capture, View, depth_normals

if TYPE_CHECKING:  # pragma: no cover
    import open3d as o3d

__all__ = ["points_to_cloud", "cloud_arrays", "view_point_cloud", "capture_point_cloud", "skip_open3d_web_viewer"]

_WEB_VIEWER = "open3d.visualization.draw_plotly"
_WEB_VIEWER_NAMES = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")


def skip_open3d_web_viewer() -> None:
    """Let ``import open3d`` skip its Plotly/Dash viewer, which nothing here uses.

    Open3D imports ``open3d.visualization.draw_plotly`` on every ``import open3d``, and that imports Dash
    and IPython: 1.1 s of the 2.0 s the import takes on 2 cores, in every ``fs3d`` command and every
    batch worker. Called by those entry points only (never on ``import fingersplat3d``, so a user's own
    session keeps Open3D whole); a no-op once Open3D is imported. In its place, a module whose functions
    say why they are missing.
    """
    if "open3d" in sys.modules or _WEB_VIEWER in sys.modules:
        return

    def missing(*args, **kwargs):
        raise RuntimeError("Open3D's Plotly viewer is not loaded in an fs3d process; "
                           "use it from your own Python session")

    stub = types.ModuleType(_WEB_VIEWER, "Open3D's Plotly viewer, not loaded (see fingersplat3d.geometry).")
    for name in _WEB_VIEWER_NAMES:
        setattr(stub, name, missing)
    sys.modules[_WEB_VIEWER] = stub


def points_to_cloud(points: np.ndarray, colors: np.ndarray | None = None,
                    normals: np.ndarray | None = None) -> "o3d.geometry.PointCloud":
    """An Open3D cloud from ``[N, 3]`` points, optional ``[N]``/``[N, 3]`` colours in [0, 1] and normals."""
    import open3d as o3d

    points = np.asarray(points, np.float64).reshape(-1, 3)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if colors is not None:
        colors = np.asarray(colors, np.float64).reshape(len(points), -1)
        cloud.colors = o3d.utility.Vector3dVector(np.repeat(colors, 3, axis=1) if colors.shape[1] == 1 else colors)
    if normals is not None:
        cloud.normals = o3d.utility.Vector3dVector(np.asarray(normals, np.float64).reshape(-1, 3))
    return cloud


def cloud_arrays(cloud: "o3d.geometry.PointCloud") -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(points [N, 3], colors [N, 3] or None, normals [N, 3] or None)`` as numpy arrays."""
    colors = np.asarray(cloud.colors) if cloud.has_colors() else None
    normals = np.asarray(cloud.normals) if cloud.has_normals() else None
    return np.asarray(cloud.points), colors, normals


def view_point_cloud(view: View, depth: np.ndarray | None = None, stride: int = 1,
                     estimate_normals: bool = True) -> "o3d.geometry.PointCloud":
    """Back-project a view's depth (its ground truth unless ``depth`` is given) to a coloured cloud.

    Only finite, positive depths inside the mask (when the view has one) become points; with
    ``estimate_normals``, each point's normal is the depth map's own (:func:`~fingersplat3d.scene.depth_normals`,
    from its neighbours on the pixel grid, facing the camera).
    """
    if view.camera is None:
        raise ValueError(f"view {view.name!r} has no camera: cannot back-project its depth")
    depth = view.depth if depth is None else np.asarray(depth, np.float32)
    if depth is None:
        raise ValueError(f"view {view.name!r} has no depth map")
    with np.errstate(invalid="ignore"):
        surface = np.isfinite(depth) & (depth > 0)
    if view.mask is not None:
        surface &= view.mask
    valid = surface & _stride_mask(depth.shape, stride)
    pixels = np.argwhere(valid)[:, ::-1].astype(np.float64)
    points = view.camera.unproject(pixels, depth[valid])
    normals = None
    if estimate_normals and len(points) >= 3:
        normals = depth_normals(view.camera, np.where(surface, depth, np.nan))[valid]
        normals[~np.isfinite(normals).all(1)] = 0.0  # a pixel with no neighbour on the map: no direction
    return points_to_cloud(points, view.image[valid], normals)


def capture_point_cloud(capture: Capture, voxel_mm: float | None = None, stride: int = 1) -> "o3d.geometry.PointCloud":
    """All views' depth maps fused into one cloud (world frame), optionally voxel-downsampled."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud()
    for view in capture.views:
        if view.depth is not None and view.camera is not None:
            cloud += view_point_cloud(view, stride=stride, estimate_normals=True)
    if voxel_mm:
        cloud = cloud.voxel_down_sample(voxel_mm)
        if cloud.has_normals():  # voxel averaging shortens normals: make them unit again
            cloud.normalize_normals()
    return cloud


def _stride_mask(shape: tuple[int, int], stride: int) -> np.ndarray:
    keep = np.zeros(shape, bool)
    keep[::stride, ::stride] = True
    return keep

