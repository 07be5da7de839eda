"""Pictures people look at: contact sheets of captures with masks, depth and minutiae; what a fuse found."""
from __future__ import annotations

import cv2
import numpy as np

from .align.transfer import backing_on
from .io.depth import depth_colormap
from .sampling import resized_image
from .scene import Capture

__all__ = ["TILE_HEIGHT", "contact_sheet", "draw_minutiae", "fuse_overview", "gray8", "side_by_side"]

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
        # shrunk first, then made 8-bit RGB (a camera-sized photo converted whole costs half a second)
        photo = _to_rgb8(cv2.resize(np.asarray(view.image, np.float32), size, interpolation=cv2.INTER_AREA))
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


_BACKED = np.array([60, 200, 90], np.float64)  # skin a second view also sees: shape from the photos
_ONE_VIEW = np.array([245, 160, 40], np.float64)  # skin only this view sees: the pointmap's guess
_NOT_PLACED = (215, 40, 40)
TILE_HEIGHT = 360
"""Rows of a photo in :func:`fuse_overview`."""
_CAPTION = 44
_PER_ROW = 5  # tiles a row: ten views (a CFPose capture) make two rows


def _caption(tile: np.ndarray, lines: list[str], colour=(30, 30, 30)) -> np.ndarray:
    """``tile`` under a white strip holding up to two lines of text."""
    strip = np.full((_CAPTION, tile.shape[1], 3), 255, np.uint8)
    for row, line in enumerate(lines[:2]):
        cv2.putText(strip, line, (6, 18 + 20 * row), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1, cv2.LINE_AA)
    return np.vstack([strip, tile])


def _view_tile(image: np.ndarray, backing: np.ndarray | None) -> np.ndarray:
    """The photo, its skin a second view backs tinted green, the skin only it sees amber (``backing`` from
    :func:`~fingersplat3d.align.transfer.multi_view_backing`, any stride; None: not placed, a red frame)."""
    scale = TILE_HEIGHT / image.shape[0]
    size = (max(1, round(image.shape[1] * scale)), TILE_HEIGHT)
    # shrunk first, then made 8-bit RGB: a 20-megapixel photo converted whole cost 0.5 s a view
    tile = _to_rgb8(resized_image(np.asarray(image, np.float32), size))
    if backing is None:
        cv2.rectangle(tile, (0, 0), (tile.shape[1] - 1, tile.shape[0] - 1), _NOT_PLACED, 6)
        return tile
    tinted = tile.astype(np.float64)
    backing = backing_on(backing, (size[1], size[0]))
    for value, colour in ((1, _BACKED), (0, _ONE_VIEW)):
        tinted[backing == value] = 0.55 * tinted[backing == value] + 0.45 * colour
    return tinted.astype(np.uint8)


_LABEL_GAP = 14
"""Pixels between a camera's dot and its name in the rig picture."""


def _label_box(dot: tuple[int, int], xy: np.ndarray, text_size: tuple[int, int]) -> tuple[int, int]:
    """Where a camera's name goes (cv2.putText's origin: the text's bottom left) beyond its dot at pixel ``dot``, away
    from the finger (``xy``: the camera's place about it, any scale), before any clamping."""
    outward = xy / max(float(np.linalg.norm(xy)), 1e-12)
    width, height = text_size
    x = dot[0] + _LABEL_GAP * outward[0] - width * (outward[0] < -0.3) - width / 2 * (abs(outward[0]) <= 0.3)
    y = dot[1] + _LABEL_GAP * outward[1] + height * (outward[1] > 0.3) + height / 2 * (abs(outward[1]) <= 0.3)
    return int(x), int(y)


def _label_origin(dot: tuple[int, int], xy: np.ndarray, text_size: tuple[int, int], size: int) -> tuple[int, int]:
    """Where a camera's name goes in the ``size`` square rig picture: beside its dot (:func:`_label_box`) where it fits;
    else (a long file name beside a camera at the picture's side) above the dot, or below one in the lower half, moved
    in from the picture's edge rather than cut there."""
    x, y = _label_box(dot, xy, text_size)
    width, height = text_size
    if x < 2 or x + width > size - 2:
        x = int(dot[0] - width / 2)
        y = dot[1] - _LABEL_GAP if xy[1] <= 0 else dot[1] + _LABEL_GAP + height
    return min(max(x, 2), max(2, size - 2 - width)), min(max(y, height + 2), size - 4)


