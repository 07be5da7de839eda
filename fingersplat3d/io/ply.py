"""The project's one PLY path: binary PLY through ``plyfile`` (the library the 3DGS tools use).

Points and meshes are written as float32 little-endian vertices (Open3D writes float64: these files
are half the size, which matters for shipped samples and large fused clouds) and open in MeshLab,
Open3D and trimesh. :func:`read_vertex_element` is the checked reader the Gaussian PLY builds on:
anything that is not a readable binary PLY is an :class:`~fingersplat3d.errors.InputError` naming
the file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from plyfile import PlyData, PlyElement, PlyElementParseError, PlyHeaderParseError

from ..atomic import atomic_path
from ..errors import input_error

__all__ = ["write_mesh_ply", "write_points_ply", "write_vertex_ply", "read_vertex_element", "read_vertex_ply"]


def _vertex_block(vertices: np.ndarray, normals: np.ndarray | None, colors: np.ndarray | None) -> np.ndarray:
    vertices = np.asarray(vertices, np.float32)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.all(np.isfinite(vertices)):
        raise ValueError("vertices must be a finite [N, 3] array")
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
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
    return block


def _write(path: str | Path, elements: list[PlyElement], comments: str | list[str]) -> Path:
    path = Path(path)
    with atomic_path(path) as temporary:
        PlyData(elements, text=False, byte_order="<",
                comments=[comments] if isinstance(comments, str) else list(comments)).write(str(temporary))
    return path


def write_vertex_ply(path: str | Path, block: np.ndarray, comment: str | list[str] = "written by fingersplat3d") -> Path:
    """One ``vertex`` element from a structured array (its fields are the properties), atomically; ``comment``:
    the header's comment line, or lines."""
    return _write(path, [PlyElement.describe(block, "vertex")], comment)


def write_mesh_ply(path: str | Path, vertices: np.ndarray, triangles: np.ndarray,
                   normals: np.ndarray | None = None, colors: np.ndarray | None = None) -> Path:
    """A triangle mesh: vertices ``[N, 3]``, triangles ``[T, 3]``, optional normals and colours in [0, 1]."""
    block = _vertex_block(vertices, normals, colors)
    triangles = np.asarray(triangles, np.int64)
    if triangles.ndim != 2 or triangles.shape[1] != 3 or triangles.min(initial=0) < 0 or triangles.max(initial=0) >= len(block):
        raise ValueError("triangles must be a [T, 3] array of valid vertex indices")
    faces = np.empty(len(triangles), dtype=[("vertex_indices", "<i4", (3,))])
    faces["vertex_indices"] = triangles
    face = PlyElement.describe(faces, "face", len_types={"vertex_indices": "u1"}, val_types={"vertex_indices": "i4"})
    return _write(path, [PlyElement.describe(block, "vertex"), face], "written by fingersplat3d")


def write_points_ply(path: str | Path, points: np.ndarray, normals: np.ndarray | None = None,
                     colors: np.ndarray | None = None) -> Path:
    """A point cloud: points ``[N, 3]`` with optional normals and colours in [0, 1]."""
    return write_vertex_ply(path, _vertex_block(points, normals, colors))


def read_vertex_element(path: str | Path, what: str = "PLY") -> np.ndarray:
    """The ``vertex`` element of a binary PLY file as a structured array (native byte order).

    ``what`` names the expected kind of file in the messages ("3D Gaussian PLY", ...).
    """
    return read_vertex_ply(path, what)[0]


def read_vertex_ply(path: str | Path, what: str = "PLY") -> tuple[np.ndarray, list[str]]:
    """:func:`read_vertex_element`'s array and the header's comment lines."""
    path = Path(path)
    if not path.is_file():
        raise input_error(path, f"no such {what} file")
    with open(path, "rb") as handle:
        if handle.read(3) != b"ply":
            raise input_error(path, "not a PLY file (it does not start with 'ply')")
    try:
        data = PlyData.read(str(path))
    except PlyHeaderParseError as error:
        raise input_error(path, f"corrupt PLY header ({_one_line(error)})") from None
    except (PlyElementParseError, ValueError, EOFError) as error:
        raise input_error(path, f"the file is truncated or corrupt ({_one_line(error)})") from None
    if data.text:
        raise input_error(path, f"ASCII PLY is not supported for a {what} (write it binary)")
    if not data.elements or data.elements[0].name != "vertex":
        raise input_error(path, f"not a {what}: the first element is not 'vertex'")
    vertices = data.elements[0].data
    if any(vertices.dtype[name].kind == "O" for name in vertices.dtype.names):
        raise input_error(path, f"not a {what}: the vertex element has list properties")
    return vertices.astype(vertices.dtype.newbyteorder("=")), [str(line) for line in data.comments]


def _one_line(error: Exception) -> str:
    return " ".join(str(error).split()).rstrip(".")
