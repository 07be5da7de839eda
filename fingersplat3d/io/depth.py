"""Depth maps: float32 ``H x W`` ``.npy`` files, plus pictures of them.

A depth map holds camera-frame z (mm for metric data) on its view's pixel grid; NaN means "no
depth here". Inf and negative values are errors. Pictures are for people, not for reading back:
``write_depth_preview`` writes a 16-bit PNG (near = bright, the valid range mapped to 1..65535,
NaN = 0) and ``depth_colormap`` returns an RGB ``uint8`` picture (near = the hot end, NaN black).
Previews belong in reconstruction folders, never in a capture's ``depth/``.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..errors import input_error
from ..atomic import atomic_path

__all__ = ["read_depth", "write_depth", "write_depth_preview", "depth_colormap"]


def _problem(depth: np.ndarray) -> str | None:
    """Why ``depth`` is not a valid depth map, or None."""
    if depth.ndim != 2:
        return f"depth map must be 2-D (H x W), got shape {depth.shape}"
    if depth.shape[0] < 1 or depth.shape[1] < 1:
        return f"depth map is empty (shape {depth.shape})"
    if np.isinf(depth).any():
        return "depth map contains Inf (use NaN for pixels without depth)"
    if (depth < 0).any():  # NaN compares False, so NaN passes
        return f"depth map contains negative values (min {np.nanmin(depth):g})"
    return None


def read_depth(path: str | Path, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a depth ``.npy`` as float32 ``H x W``; ``shape`` ``(H, W)`` is checked when given."""
    path = Path(path)
    if not path.is_file():
        raise input_error(path, "file not found")
    with open(path, "rb") as file:
        if file.read(6) != b"\x93NUMPY":  # numpy would take it for a pickle and suggest loading it unsafely
            raise input_error(path, "not a .npy depth map (the file does not start with NumPy's header)")
    try:
        raw = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as error:
        raise input_error(path, f"not a readable .npy depth map ({error})") from None
    if not isinstance(raw, np.ndarray) or raw.dtype.kind not in "fiu":
        raise input_error(path, f"depth map must hold real numbers, got {getattr(raw, 'dtype', type(raw))}")
    depth = raw.astype(np.float32)
    if raw.dtype.kind == "f" and np.isinf(depth).any() != np.isinf(raw).any():
        raise input_error(path, "depth map has values too large for float32")
    problem = _problem(depth)
    if problem:
        raise input_error(path, problem)
    if shape is not None and depth.shape != tuple(shape):
        raise input_error(path, f"depth map is {depth.shape[1]}x{depth.shape[0]} but its image is {shape[1]}x{shape[0]}")
    return depth


def write_depth(path: str | Path, depth: np.ndarray) -> Path:
    """Write a depth map as float32 ``.npy``, atomically (refuses Inf, negatives, wrong rank)."""
    path = Path(path)
    depth = np.asarray(depth, dtype=np.float32)
    problem = _problem(depth)
    if problem:
        raise ValueError(f"{path}: refusing to write: {problem}")
    with atomic_path(path) as temporary, open(temporary, "wb") as handle:
        np.save(handle, depth, allow_pickle=False)
    return path


def _nearness(depth: np.ndarray, span: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Valid mask and ``[0, 1]`` nearness (1 = nearest valid pixel, 0 = farthest; ``span``: the (near, far) these stand
    for instead, clipped to it)."""
    depth = np.asarray(depth, np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth map must be 2-D (H x W), got shape {depth.shape}")
    valid = np.isfinite(depth)
    nearness = np.zeros(depth.shape)
    if valid.any():
        near, far = (depth[valid].min(), depth[valid].max()) if span is None else span
        if far == near:
            nearness[valid] = 1.0
        else:
            ratio = (far - depth[valid]) / (far - near)
            nearness[valid] = ratio if span is None else np.clip(ratio, 0.0, 1.0)  # a map's own range needs no clip
    return valid, nearness


def write_depth_preview(path: str | Path, depth: np.ndarray) -> Path:
    """Write a 16-bit grayscale PNG of a depth map: near = 65535, far = 1, NaN = 0."""
    path = Path(path)
    valid, nearness = _nearness(depth)
    picture = np.where(valid, 1 + np.round(nearness * 65534), 0).astype(np.uint16)
    with atomic_path(path) as temporary:
        if not cv2.imwrite(str(temporary), picture):
            raise OSError(f"{path}: could not write depth preview")
    return path


def depth_colormap(depth: np.ndarray, colormap: int = cv2.COLORMAP_TURBO,
                   span: tuple[float, float] | None = None) -> np.ndarray:
    """An ``H x W x 3`` RGB uint8 picture of a depth map (near = hot end of ``colormap``, NaN black; ``span``: the
    (near, far) depths the colour map's ends stand for, default the map's own)."""
    valid, nearness = _nearness(depth, span)
    levels = np.round(nearness * 255).astype(np.uint8)
    rgb = cv2.applyColorMap(levels, colormap)[..., ::-1]
    return np.ascontiguousarray(np.where(valid[..., None], rgb, 0).astype(np.uint8))
