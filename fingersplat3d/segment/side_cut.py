"""A finger the image border cuts along its side: its chords' widths there, from the capture's other views.

A chord the border cuts is completed from its whole neighbours
(:func:`~fingersplat3d.segment.silhouette.chord_sections`), which is right where the border cuts the finger across its end. Where it cuts a view along its side (a thick finger
filling a side view, a phone's close-up), the only whole chords left are the tip's cap and what the border spared, and
the completed widths come out narrow: the prior's relief too flat, the charts' surface angles wrong. Cameras turned
about a finger see one section at each distance from the tip, its width changing with the view by a ratio that holds
along the body, so another view's whole chords stand in (:func:`side_cut_widths`). Pure numpy.
"""
from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from .silhouette import (SilhouetteFrame, WidthReference, capture_axes, finger_axis, mask_pixels, orient_frames,
                         raw_chords, silhouette_frame)

__all__ = ["capture_frames", "side_cut_widths", "sides_cut_share", "SIDE_CUT_SHARE", "MIN_SHARED_STATIONS",
           "CAP_FALLBACK"]

SIDE_CUT_SHARE = 0.2
""":func:`side_cut_widths`: a view whose chords the image border cuts at one side over this share of its stations (a
finger the frame cuts along its side, not only across its end) takes its widths there from the other views."""
MIN_SHARED_STATIONS = 10
""":func:`side_cut_widths`: the whole chords (off the tip's cap) two views must share at one distance from the tip for
one's widths to stand in for the other's."""
CAP_FALLBACK = 0.1
""":func:`side_cut_widths`: where two views share fewer whole chords off the tip's cap than :data:`MIN_SHARED_STATIONS`
(a thick finger whose side the frame cuts from just behind its cap), the ratio is taken over the cap's whole chords
too, where both views' outlines close at the tip (a crop cut at both ends has no cap to compare), from this share of
a half-width behind the tip (the very tip's few pixels are too short to compare). On the cap the views' width ratio
lies within 3-6 % of the body's (``fs3d synth`` uwa, wide shapes, seed 4, zoomed out until no view is cut: a side
view against the other side's 0.95 on the cap, 0.98 on the body; against the front's 1.14 and 1.08), where the
chords completed from the cap alone come out 15-20 % narrow."""


def capture_frames(masks: list[np.ndarray], smoothing: float = 0.15) -> list[SilhouetteFrame]:
    """:func:`~fingersplat3d.segment.silhouette.orient_frames`, a view the frame cuts along its side taking its widths
    there from the others (:func:`side_cut_widths`; its frame's ``widths_from_views`` says so)."""
    frames = orient_frames(masks, smoothing)
    hints = capture_axes(masks)
    return [frame if reference is None else
            silhouette_frame(mask, smoothing, toward=frame.axis, hint=hint, widths=reference)
            for mask, frame, hint, reference in zip(masks, frames, hints, side_cut_widths(masks, frames, hints))]


def side_cut_widths(masks: Sequence[np.ndarray], frames: Sequence[SilhouetteFrame] | None = None,
                    hints: Sequence[np.ndarray | None] | None = None,
                    axes: Sequence[np.ndarray] | None = None) -> list[WidthReference | None]:
    """Per view of one capture, the chord half-widths the other views give it where the frame cuts it along its side.

    A finger the image border cuts along its side (a thick finger filling a side view, a phone's close-up) shows no
    chord whole there, and completed from the nearest whole ones (the tip's cap, a stretch the border spared) it comes
    out narrow: its relief too flat and its surface angles wrong, enough for a chart's first turn to miss by 30 degrees.
    Cameras turned about a finger see one section at each distance from the tip, its width changing with the view by
    a ratio that holds along the body (a section's shape changes slowly along it). So a view whose chords the frame
    cuts at one side over :data:`SIDE_CUT_SHARE` of its stations takes, at each cut station, another view's whole
    chord at the same distance from the tip times the two views' median ratio over the whole chords they share off the
    tip's cap (:data:`MIN_SHARED_STATIONS` at least; else over the cap's too where both outlines close at the tip,
    :data:`CAP_FALLBACK`; the median over the views that give one). None for a view that is not cut so, or that no
    other view can stand in for. A capture no view of which the border touches along its
    axis is answered before any frame is made or read. What the caller holds it passes: ``frames``
    (:func:`~fingersplat3d.segment.silhouette.orient_frames`'s), ``hints`` (:func:`capture_axes`'s) or ``axes`` (each
    view's :func:`finger_axis`; the frames' axes when they are given).
    """
    masks = [np.asarray(mask, bool) for mask in masks]
    if len(masks) < 2:
        return [None] * len(masks)
    if frames is not None:
        axes = [frame.axis for frame in frames]
    elif axes is None:
        hints = capture_axes(masks) if hints is None else hints
        axes = [finger_axis(mask, hint)[0] for mask, hint in zip(masks, hints)]
    if not any(_may_be_side_cut(mask, axis) for mask, axis in zip(masks, axes)):
        return [None] * len(masks)  # (the frames cost more than this look: a tenth of a second a view at 1280 px)
    frames = orient_frames(masks) if frames is None else frames
    profiles = [_station_profile(mask, frame) for mask, frame in zip(masks, frames)]
    references: list[WidthReference | None] = []
    for index, (frame, (sigma, width, whole, share)) in enumerate(zip(frames, profiles)):
        if share <= SIDE_CUT_SHARE:
            references.append(None)
            continue
        estimates = []
        for other, (sigma_o, width_o, whole_o, _) in enumerate(profiles):
            if other == index or not whole_o.any():
                continue
            given = _read_whole(sigma_o, width_o, whole_o, sigma)
            cap = float(np.median(width_o[whole_o]))  # the tip's cap is about a half-width long
            both = whole & np.isfinite(given)
            shared = both & (sigma > cap)
            if shared.sum() < MIN_SHARED_STATIONS and frame.tip_found and frames[other].tip_found:
                shared = both & (sigma > CAP_FALLBACK * cap)  # a cap to compare only where both outlines close at it
            if shared.sum() >= MIN_SHARED_STATIONS:
                estimates.append(float(np.median(width[shared] / given[shared])) * given)
        if not estimates:
            references.append(None)
            continue
        stacked = np.stack(estimates)
        known = np.isfinite(stacked).any(0)
        expected = np.full(sigma.size, np.nan)
        expected[known] = np.nanmedian(stacked[:, known], axis=0)
        references.append(_reference(frame, sigma, expected))
    return references


