"""A check of the solved turns against the silhouettes: how far apart two views must at least be turned.

Turning about a finger cannot narrow its silhouette faster than a flat board narrows: a section of
half-width ``w_a`` seen from view a shows at least ``w_a cos(turn)`` to a view turned by ``turn``
about the finger, *when the two rims view a sees lie at one depth* (its chord faces view a: true of
the section's widest view, and of any view square to a section symmetric about its pad). So the
narrower of two views' half-widths, in scene units, bounds their turn from below: ``turn >=
acos(w_narrow / w_wide)`` (less a tolerance for how well silhouettes are measured). It is a bound
for that case, not for every convex section: when the wider view is itself oblique to a flat
section, its chord is tilted and the narrower view may be turned less. So only the capture's widest
view, the one nearest the section's widest extent, bounds its turns to the others; a pair of two
other views gets no bound. Measured on another group's flat finger (nine rolls): every pair bounded
from the widest view (the 0-degree one) holds, while bounding every pair had put -45 and -38 degrees
at least 18 apart (true 7), 23 and 47 at least 37 (true 24), and -45 and -18 at least 34 (true 27).

Why it is needed: where two views share little skin, the turn and the relief trade against each
other, and the alignment takes the relief from a round prior. On a flat finger the prior is too
round and the turn comes out too small: the curvature of the fit (``turn_uncertainty_deg``) need
not show it, but the silhouettes do. Measured: another group's renders of a flat finger
(half-width 180 px at roll 0, 130 px at +-47) put two of its 45-degree turns at 23 and 37 degrees,
which the widths bound at >= 38 and >= 45; on the nine real dev captures every pair is 6 degrees
or more inside its bound. Pure numpy.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..segment.silhouette import SilhouetteFrame, capture_axes, silhouette_frame

__all__ = ["typical_half_width", "turn_lower_bounds_deg", "least_turns_deg", "WIDTH_TOLERANCE"]

WIDTH_TOLERANCE = 0.02
"""How much wider the narrower view is taken to be than measured (masks and chord medians are good to ~1-2 %):
at small turns the bound is steep (a 1 % narrower silhouette bounds a turn at 8 degrees, 4 % at 16), and a bound
read from noise would push right turns apart. Measured on another group's crops: with no tolerance, triplets
13-23 degrees apart moved from <= 0.2 to <= 1.4 degrees off."""


def typical_half_width(mask: np.ndarray, hint: np.ndarray | None = None) -> float:
    """The median chord half-width (pixels) over the middle half of a finger silhouette (no tip cap, no cut end);
    ``hint``: the axis of an outline the frame does not cut (:func:`~fingersplat3d.segment.silhouette.capture_axes`)."""
    return _middle_median(silhouette_frame(mask, hint=hint).sections.half_width)


def _middle_median(width: np.ndarray) -> float:
    count = width.size
    return float(np.median(width[count // 4:max(count - count // 4, count // 4 + 1)]))


def turn_lower_bounds_deg(half_widths_px: Sequence[float], depths: Sequence[float], focals: Sequence[float]) -> np.ndarray:
    """``[N, N]`` degrees: the least turn between the widest view and each other view that their silhouette
    half-widths allow (see the module); NaN for a pair of two other views.

    ``depths``: each view's typical depth of the finger (its silhouette's scale, scene units per
    focal length); ``focals`` in pixels. NaN where a width or depth is not finite and positive.
    """
    width = np.asarray(half_widths_px, np.float64) * np.asarray(depths, np.float64) / np.asarray(focals, np.float64)
    width = np.where(np.isfinite(width) & (width > 0), width, np.nan)
    bounds = np.full((len(width), len(width)), np.nan)
    if not np.isfinite(width).any():
        return bounds
    widest = int(np.nanargmax(width))
    turn = np.degrees(np.arccos(np.clip((1.0 + WIDTH_TOLERANCE) * width / width[widest], 0.0, 1.0)))
    bounds[widest, :], bounds[:, widest] = turn, turn
    return bounds


def least_turns_deg(masks: Sequence[np.ndarray], depths: Sequence[np.ndarray], focals: Sequence[float],
                    frames: Sequence[SilhouetteFrame] | None = None) -> np.ndarray:
    """:func:`turn_lower_bounds_deg` of views given their finger masks and depth maps (the median depth over each
    mask is its scale); ``frames``: the masks' silhouette frames with the capture's axis hints, when the caller has
    them (a registration keeps them), else made here."""
    typical = []
    for mask, depth in zip(masks, depths):
        inside = depth[mask & np.isfinite(depth)]
        typical.append(float(np.median(inside)) if inside.size else float("nan"))
    if frames is None:
        frames = [silhouette_frame(mask, hint=hint) for mask, hint in zip(masks, capture_axes(masks))]
    return turn_lower_bounds_deg([_middle_median(frame.sections.half_width) for frame in frames], typical, focals)
