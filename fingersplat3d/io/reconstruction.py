"""Writers for the files of a reconstruction folder (docs/conventions.md, "A reconstruction folder").

``fused.ply`` (:func:`write_fused_cloud`), ``depth/<view>.npy`` with its pictures
(:func:`write_view_depth`) and ``report.json`` (:func:`write_report`). ``cameras.json`` is
:func:`fingersplat3d.io.cameras.write_cameras`; ``mesh.ply`` is :func:`fingersplat3d.mesh.write_mesh`.
Every file is written under a temporary name and moved into place when complete.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import cv2
import numpy as np

from ..atomic import atomic_path
from ..sampling import map_on_grid, resized_mask
from .cameras import UNITS
from .depth import depth_colormap, write_depth, write_depth_preview
from .images import write_image
from .jsonio import to_jsonable
from .ply import write_points_ply

if TYPE_CHECKING:  # pragma: no cover
    import open3d as o3d

__all__ = ["DepthFiles", "write_fused_cloud", "write_view_depth", "depth_legend_picture", "write_report"]


def write_fused_cloud(path: str | Path, cloud: "o3d.geometry.PointCloud") -> Path:
    """Write an Open3D cloud as binary float32 PLY with its colours and normals (those it has).

    Refuses (``ValueError`` naming ``path``, nothing written) an empty cloud and NaN/Inf in
    points, normals or colours. The reconstruction contract expects colours and normals; the
    fusion stage provides them, this writer keeps whatever the cloud holds.
    """
    from ..geometry import cloud_arrays

    path = Path(path)
    if not hasattr(cloud, "points"):
        raise TypeError(f"{path}: expected an open3d.geometry.PointCloud, got {type(cloud).__name__}")
    points, colors, normals = cloud_arrays(cloud)
    if len(points) == 0:
        raise ValueError(f"{path}: refusing to write an empty point cloud")
    for what, values in (("points", points), ("normals", normals), ("colours", colors)):
        if values is not None and not np.all(np.isfinite(values)):
            bad = int(np.count_nonzero(~np.isfinite(values).all(axis=1)))
            raise ValueError(f"{path}: refusing to write a point cloud with NaN or Inf in {bad} of its {len(values)} {what}")
    return write_points_ply(path, points, normals=normals, colors=colors)


class DepthFiles(NamedTuple):
    """The three files :func:`write_view_depth` writes for one view."""

    depth: Path  # depth/<name>.npy: float32 H x W, NaN = none
    preview: Path  # depth/<name>.png: 16-bit grayscale, near bright, NaN 0
    picture: Path  # depth/<name>_color.png: colour-mapped depth with a colour bar


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not name or name in (".", "..") or "/" in name or "\\" in name or "\0" in name:
        raise ValueError(f"view name must be a plain file name (no path separators), got {name!r}")
    return name


def write_view_depth(folder: str | Path, name: str, depth: np.ndarray, units: str = "mm") -> DepthFiles:
    """Write one view's depth into ``folder/depth/``: ``<name>.npy``, ``<name>.png``, ``<name>_color.png``.

    ``depth`` is ``[H, W]`` camera-frame z on the view's own pixel grid, NaN where there is none
    (Inf or negative values are refused before anything is written). ``units`` (``"mm"`` or
    ``"arbitrary"``) labels the colour bar. Either all three files are written or, on failure,
    none of this call's files is left in place.
    """
    if units not in UNITS:
        raise ValueError(f'units must be "mm" or "arbitrary", got {units!r}')
    folder = Path(folder) / "depth"
    name = _check_name(name)
    depth = np.asarray(depth, np.float32)
    files = DepthFiles(folder / f"{name}.npy", folder / f"{name}.png", folder / f"{name}_color.png")
    written: list[Path] = []
    try:
        write_depth(files.depth, depth)  # validates before writing anything
        written.append(files.depth)
        picture = depth_legend_picture(depth, units)
        write_depth_preview(files.preview, depth)
        written.append(files.preview)
        write_image(files.picture, picture.astype(np.float32) / 255.0)
        written.append(files.picture)
    except BaseException:
        for path in written:
            path.unlink(missing_ok=True)
        raise
    return files


def _label(value: float, decimals: int, units: str) -> str:
    return f"{value:.{decimals}f} {'mm' if units == 'mm' else 'units'}"


def depth_legend_picture(depth: np.ndarray, units: str = "mm", min_height: int = 192,
                         max_height: int = 2048) -> np.ndarray:
    """``depth_colormap`` of ``depth`` with a colour bar on the right labelled near/far in ``units``.

    RGB uint8. Pictures shorter than ``min_height`` pixels are enlarged (nearest neighbour) so
    the labels stay readable, and pictures taller than ``max_height`` shrunk (area average: a picture to look at;
    the depth itself is the .npy, and the 16-bit preview keeps the full grid); NaN pixels are black.
    """
    depth = np.asarray(depth)
    depth = depth if depth.dtype in (np.float32, np.float64) else depth.astype(np.float64)
    valid = np.isfinite(depth)
    span = (float(np.nanmin(depth)), float(np.nanmax(depth))) if valid.any() else None
    if depth.shape[0] > max_height:  # the depth shrunk before it is coloured: a 20-megapixel map's colours cost 1.3 s
        size = (max(1, round(depth.shape[1] * max_height / depth.shape[0])), max_height)
        # averaged over its finite pixels, NaN where under half a pixel's area has depth; coloured over the whole range
        picture = depth_colormap(map_on_grid(depth, size, resized_mask(valid, size)), span=span)
    else:
        picture = depth_colormap(depth)
        if picture.shape[0] < min_height:
            factor = math.ceil(min_height / picture.shape[0])
            picture = np.repeat(np.repeat(picture, factor, axis=0), factor, axis=1)
    height = picture.shape[0]
    margin = max(4, height // 40)
    font, font_scale = cv2.FONT_HERSHEY_SIMPLEX, max(0.4, height / 900)
    thickness = max(1, round(font_scale * 1.5))
    if span is not None:
        near, far = span
        decimals = int(np.clip(2 - math.floor(math.log10(far - near)), 0, 6)) if far > near else 2
        labels = [_label(near, decimals, units), _label((near + far) / 2, decimals, units), _label(far, decimals, units)]
    else:
        labels = ["no depth"]
    text_width = max(cv2.getTextSize(text, font, font_scale, thickness)[0][0] for text in labels)
    text_height = cv2.getTextSize("0", font, font_scale, thickness)[0][1]
    bar_width = max(8, height // 24)
    panel = np.full((height, 3 * margin + bar_width + text_width, 3), 32, np.uint8)
    top, bottom = margin + text_height // 2, height - margin - text_height // 2
    text_x = 2 * margin + bar_width
    if span is not None:
        # The bar goes through the same colour map as the picture: near (hot) at the top.
        column = np.linspace(near, far, max(2, bottom - top))[:, None].repeat(bar_width, axis=1)
        panel[top:top + len(column), margin:margin + bar_width] = depth_colormap(column)
        for text, y in zip(labels, (top, (top + bottom) // 2, bottom)):
            cv2.putText(panel, text, (text_x, y + text_height // 2), font, font_scale, (235, 235, 235), thickness, cv2.LINE_AA)
    else:
        cv2.putText(panel, labels[0], (text_x, height // 2), font, font_scale, (235, 235, 235), thickness, cv2.LINE_AA)
    return np.ascontiguousarray(np.concatenate([picture, panel], axis=1))


def write_report(path: str | Path, report: dict) -> Path:
    """Write ``report.json``: sorted keys, indented, numpy-safe, NaN/Inf as null, atomically.

    The whole report is converted before the file is touched, so an unsupported value
    (``TypeError`` naming where it sits) leaves nothing behind.
    """
    path = Path(path)
    if not isinstance(report, dict):
        raise TypeError(f"{path}: a report is a dict, got {type(report).__name__}")
    text = json.dumps(to_jsonable(report, "report"), sort_keys=True, indent=2, allow_nan=False) + "\n"
    with atomic_path(path) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return path
