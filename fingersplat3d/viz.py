"""Pictures people look at: contact sheets of captures with masks, depth and minutiae."""
from __future__ import annotations

import cv2
import numpy as np

from .io.depth import depth_colormap
from .scene import Capture

__all__ = ["contact_sheet", "draw_minutiae", "gray8", "side_by_side"]

_ENDING = (230, 60, 40)
_BIFURCATION = (40, 120, 240)


def gray8(image: np.ndarray) -> np.ndarray:
    """A [0, 1] image (gray, or colour averaged) as 8-bit gray."""
    gray = image if image.ndim == 2 else image.mean(2)
    return (np.clip(gray, 0, 1) * 255).astype(np.uint8)


def side_by_side(parts: list[np.ndarray], height: int, gap: int = 8, interpolation: int | None = None) -> np.ndarray:
    """8-bit gray ``parts`` scaled to ``height`` and set in a row, ``gap`` white pixels apart. ``interpolation``:
    OpenCV's flag for every part; None: area averaging to shrink, bilinear to enlarge."""
    tiles = []
    for part in parts:
        scale = height / part.shape[0]
        flag = interpolation if interpolation is not None else (cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
        tiles.append(cv2.resize(part, (max(1, int(round(part.shape[1] * scale))), height), interpolation=flag))
        tiles.append(np.full((height, gap), 255, np.uint8))
    return np.hstack(tiles[:-1])


def _to_rgb8(image: np.ndarray) -> np.ndarray:
    rgb = np.repeat(image[..., None], 3, axis=2) if image.ndim == 2 else image
    return np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8)


def draw_minutiae(image_rgb8: np.ndarray, entries: list[dict], kinds: dict[int, str], scale: float = 1.0) -> np.ndarray:
    """Draw visible minutiae (circle + direction tick): endings red, bifurcations blue."""
    out = np.ascontiguousarray(image_rgb8.copy())
    radius = max(2, round(4 * scale))
    for entry in entries:
        if not entry.get("visible") or entry.get("uv") is None:
            continue
        u, v = (float(x) * scale for x in entry["uv"])
        color = _BIFURCATION if kinds.get(entry["id"]) == "bifurcation" else _ENDING
        centre = (round(u), round(v))
        cv2.circle(out, centre, radius, color, 1, cv2.LINE_AA)
        if entry.get("angle_deg") is not None:
            angle = np.radians(entry["angle_deg"])
            tip = (round(u + 3 * radius * np.cos(angle)), round(v + 3 * radius * np.sin(angle)))
            cv2.line(out, centre, tip, color, 1, cv2.LINE_AA)
    return out


def contact_sheet(capture: Capture, minutiae: dict | None = None, tile_width: int = 480) -> np.ndarray:
    """One row per view: the photo (with ground-truth minutiae), the mask, the depth map. RGB uint8."""
    kinds = {m["id"]: m["kind"] for m in (minutiae or {}).get("minutiae_3d", [])}
    rows = []
    for view in capture.views:
        scale = tile_width / view.width
        size = (tile_width, max(1, round(view.height * scale)))
        photo = cv2.resize(_to_rgb8(view.image), size, interpolation=cv2.INTER_AREA)
        if minutiae and view.name in minutiae.get("views", {}):
            photo = draw_minutiae(photo, minutiae["views"][view.name], kinds, scale)
        tiles = [photo]
        if view.mask is not None:
            tiles.append(cv2.resize(_to_rgb8(view.mask.astype(np.float32)), size, interpolation=cv2.INTER_NEAREST))
        if view.depth is not None:
            tiles.append(cv2.resize(depth_colormap(view.depth), size, interpolation=cv2.INTER_NEAREST))
        row = np.concatenate(tiles, axis=1)
        cv2.putText(row, view.name, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 0), 1, cv2.LINE_AA)
        rows.append(row)
    width = max(row.shape[1] for row in rows)
    rows = [np.pad(row, ((0, 4), (0, width - row.shape[1]), (0, 0))) for row in rows]
    return np.concatenate(rows, axis=0)
