"""A finger silhouette as a swept section: its axis, tip, and chord width and centre along the axis.

A distal phalanx is close to a *generalised cylinder*: a cross-section swept along a nearly
straight axis, shrinking over the fingertip cap. Its silhouette is described by

* the axis: the principal direction of the mask pixels, oriented toward the fingertip (the end
  of the silhouette that the image border does not cut; see :func:`silhouette_frame`);
* at every 1-pixel station ``s`` along the axis, the chord across the silhouette: half-width
  ``w(s)`` and centre ``c(s)`` in the across coordinate ``t``; chords cut by the image border are
  completed from their neighbours (the finger goes on beyond the frame), both are median filtered
  and ``w^2`` is fitted by local quadratics (no 1-px terraces; exact on an ellipsoidal cap).

Used by the ``prior`` pointmap backend (relief from the chords) and by the cylinder charts of
:mod:`fingersplat3d.align.correspond.chart` (surface coordinates from the chords). Pure numpy/scipy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter
from scipy.signal import savgol_filter

__all__ = ["Sections", "SilhouetteFrame", "principal_axis", "chord_sections", "silhouette_frame"]


@dataclass(frozen=True, eq=False)
class Sections:
    """The swept section: chord half-width and centre per 1-px station along the axis."""

    start: float  # s at the start of station 0
    half_width: np.ndarray  # [N] pixels
    centre: np.ndarray  # [N] t of the chord centre

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Half-width and centre ``w(s)``, ``c(s)`` (linear between stations, clamped at the ends)."""
        knots = np.arange(self.half_width.size) + 0.5
        station = s - self.start
        return np.interp(station, knots, self.half_width), np.interp(station, knots, self.centre)

    def height(self, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Unit-ratio relief ``sqrt(w(s)^2 - (t - c(s))^2)``, 0 off the section (pixels)."""
        station = s - self.start
        w, c = self.at(s)
        outside = (station < -0.5) | (station > self.half_width.size + 0.5)
        return np.where(outside, 0.0, np.sqrt(np.maximum(w * w - (t - c) ** 2, 0.0)))


def principal_axis(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction of largest spread of the pixels and their centroid (x axis when undefined)."""
    centre = np.array([u.mean(), v.mean()])
    if u.size < 2:
        return np.array([1.0, 0.0]), centre
    du, dv = u - centre[0], v - centre[1]
    cov = np.array([[np.dot(du, du), np.dot(du, dv)], [np.dot(du, dv), np.dot(dv, dv)]]) / u.size
    values, vectors = np.linalg.eigh(cov)
    if values[1] - values[0] <= 1e-9 * max(values[1], 1e-12):
        return np.array([1.0, 0.0]), centre  # round blob: any direction is an axis
    return vectors[:, 1], centre


def chord_sections(s: np.ndarray, t: np.ndarray, on_border: np.ndarray, smoothing: float) -> Sections:
    """Per-station (1 px along the axis) chord half-width and centre, completed and smoothed."""
    s0 = float(s.min())
    index = np.floor(s - s0).astype(np.int64)
    count = int(index.max()) + 1
    low = np.full(count, np.inf)
    high = np.full(count, -np.inf)
    np.minimum.at(low, index, t)
    np.maximum.at(high, index, t)
    present = np.isfinite(low)
    # A chord end on the image border is cut by the frame, not by the finger's outline.
    border_low = np.full(count, np.inf)
    border_high = np.full(count, -np.inf)
    np.minimum.at(border_low, index[on_border], t[on_border])
    np.maximum.at(border_high, index[on_border], t[on_border])
    cut_low = present & (border_low <= low + 1.0)
    cut_high = present & (border_high >= high - 1.0)
    half_width = np.where(present, 0.5 * (high - low) + 0.5, np.nan)  # +0.5: pixels have extent
    centre = np.where(present, 0.5 * (high + low), np.nan)
    whole = present & ~cut_low & ~cut_high
    cut = present & ~whole
    stations = np.arange(count)
    if cut.any() and whole.any():
        # Complete the width from the nearest whole chords and keep the seen end where it is
        # (a chord cut at both ends takes its centre from its neighbours too).
        half_width[cut] = np.maximum(np.interp(stations[cut], stations[whole], half_width[whole]), half_width[cut])
        seen_high = cut & cut_low & ~cut_high
        seen_low = cut & cut_high & ~cut_low
        centre[seen_high] = high[seen_high] + 0.5 - half_width[seen_high]
        centre[seen_low] = low[seen_low] - 0.5 + half_width[seen_low]
        both = cut & cut_low & cut_high
        centre[both] = np.interp(stations[both], stations[whole], centre[whole])
    if not present.all():  # a thin diagonal mask can leave a station empty
        half_width = np.interp(stations, stations[present], half_width[present])
        centre = np.interp(stations, stations[present], centre[present])
    window = int(round(smoothing * 2.0 * float(np.median(half_width))))
    if window >= 3 and count >= 3:
        window = min(window | 1, count - (1 - count % 2))  # odd, at most the station count
        half_width = median_filter(half_width, size=window, mode="nearest")
        centre = median_filter(centre, size=window, mode="nearest")
        # Outline pixels quantise the chords into 1-px steps, which would print as depth terraces.
        # A local quadratic of w^2 removes them and is exact over an ellipsoidal cap (w^2 is
        # quadratic in s there) as well as over a straight or tapered body.
        if count > window:
            half_width = np.sqrt(np.maximum(savgol_filter(half_width ** 2, window, 2, mode="interp"), 0.25))
            centre = savgol_filter(centre, window, 2, mode="interp")
    return Sections(s0, half_width, centre)


@dataclass(frozen=True, eq=False)
class SilhouetteFrame:
    """A silhouette's axis frame: ``p = origin + s * axis + t * normal`` (pixels)."""

    axis: np.ndarray  # [2] unit (du, dv) along the finger, toward the tip
    normal: np.ndarray  # [2] unit, the axis turned by +90 degrees in the image (x right, y down)
    origin: np.ndarray  # [2] centroid of the mask pixels
    sections: Sections
    s_tip: float
    """Axis coordinate of the tip end of the silhouette."""
    tip_found: bool
    """Whether one end was told apart as the tip (False: both or neither end is cut by the border,
    and the axis keeps the direction of larger mask extent)."""

    def coordinates(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Axis ``s`` and across ``t`` coordinates of pixels ``uv [..., 2]``."""
        offset = np.asarray(uv, np.float64) - self.origin
        return offset @ self.axis, offset @ self.normal

    def pixels(self, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Pixels ``[..., 2]`` at axis and across coordinates ``s``, ``t``."""
        s, t = np.asarray(s, np.float64), np.asarray(t, np.float64)
        return self.origin + s[..., None] * self.axis + t[..., None] * self.normal


def silhouette_frame(mask: np.ndarray, smoothing: float = 0.15) -> SilhouetteFrame:
    """The axis frame and chord sections of a finger mask (see the module docstring).

    The tip is the end of the silhouette whose last stations do not touch the image border; when
    both or neither touch, the end with the narrower chords is taken. The axis points to the tip
    (increasing ``s``). The sign of the
    axis fixes the sign of ``normal``, so two views of one finger from cameras turned about it get
    frames that agree: their surface angles (:mod:`fingersplat3d.align.correspond.chart`) differ by the turn.
    """
    mask = np.asarray(mask, bool)
    rows, cols = mask.shape
    v, u = np.nonzero(mask)
    axis, origin = principal_axis(u, v)
    on_border = (u == 0) | (v == 0) | (u == cols - 1) | (v == rows - 1)

    def chords(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray, Sections]:
        normal = np.array([-direction[1], direction[0]])
        s = (u - origin[0]) * direction[0] + (v - origin[1]) * direction[1]
        t = (u - origin[0]) * normal[0] + (v - origin[1]) * normal[1]
        return s, normal, chord_sections(s, t, on_border, smoothing)

    s, normal, sections = chords(axis)
    end = max(2.0, 0.01 * float(np.ptp(s)))
    cut_low = bool(np.any(on_border & (s < s.min() + end)))
    cut_high = bool(np.any(on_border & (s > s.max() - end)))
    tip_found = cut_low != cut_high
    if tip_found:
        flip = cut_high  # the high end is cut by the frame: the tip is at the low end
    else:
        tail = max(1, sections.half_width.size // 10)
        flip = float(np.mean(sections.half_width[:tail])) < float(np.mean(sections.half_width[-tail:]))
    if flip:
        axis = -axis
        s, normal, sections = chords(axis)
    return SilhouetteFrame(axis, normal, origin, sections, float(s.max()) + 0.5, tip_found)