def sides_cut_share(mask: np.ndarray, frame: SilhouetteFrame) -> float:
    """The share of a view's stations along the finger whose chord the image border cuts at one side or both: the
    frame cutting the finger along its flanks (a tight crop, a close-up the finger fills across), not across its end
    (a finger leaving the frame at its base cuts a station or two). 0 for a view whose outline the frame does not touch
    along the finger (:func:`_may_be_side_cut`, read first: the stations cost more)."""
    mask = np.asarray(mask, bool)
    if not _may_be_side_cut(mask, frame.axis):
        return 0.0
    _, (_, _, present, cut_low, cut_high) = _frame_chords(mask, frame)
    return float((present & (cut_low | cut_high)).sum()) / max(int(present.sum()), 1)


def _frame_chords(mask: np.ndarray, frame: SilhouetteFrame) -> tuple[float, tuple]:
    """``(s0, raw_chords(...))``: the view's raw chords per 1-px station along its ``frame``'s axis from ``s0``."""
    u, v, on_border = mask_pixels(mask)
    s, t = frame.coordinates(np.stack([u, v], 1))
    s0 = float(s.min())
    return s0, raw_chords(s, t, on_border, s0)


def _may_be_side_cut(mask: np.ndarray, axis: np.ndarray) -> bool:
    """Whether the border pixels of ``mask`` on edges along its ``axis`` could cut half of :data:`SIDE_CUT_SHARE` of its
    stations (each border pixel of an edge at angle ``a`` to the axis cuts at most ``|cos a|`` of a station). Read from
    the image's four edges and the mask's outer outlines (the extremes along any direction lie on them), not from
    every pixel: this look runs on every capture."""
    if int(np.count_nonzero(mask)) < 16:
        return False
    top, bottom, left, right = (int(np.count_nonzero(edge)) for edge in (mask[0], mask[-1], mask[:, 0], mask[:, -1]))
    weighted = (top + bottom) * abs(float(axis[0])) + (left + right) * abs(float(axis[1]))
    if weighted == 0.0:
        return False
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    outline = np.concatenate([contour[:, 0, :] for contour in contours]).astype(np.float64)
    along = float(np.ptp(outline @ np.asarray(axis, np.float64))) + 1.0
    return weighted > 0.5 * SIDE_CUT_SHARE * along


def _station_profile(mask: np.ndarray, frame: SilhouetteFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A view's raw chords in its frame: each station's distance from the tip, half-width and whether it is whole, and
    the share of its stations the border cuts at one side only."""
    s0, (low, high, present, cut_low, cut_high) = _frame_chords(mask, frame)
    with np.errstate(invalid="ignore"):
        width = np.where(present, 0.5 * (high - low) + 0.5, np.nan)
    whole = present & ~cut_low & ~cut_high
    share = float((present & (cut_low != cut_high)).sum()) / max(int(present.sum()), 1)
    sigma = frame.s_tip - (s0 + np.arange(low.size) + 0.5)
    return sigma, width, whole, share


def _read_whole(sigma: np.ndarray, width: np.ndarray, whole: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``width`` at distances ``at`` from the tip, where the station nearest each is whole (NaN elsewhere)."""
    order = np.argsort(sigma)
    nearest = np.clip(np.round(np.interp(at, sigma[order], np.arange(sigma.size)[order])).astype(int), 0, sigma.size - 1)
    inside = (at >= sigma.min() - 0.5) & (at <= sigma.max() + 0.5)
    return np.where(inside & whole[nearest], width[nearest], np.nan)


def _reference(frame: SilhouetteFrame, sigma: np.ndarray, expected: np.ndarray) -> WidthReference:
    order = np.argsort(sigma)

    def widths(uv: np.ndarray) -> np.ndarray:
        s, _ = frame.coordinates(uv)
        return _read_whole(sigma[order], expected[order], np.isfinite(expected[order]), frame.s_tip - s)

    return widths
