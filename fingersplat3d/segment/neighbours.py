"""One finger per mask: a neighbouring finger in the frame, joined to the finger's mask, is cut away.

A photo of one finger often shows a neighbour beside it (a phone's close-up, a hand not spread), and where the two
touch, or their outlines meet at the frame's edge, one mask holds both. Its outline and width then mislead everything
downstream: the finger's axis, the prior's cross-section, the silhouette contours, the fused cloud, the print.

1. **Is there another finger?** A finger is a sausage as wide as its widest disc inside the frame. The mask is
   *opened* by a disc a :data:`NECK_SHARE` of that width across, outside the frame counting as background (a
   neighbour the frame cuts to a strip holds no such disc): the largest piece left is the finger's *body*. A part of
   the mask outside the body of at least :data:`LARGE_SHARE` of its area is another finger's; what the opening shaves
   off the finger itself (corners, small bumps of the outline) is far smaller. With no such part the mask comes back
   as it was, to the bit.
2. **Where does the finger end on that side?** Where the two fingers touch, the opening cannot part them (a disc
   straddles the seam). The finger's outline on the neighbour's side is straight to first order along the finger: it
   is read where it is clear (stations along the body's axis where the mask ends where the body does, not at the
   frame), a line is fitted to it, and whatever of the mask lies beyond that line (by :data:`MARGIN_SHARE` of the
   width) is cut away; where too little of it is clear, the other finger's part alone is.

Pure OpenCV/numpy.
"""
from __future__ import annotations

import cv2
import numpy as np

from .regions import fill_holes, largest_component

__all__ = ["NECK_SHARE", "LARGE_SHARE", "MARGIN_SHARE", "one_finger"]

NECK_SHARE = 0.4
"""Diameter of the opening's disc as a share of the finger's width (its widest disc): a part of the mask narrower
than this is no finger's body."""
LARGE_SHARE = 0.03
"""A part of the mask outside the finger's opened body, of at least this share of the mask's area, is another
finger's (the opening shaves a finger's own outline by far less)."""
MARGIN_SHARE = 0.02
"""How far (a share of the finger's width) beyond the line of its clear outline the mask is still the finger's."""
_MIN_CLEAR_SHARE = 0.25  # of the body's length: fewer stations with a clear outline fit no line


def one_finger(mask: np.ndarray) -> np.ndarray:
    """``mask`` ``[H, W]`` bool without any other finger joined to it (see the module)."""
    mask = np.asarray(mask, bool)
    # The widest disc inside the frame: with the border continuing the mask (silhouette.widest_disc), a neighbour cut
    # along the frame's edge would read as part of one vast finger.
    inside = cv2.distanceTransform(np.pad(mask, 1).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    width = 2.0 * float(inside.max())
    radius = 0.5 * NECK_SHARE * width
    if radius < 2.0:
        return mask
    # The opening by a disc through two distance transforms (a disc as large as this costs OpenCV's morphology
    # seconds on a real photo): the centres the disc fits at, then every pixel within its radius of one.
    centres = (inside >= radius).view(np.uint8)
    opened = mask & (cv2.distanceTransform(1 - centres, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) <= radius)
    body = largest_component(opened.view(np.uint8))
    if body is None:
        return mask
    count, labels, stats, _ = cv2.connectedComponentsWithStats((mask & ~body).view(np.uint8), connectivity=8)
    large = 1 + np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= LARGE_SHARE * np.count_nonzero(mask))
    if large.size == 0:
        return mask
    other = np.isin(labels, large)
    beyond = _beyond_the_outline(mask, body, other, width)
    kept = mask & ~(other if beyond is None else beyond)
    found = largest_component(kept.view(np.uint8))
    return mask if found is None else fill_holes(found)


def _beyond_the_outline(mask: np.ndarray, body: np.ndarray, other: np.ndarray, width: float) -> np.ndarray | None:
    """The mask's pixels beyond the line of the finger's clear outline on the other finger's side (None where the
    outline is clear over too little of the body to fit one)."""
    rows, cols = np.nonzero(body)
    points = np.stack([cols, rows], axis=1).astype(np.float64)
    centre = points.mean(axis=0)
    _, vectors = np.linalg.eigh(np.cov((points - centre).T))
    along, across = vectors[:, 1], vectors[:, 0]
    other_rows, other_cols = np.nonzero(other)
    side = 1.0 if np.median((np.stack([other_cols, other_rows], 1) - centre) @ across) > 0 else -1.0
    # Each station's (a pixel along the axis) farthest extent of the body toward the other finger.
    all_rows, all_cols = np.nonzero(mask)
    relative = np.stack([all_cols, all_rows], axis=1) - centre
    s, t = relative @ along, side * (relative @ across)
    station = np.round(s - s.min()).astype(np.int64)
    in_body = body[all_rows, all_cols]
    body_extent = np.full(station.max() + 1, -np.inf)
    np.maximum.at(body_extent, station[in_body], t[in_body])
    seen = np.isfinite(body_extent)
    # Clear: the mask ends where the body does (background just beyond its edge, whatever lies farther). The body's
    # two ends are left out (a tip's cap, or the opening's rounded corners where the frame cuts it, is no straight
    # outline).
    beyond_edge = t - body_extent[station]
    touching = np.zeros(station.max() + 1, bool)
    touching[station[(beyond_edge > 0.5) & (beyond_edge <= 1.0 + max(2.0, MARGIN_SHARE * width))]] = True
    # Nor where the body's edge is the frame's (the frame ends the mask, not the finger's outline).
    height, frame_width = mask.shape
    on_frame = ((np.minimum(all_rows, height - 1 - all_rows) < 3)
                | (np.minimum(all_cols, frame_width - 1 - all_cols) < 3))
    touching[station[on_frame & in_body & (beyond_edge > -2.0)]] = True
    end = 0.5 * width
    positions = np.flatnonzero(seen)
    inner = (positions > positions.min() + end) & (positions < positions.max() - end)
    clear = positions[inner & ~touching[positions]]
    if clear.size < _MIN_CLEAR_SHARE * (positions.max() - positions.min() + 1) or clear.size < 3:
        return None
    slope, offset = np.polyfit(clear.astype(np.float64), body_extent[clear], 1)
    beyond = t > slope * station + offset + MARGIN_SHARE * width
    cut = np.zeros_like(mask)
    cut[all_rows[beyond], all_cols[beyond]] = True
    return cut