def _rig_tile(cameras: list, names: list[str], aligned: list[bool], size: int = 300) -> np.ndarray | None:
    """The placed cameras seen along the finger (the normal of the plane their optical axes span), around the point
    nearest to all their axes; None with fewer than two placed cameras or axes all parallel."""
    placed = [k for k, ok in enumerate(aligned) if ok]
    if len(placed) < 2:
        return None
    centres = np.stack([cameras[k].center for k in placed])
    axes = np.stack([cameras[k].rotation.T @ np.array([0.0, 0.0, 1.0]) for k in placed])
    singular, basis = np.linalg.svd(axes)[1:]
    if singular[1] < 1e-3 * singular[0]:
        return None
    along = basis[-1] if len(placed) > 2 else np.cross(axes[0], axes[1]) / np.linalg.norm(np.cross(axes[0], axes[1]))
    # the point nearest to every optical axis (least squares), where the finger sits
    projectors = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]
    middle = np.linalg.lstsq(projectors.sum(0), np.einsum("kij,kj->i", projectors, centres), rcond=None)[0]
    right = axes[0] - (axes[0] @ along) * along
    right /= np.linalg.norm(right)
    up = np.cross(along, right)
    flat = np.stack([(centres - middle) @ right, (centres - middle) @ up], 1)
    reach = max(float(np.abs(flat).max()), 1e-12)
    to_pixels = lambda xy: tuple(int(v) for v in np.round(size / 2 + xy * (0.38 * size / reach)))  # noqa: E731
    tile = np.full((size, size, 3), 255, np.uint8)
    cv2.circle(tile, to_pixels(np.zeros(2)), max(4, size // 20), (200, 170, 150), -1, cv2.LINE_AA)
    for k, xy in zip(placed, flat):
        dot = to_pixels(xy)
        cv2.line(tile, dot, to_pixels(np.zeros(2)), (170, 170, 170), 1, cv2.LINE_AA)
        cv2.circle(tile, dot, 6, (40, 80, 200), -1, cv2.LINE_AA)
        text_size = cv2.getTextSize(names[k], cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0]
        origin = _label_origin(dot, xy, text_size, size)
        cv2.putText(tile, names[k], origin, cv2.FONT_HERSHEY_SIMPLEX, 0.5, (30, 30, 30), 1, cv2.LINE_AA)
    return tile


def _wrapped(line: str, width: int, scale: float) -> list[str]:
    """``line`` broken after its commas into lines no wider than ``width`` pixels (a part wider alone stays whole);
    the parts after the first indented."""
    parts, lines = line.split(", "), []
    current = parts[0]
    for part in parts[1:]:
        candidate = f"{current}, {part}"
        if cv2.getTextSize(candidate, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] <= width:
            current = candidate
        else:
            lines.append(current + ",")
            current = "   " + part
    return lines + [current]


def fuse_overview(images: list[np.ndarray], names: list[str], cameras: list, backing: list[np.ndarray | None],
                  alignment: dict) -> np.ndarray:
    """``fs3d fuse``'s picture of what it found (RGB uint8): each photo, the skin a second view backs green and the
    skin only it sees amber (there the shape is the pointmap's guess), a view not placed framed red; the placed
    cameras seen along the finger; each turn between views and how far it moves with the focal 10 % off, and a
    warning where the photos do not hold the focal (``alignment``: report.json's)."""
    from .eval.poses import ROLL_NOTED_DEG, view_turn_deg

    aligned = [backing_map is not None for backing_map in backing]
    shares = alignment.get("backed_by_two_views") or {}
    tiles = []
    for image, name, backing_map in zip(images, names, backing):
        share = shares.get(name)
        words = ([f"{name}: not registered"] if backing_map is None else
                 [name, f"{100 * share:.0f} % backed by a second view" if share is not None else ""])
        tiles.append(_caption(_view_tile(image, backing_map), words, _NOT_PLACED if backing_map is None else (30, 30, 30)))
    rig = _rig_tile(cameras, names, aligned)
    if rig is not None:
        moves = alignment.get("turn_sensitivity_deg") or {}
        held = (alignment.get("focal_probe") or {}).get("held") is not False
        how = "with the focal 10% off" if held else "with the focal held shorter"  # the probe's (how sure it is)
        lines = [] if held else ["the photos do not hold the focal: give --focal-px"]  # first: never cut off
        for a in range(len(names)):
            for b in range(a + 1, len(names)):
                if aligned[a] and aligned[b]:
                    pair = f"{names[a]}-{names[b]}"
                    angle, roll = view_turn_deg(cameras[a].rotation, cameras[b].rotation)
                    rolled = f" (photo turned {roll:.0f})" if abs(roll) >= ROLL_NOTED_DEG else ""
                    lines.append(f"{pair}: {angle:.1f} deg" + rolled + (f", moves {moves[pair]:.1f} {how}"
                                                                         if moves.get(pair) is not None else ""))
        lines = [part for line in lines for part in _wrapped(line, rig.shape[1] - 12, 0.42)]
        text = np.full((20 * min(len(lines), 8) + 8, rig.shape[1], 3), 255, np.uint8)
        for row, line in enumerate(lines[:8]):
            colour = _NOT_PLACED if line.startswith("the photos") else (30, 30, 30)
            cv2.putText(text, line, (6, 16 + 20 * row), cv2.FONT_HERSHEY_SIMPLEX, 0.42, colour, 1, cv2.LINE_AA)
        tiles.append(_caption(np.vstack([rig, text]), ["the cameras seen along the finger", "turns between them"]))
    rows = [_row(tiles[start:start + _PER_ROW]) for start in range(0, len(tiles), _PER_ROW)]
    width = max(row.shape[1] for row in rows)
    rows = [np.hstack([row, np.full((row.shape[0], width - row.shape[1], 3), 255, np.uint8)]) for row in rows]
    keys = ["green: skin two views see (shape from the photos)", "amber: one view only (shape guessed)",
            "red frame: not registered"]
    lines = ["   ".join(keys)] if width >= 900 else keys  # a narrow picture (one photo) gets a line each
    legend = np.full((8 + 18 * len(lines), width, 3), 255, np.uint8)
    for row, line in enumerate(lines):
        cv2.putText(legend, line, (6, 18 + 18 * row), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (60, 60, 60), 1, cv2.LINE_AA)
    return np.vstack(rows + [legend])


def _row(tiles: list[np.ndarray]) -> np.ndarray:
    """Tiles side by side, top-aligned on white, 10 px apart."""
    height = max(tile.shape[0] for tile in tiles)
    parts = []
    for tile in tiles:
        parts += [np.vstack([tile, np.full((height - tile.shape[0], tile.shape[1], 3), 255, np.uint8)]),
                  np.full((height, 10, 3), 255, np.uint8)]
    return np.hstack(parts[:-1])
