"""Silhouette contours as correspondences: a view's surface must reach another view's outline where it sees it.

A camera's silhouette edge is where its rays graze the finger. The skin there faces sideways, and a
second view turned toward that side sees it (the front camera's outline is skin a 45-degree side camera
sees squarely). So, per station along view b's silhouette axis and per side of it, the point of view
a's surface that projects furthest toward that side of b must land *on* b's edge: no further (it would
stand outside b's silhouette), no nearer (b's outline would then be skin nobody placed there).

That is the one thing the photos say about the skin only one view sees beyond another's outline: without
it, the surface there is the prior's guess, and on synthetic fingers it fell away too early (side views'
unshared skin 0.74-0.85 mm too deep, their surfaces 5-7 px short of the front view's outline).

Each such pair becomes a correspondence the global alignment already knows how to use: a's pixel (its
outermost point at the station, chosen afresh from the current model every round) against b's edge
point, weighted only across the edge (information ``n n^T``: the along-edge offset is free) and only
in the a -> b direction (b's own depth at its rim means nothing). A side counts when a faces b's rim
there by more than :data:`MIN_FACING` and b's edge is its silhouette's (not the image border's).
Pure numpy.
"""
from __future__ import annotations

import numpy as np

from ...scene import Camera
from ...segment.silhouette import SilhouetteFrame, silhouette_frame

__all__ = ["contour_correspondences", "MIN_FACING", "STATION_STEP_PX"]

MIN_FACING = 0.35  # cosine between a's line of sight and the skin's normal at b's rim (~70 degrees)
STATION_STEP_PX = 6.0  # one contour correspondence per this many pixels along b's axis, per side
REACH_PERIODS = 4.0  # a's outermost point counts when it projects within this many ridge periods of b's edge
_END_SHARE = 0.15  # stations this share of the silhouette's length from either end are left out (tip cap, cut end)
_BORDER_PX = 3  # an edge this close to the image border is the frame's, not the finger's


def _camera(alignment, view: int, shape: tuple[int, int]) -> Camera:
    return Camera.from_focal(alignment.focals[view], shape[1], shape[0], alignment.world_to_cam[view])


def contour_correspondences(alignment, masks, a: int, b: int, period_px: float, stride: int = 2,
                            outline: SilhouetteFrame | None = None):
    """``(uv_a [K, 2], uv_b [K, 2], information_b [K, 2, 2])`` of the contour correspondences of view ``a``'s
    surface against view ``b``'s outline (module docstring); empty arrays when there are none. ``outline``:
    :func:`~fingersplat3d.segment.silhouette.silhouette_frame` of ``masks[b]``, when the caller holds it."""
    empty = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2)))
    depth_a, mask_b = alignment.depths[a], np.asarray(masks[b], bool)
    if mask_b.sum() < 64 or not np.isfinite(depth_a).any():
        return empty
    camera_a, camera_b = _camera(alignment, a, depth_a.shape), _camera(alignment, b, mask_b.shape)
    frame = silhouette_frame(mask_b) if outline is None else outline
    rows, cols = np.nonzero(np.isfinite(depth_a[::stride, ::stride]))  # every stride-th pixel, in row-major order
    rows, cols = rows * stride, cols * stride
    uv_a = np.stack([cols, rows], 1).astype(np.float64)
    points = camera_a.unproject(uv_a, depth_a[rows, cols])
    uv_in_b, z = camera_b.project(points)
    ok = np.isfinite(uv_in_b).all(1) & (z > 0)
    uv_a, points, uv_in_b = uv_a[ok], points[ok], uv_in_b[ok]
    s, t = frame.coordinates(uv_in_b)
    start = frame.sections.start
    length = frame.sections.half_width.size
    stations = start + np.arange(_END_SHARE * length, (1 - _END_SHARE) * length, STATION_STEP_PX)
    height, width = mask_b.shape
    # What depends on the station or the side alone, for all of them at once (the same arithmetic, element by element).
    halves, centres = frame.sections.at(stations)
    sides = (-1.0, 1.0)
    edges = [frame.origin + stations[:, None] * frame.axis + (centres + side * halves)[:, None] * frame.normal
             for side in sides]
    on_image = [(_BORDER_PX <= edge[:, 0]) & (edge[:, 0] <= width - 1 - _BORDER_PX) & (_BORDER_PX <= edge[:, 1])
                & (edge[:, 1] <= height - 1 - _BORDER_PX) for edge in edges]
    rotation_b = camera_b.rotation
    normals_world = [rotation_b.T @ np.array([side * frame.normal[0], side * frame.normal[1], 0.0]) for side in sides]
    by_s = np.argsort(s, kind="stable")  # each station's points by two binary searches, not a pass over all of them
    lows = np.searchsorted(s[by_s], stations - 0.5 * STATION_STEP_PX - 1e-6, side="left")
    highs = np.searchsorted(s[by_s], stations + 0.5 * STATION_STEP_PX + 1e-6, side="right")
    reach = REACH_PERIODS * period_px
    chosen, chosen_sides = [], []
    for k, (station, low, high) in enumerate(zip(stations, lows, highs)):
        near = np.sort(by_s[low:high])  # in index order, as the argmax below breaks ties by it
        near = near[np.abs(s[near] - station) <= 0.5 * STATION_STEP_PX]  # the window's test itself, to the bit
        if not near.size:
            continue
        centre, half = centres[k], halves[k]
        across = t[near] - centre
        for j, side in enumerate(sides):
            if not on_image[j][k]:
                continue
            best = near[int(np.argmax(side * across))]
            if side * (t[best] - centre) < half - reach:
                continue  # a's surface does not come near this side of b's outline
            chosen.append(best)
            chosen_sides.append(j)
    if not chosen:
        return empty
    chosen, chosen_sides = np.asarray(chosen), np.asarray(chosen_sides)
    sight = camera_a.center - points[chosen]
    facing = np.einsum("nk,nk->n", np.stack([normals_world[j] for j in chosen_sides]), sight)
    keep = facing / np.maximum(np.linalg.norm(sight, axis=1), 1e-12) >= MIN_FACING  # a sees the skin at b's rim
    if not keep.any():
        return empty
    chosen, side = chosen[keep], np.asarray(sides)[chosen_sides[keep]]
    half_at, centre_at = frame.sections.at(s[chosen])
    # On the outline itself (the outer side of the outermost mask pixel). One pixel inside it, where b's own pointmap
    # still had depth, set every target a pixel short, all the same way: synthetic side cameras 0.7-1.0 degrees off
    # with exact matches (0.04-0.14 without the contours; docs/measurements.md, stop 73).
    station_points = (frame.origin + s[chosen][:, None] * frame.axis
                      + (centre_at + side * half_at)[:, None] * frame.normal)
    normal_image = side[:, None] * frame.normal
    return uv_a[chosen], station_points, np.einsum("ni,nj->nij", normal_image, normal_image)
