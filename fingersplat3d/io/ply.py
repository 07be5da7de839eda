"""Binary PLY writers (float32, little endian) that MeshLab, Open3D and trimesh all read.

Open3D writes vertex coordinates as float64; these writers keep files half the size, which
matters for shipped samples and for large fused clouds.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..atomic import atomic_path

__all__ = ["write_mesh_ply", "write_points_ply"]


def _vertex_block(vertices: np.ndarray, normals: np.ndarray | None, colors: np.ndarray | None) -> tuple[list[str], np.ndarray]:
    vertices = np.asarray(vertices, np.float32)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.all(np.isfinite(vertices)):
        raise ValueError("vertices must be a finite [N, 3] array")
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    header = ["property float x", "property float y", "property float z"]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
        header += ["property float nx", "property float ny", "property float nz"]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
        header += ["property uchar red", "property uchar green", "property uchar blue"]
    block = np.empty(len(vertices), dtype=fields)
    block["x"], block["y"], block["z"] = vertices.T
    if normals is not None:
        normals = np.asarray(normals, np.float32).reshape(-1, 3)
        block["nx"], block["ny"], block["nz"] = normals.T
    if colors is not None:
        colors = np.asarray(colors, np.float64).reshape(len(vertices), -1)
        colors = np.repeat(colors, 3, axis=1) if colors.shape[1] == 1 else colors
        colors8 = np.round(np.clip(colors, 0.0, 1.0) * 255).astype(np.uint8)
        block["red"], block["green"], block["blue"] = colors8.T
    return header, block


def write_mesh_ply(path: str | Path, vertices: np.ndarray, triangles: np.ndarray,
                   normals: np.ndarray | None = None, colors: np.ndarray | None = None) -> Path:
    """A triangle mesh: vertices ``[N, 3]``, triangles ``[T, 3]``, optional normals and colours in [0, 1]."""
    header, block = _vertex_block(vertices, normals, colors)
    triangles = np.asarray(triangles, np.int64)
    if triangles.ndim != 2 or triangles.shape[1] != 3 or triangles.min(initial=0) < 0 or triangles.max(initial=0) >= len(block):
        raise ValueError("triangles must be a [T, 3] array of valid vertex indices")
    faces = np.empty(len(triangles), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"] = triangles
    lines = ["ply", "format binary_little_endian 1.0", "comment written by fingersplat3d",
             f"element vertex {len(block)}", *header, f"element face {len(faces)}",
             "property list uchar int vertex_indices", "end_header"]
    path = Path(path)
    with atomic_path(path) as temporary, open(temporary, "wb") as handle:
        handle.write(("\n".join(lines) + "\n").encode("ascii"))
        handle.write(block.tobytes())
        handle.write(faces.tobytes())
    return path


def write_points_ply(path: str | Path, points: np.ndarray, normals: np.ndarray | None = None,
                     colors: np.ndarray | None = None) -> Path:
    """A point cloud: points ``[N, 3]`` with optional normals and colours in [0, 1]."""
    header, block = _vertex_block(points, normals, colors)
    lines = ["ply", "format binary_little_endian 1.0", "comment written by fingersplat3d",
             f"element vertex {len(block)}", *header, "end_header"]
    path = Path(path)
    with atomic_path(path) as temporary, open(temporary, "wb") as handle:
        handle.write(("\n".join(lines) + "\n").encode("ascii"))
        handle.write(block.tobytes())
    return path
