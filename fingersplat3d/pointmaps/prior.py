"""The ``prior`` backend: a finger-surface pointmap from one image's silhouette, no weights.

A distal phalanx is close to a *generalised cylinder*: a cross-section (wider than high) swept
along a nearly straight axis, shrinking over the fingertip cap. Seen from the side, each slice
perpendicular to the axis projects to a chord of the silhouette whose length is the slice's
width, and the visible half of the slice rises above that chord like a half ellipse. So:

1. the silhouette is the view's mask when given, else :func:`~fingersplat3d.segment.masks.finger_mask`;
2. the finger axis is the silhouette's principal direction (PCA of its pixels);
3. at every 1-pixel station along the axis, the chord across the silhouette gives a half-width
   ``w(s)`` and a centre ``c(s)``; chords cut by the image border are completed from their
   neighbours (the finger goes on beyond the frame); both are median-filtered along the axis and
   ``w^2`` is fitted by local quadratics (no 1-px terraces; exact on an ellipsoidal cap);
4. a point above ``(s, t)`` (along, across the axis) has the relief
   ``h = depth_ratio * sqrt(w(s)^2 - (t - c(s))^2)``: exact for any cross-section shape scaled
   uniformly along the axis (a cylinder, and an ellipsoidal tip cap, rounded in both directions);
5. that relief is ray cast through the guessed pinhole, focal ``f = focal_factor * max(W, H)`` and
   principal point at the image centre (see :func:`finger_height`: off-axis rays see round the
   finger's side and over its tip, and the outline's rays graze each section in front of its
   widest line, so the section is the ellipse they touch, not the chord's), and depth is
   ``z = f - h`` (so near the finger one unit is about one pixel; units are arbitrary and the global
   alignment refines focal and scale), points ``X = z K^-1 [u, v, 1]``;
6. confidence is the facing ratio of the modelled surface, ``n_z = 1 / sqrt(1 + |grad h|^2)``,
   ramped to 1 at ``confidence_knee``: 1 over the frontal part of the finger, small at the
   silhouette rim and the fingertip, where depth is steepest and a pixel of outline error costs
   the most depth; 0 outside the mask, finite everywhere.

What a single silhouette cannot show is a tilt of the finger toward the camera (pitch, and the
shear of a rolled section); it shows up as a ramp in the depth error, which the global
alignment's smooth per-view correction takes up where two views see the skin, not where one alone
does. Registered views show the pitch (:mod:`~fingersplat3d.align.axis_tilt`): the pointmaps are
drawn again with each view's depth gradient along the image (``view_tilts``), the surface's depth
ramped about the silhouette's median pixel. The defaults, and this model against
distance-transform inflation, are measured in ``tools/bench_prior.py`` on synthetic ground truth.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import ClassVar, NamedTuple, Sequence

import numpy as np

from ..errors import InputError
from ..scene import View
from ..segment.masks import finger_mask
from ..segment.side_cut import side_cut_widths
from ..segment.silhouette import (Sections, WidthReference, along_axis, axis_coordinates, capture_finger_axes,
                                  chord_sections, finger_axis, mask_pixels)
from .base import Pointmap, register_backend

__all__ = ["PriorBackend", "FingerHeight", "finger_height", "height_to_points", "tilted_height"]

PERSPECTIVE_ITERATIONS = 8  # fixed-point steps of the perspective ray cast (max change < 0.3 px after 8)
MAX_RELIEF = 0.9  # relief cap, in focal lengths: keeps every point in front of the camera
MAX_TILT = 5.0  # a depth gradient beyond this (a finger within 11 degrees of end on) is not a finger's pitch
CONFIDENCE_FLOOR = 0.01  # every mask pixel keeps a point: confidence > 0 inside the mask


class FingerHeight(NamedTuple):
    """The inflated silhouette of one view."""

    height: np.ndarray  # [H, W] float32, pixels of relief toward the camera, 0 outside the mask (below 0 at a rim
    # behind the section's widest line: the flank facing away from the image centre, in perspective)
    confidence: np.ndarray  # [H, W] float32 in [0, 1], 0 outside the mask
    axis: np.ndarray  # [2] unit (du, dv) direction of the finger axis in the image


@dataclass(frozen=True)
class PriorBackend:
    """Silhouette-prior pointmaps (see the module docstring)."""

    name: ClassVar[str] = "prior"

    focal_factor: float = 3.0
    """Focal guess in units of the long image side. Contactless finger cameras frame the finger
    closely (~30-40 mm across the long side at 100-150 mm): 2.5-5 x max(W, H); 3 sits in that range.
    The depth relief is scale-free, so this mostly sets the perspective of the back-projection."""
    depth_ratio: float = 0.95
    """Visible relief over half the silhouette width. Human finger sections are wider than high
    (height/width ~0.76-0.88) with the pad fuller than the nail side (~53-60 % of the height), so
    the pad half seen from the front rises ~0.8-1.05 half-widths. Measured (3D error after a
    similarity fit, ``tools/bench_prior.py``): best at 0.95 for frontal, 45-degree and rolled views
    alike; the global alignment's relief factor corrects the rest per view."""
    smoothing: float = 0.15
    """Length of the along-axis filters of the chord widths and centres (median, then local
    quadratic), as a fraction of the finger's median width; 0 turns them off."""
    perspective: bool = True
    """Ray cast the relief through the guessed pinhole (see :func:`finger_height`); False: orthographic."""
    confidence_knee: float = 0.8
    """Facing ratio ``n_z`` at and above which the confidence is 1; below it, it falls linearly.
    Measured: the depth error (after scale, shift and tilt) grows about as ``1 / n_z``, from
    0.04 mm where ``n_z > 0.9`` to 0.1 mm at 0.5 and 0.3 mm at the rim, so a confidence
    proportional to ``n_z`` weighs residuals by their expected accuracy; ~2/3 of a finger's
    pixels face the camera better than 0.8 and get 1."""

    focal_px: float | None = None
    """The cameras' focal length in pixels when it is known (``fs3d fuse --focal-px``); it replaces the guess."""
    view_focals_px: tuple[float, ...] | None = None
    """Each view's focal length in its pixels, when known view by view (photos taken at other zooms, whose EXIF
    records each); it replaces ``focal_px`` and the guess."""
    view_tilts: tuple[tuple[float, float] | None, ...] | None = None
    """Each view's depth gradient along its image ``(d depth / du, d depth / dv)`` (units per pixel at the depth of one
    focal; None: level), from the registered cameras' finger axis (:func:`~fingersplat3d.align.axis_tilt.view_tilts`)."""

    def __post_init__(self) -> None:
        checks = [(name, getattr(self, name), low, high, low_allowed) for name, low, high, low_allowed in
                  (("focal_factor", 0.0, math.inf, False), ("depth_ratio", 0.0, math.inf, True),
                   ("smoothing", 0.0, math.inf, True), ("confidence_knee", 0.0, 1.0, False))]
        if self.focal_px is not None:
            checks.append(("focal_px", self.focal_px, 0.0, math.inf, False))
        if self.view_focals_px is not None:
            checks += [(f"view_focals_px[{i}]", f, 0.0, math.inf, False) for i, f in enumerate(self.view_focals_px)]
        for i, tilt in enumerate(self.view_tilts or ()):
            checks += [] if tilt is None else [(f"view_tilts[{i}][{k}]", g, -MAX_TILT, MAX_TILT, True)
                                               for k, g in enumerate(tilt)]
        for field_name, value, low, high, low_allowed in checks:
            # a number, not text that reads as one ("3" would repeat a string where the focal multiplies)
            number = float(value) if isinstance(value, numbers.Real) and not isinstance(value, bool) else math.nan
            if not (math.isfinite(number) and (number >= low if low_allowed else number > low) and number <= high):
                interval = f"{'[' if low_allowed else '('}{low:g}, {'inf)' if high == math.inf else f'{high:g}]'}"
                raise InputError(f"prior backend: {field_name} must be a finite number in {interval}, got {value!r}")

    def predict_views(self, views: Sequence[View]) -> list[Pointmap]:
        """One own-frame pointmap per view, on the view's pixel grid; outlines the frame does not cut take the axis
        the views agree on (:func:`~fingersplat3d.segment.silhouette.capture_axes`), and chords the frame cuts along a
        view's side take their widths from the other views (:func:`~fingersplat3d.segment.side_cut.side_cut_widths`)."""
        from ..device import per_item  # here: importing the backend does not load torch

        masks = [self._mask(view) for view in views]
        axes = capture_finger_axes(masks)  # (axis, origin) per view, found once
        widths = side_cut_widths(masks, axes=[axis for axis, _ in axes])
        return per_item(lambda index: self._predict(index, views[index], masks[index], axes[index], widths[index]),
                        range(len(views)))

    @staticmethod
    def _mask(view: View) -> np.ndarray:
        if view.mask is None:
            return finger_mask(view.image, name=f"view {view.name!r}")
        if not view.mask.any():
            raise InputError(f"view {view.name!r}: the mask is empty")
        return view.mask

    def _predict(self, index: int, view: View, mask: np.ndarray, axis: tuple[np.ndarray, np.ndarray],
                 widths: WidthReference | None = None) -> Pointmap:
        if self.view_focals_px is not None:
            if index >= len(self.view_focals_px):
                raise InputError(f"prior backend: {len(self.view_focals_px)} view focals for view {index + 1}")
            focal = float(self.view_focals_px[index])
        else:
            focal = self.focal_px if self.focal_px is not None else self.focal_factor * max(view.width, view.height)
        relief = finger_height(mask, self.depth_ratio, self.smoothing, self.confidence_knee,
                               focal if self.perspective else None, widths=widths, axis=axis)
        tilt = self.view_tilts[index] if self.view_tilts is not None and index < len(self.view_tilts) else None
        height = relief.height if tilt is None else tilted_height(relief.height, mask, tilt)
        points = height_to_points(height, mask, focal)
        return Pointmap(index, points, relief.confidence, float(focal))


register_backend("prior", PriorBackend)


def height_to_points(height: np.ndarray, mask: np.ndarray, focal: float) -> np.ndarray:
    """Camera-frame points ``[H, W, 3]`` float32 for depth ``z = focal - height`` (NaN off the mask).

    The reference depth ``z0 = focal`` puts the finger where one unit is about one pixel; the
    relief is shrunk by ``z0 / focal = 1``. Principal point at ``((W - 1) / 2, (H - 1) / 2)``.
    A relief beyond ``0.9 * focal`` (a finger closer than its own thickness: only reachable with
    focal guesses far below the image size) is capped there, so every point stays in front.
    """
    rows, cols = height.shape
    depth = np.where(mask, focal - np.minimum(height, MAX_RELIEF * focal), np.nan).astype(np.float32)
    x = (np.arange(cols, dtype=np.float32) - (cols - 1) / 2.0) / np.float32(focal)
    y = (np.arange(rows, dtype=np.float32) - (rows - 1) / 2.0) / np.float32(focal)
    points = np.empty((rows, cols, 3), np.float32)
    np.multiply(depth, x[None, :], out=points[..., 0])
    np.multiply(depth, y[:, None], out=points[..., 1])
    points[..., 2] = depth
    return points


def tilted_height(height: np.ndarray, mask: np.ndarray, gradient: Sequence[float]) -> np.ndarray:
    """``height`` (relief toward the camera, pixels) of a surface whose depth also grows by ``gradient`` (units per
    pixel along u and v) from the mask's median pixel: the swept surface with its axis tilted in depth. Off the mask,
    as it was."""
    mask = np.asarray(mask, bool)
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return height
    ramp = np.zeros(mask.shape, np.float64)
    ramp[rows, cols] = gradient[0] * (cols - np.median(cols)) + gradient[1] * (rows - np.median(rows))
    return np.where(mask, height - ramp, height).astype(height.dtype)


def finger_height(mask: np.ndarray, depth_ratio: float = 0.95, smoothing: float = 0.15,
                  confidence_knee: float = 0.8, focal: float | None = None, hint: np.ndarray | None = None,
                  widths: WidthReference | None = None,
                  axis: tuple[np.ndarray, np.ndarray] | None = None) -> FingerHeight:
    """Relief (pixels) and confidence of a finger silhouette under the swept-section model.

    With ``focal`` (pixels) the relief is ray cast in perspective: the model is the swept
    surface whose sections are centred on the image plane moved out to ``z0 = focal``, each the
    ellipse that the outline's two rays graze (:func:`tangent_sections`), and pixel ``p``'s ray
    meets it where :func:`ray_section_relief` says, across the finger in closed form, along it
    at the station ``s_c + (s - s_c) * (1 - h / focal)`` by fixed-point iteration (``c`` the
    principal point at the image centre): off the optical axis the camera sees round the
    finger's side and over its tip. Without ``focal`` the relief is orthographic, the chords
    the sections' widest lines. ``hint``: :func:`~fingersplat3d.segment.silhouette.finger_axis`'s;
    ``widths``: the chord half-widths the capture's other views give where the frame cuts this one along its side
    (:func:`~fingersplat3d.segment.side_cut.side_cut_widths`); ``axis``: ``finger_axis(mask, hint)`` when the caller
    has it already.
    """
    mask = np.asarray(mask, bool)
    rows, cols = mask.shape
    u, v, on_border = mask_pixels(mask)
    axis, origin = finger_axis(mask, hint) if axis is None else axis
    normal = np.array([-axis[1], axis[0]])
    s, t = axis_coordinates(u, v, axis, origin)  # along and across the axis, for the mask pixels only
    sections = chord_sections(s, t, on_border, smoothing, along_axis(widths, origin, axis))
    if focal is None:
        relief = sections.height(s, t) * depth_ratio
    else:
        centre = np.array([(cols - 1) / 2.0, (rows - 1) / 2.0]) - origin
        s_c, t_c = float(centre @ axis), float(centre @ normal)
        sections = tangent_sections(sections, depth_ratio, focal, t_c)
        slope = (t - t_c) / focal
        relief = np.zeros(s.shape)
        for _ in range(PERSPECTIVE_ITERATIONS):
            shrink = 1.0 - np.minimum(relief, MAX_RELIEF * focal) / focal
            relief = ray_section_relief(sections, s_c + (s - s_c) * shrink, t, slope, depth_ratio)
    height = np.zeros((rows, cols), np.float32)
    height[v, u] = relief
    return FingerHeight(height, _confidence(height, mask, confidence_knee), axis)


def tangent_sections(sections: Sections, ratio: float, focal: float, t_c: float) -> Sections:
    """The sections whose outline rays are tangent to them in perspective (a chord's ends are rays that graze the
    finger, not its widest line).

    Per station, the section is the ellipse of half-width ``a`` and depth ``ratio * a`` centred on the plane
    ``z = focal`` (pixel units there); the ray through across-coordinate ``e`` has slope ``m = (e - t_c) / focal``
    and grazes the ellipse where ``e - c = ±a sqrt(1 + ratio^2 m^2)``. Both chord ends on tangent rays give
    ``a = (e2 - e1) / (S1 + S2)`` and ``c = e1 + a S1``, ``S = sqrt(1 + ratio^2 m^2)``: narrower than the chord by
    about ``ratio^2 m^2 / 2`` (1.5 % for a finger 600 px wide at a 1660 px focal), and moved toward the image centre.
    Orthographic (``focal`` -> inf), the chord itself."""
    low = sections.centre - sections.half_width
    high = sections.centre + sections.half_width
    s_low = np.sqrt(1.0 + (ratio * (low - t_c) / focal) ** 2)
    s_high = np.sqrt(1.0 + (ratio * (high - t_c) / focal) ** 2)
    half_width = (high - low) / (s_low + s_high)
    return Sections(sections.start, half_width, low + half_width * s_low)


def ray_section_relief(sections: Sections, s: np.ndarray, t: np.ndarray, slope: np.ndarray,
                       ratio: float) -> np.ndarray:
    """Relief (pixels toward the camera from the plane ``z = focal``) where the ray of across-coordinate ``t`` and
    across slope ``slope`` first meets the section at station ``s``: the nearer root of
    ``((d - m h) / a)^2 + (h / (ratio a))^2 = 1``, ``d = t - c(s)``, written without cancellation as
    ``h = ratio (ratio d m + sqrt(a^2 (1 + ratio^2 m^2) - d^2)) / (1 + ratio^2 m^2)``. A ray that passes the
    section by less than the outline's quantisation takes its tangent point (the square root held at 0); off the
    sections' ends, 0. Negative on the flank that faces away from the image centre (its rim lies behind the
    widest line). At ``slope`` 0 it is ``ratio * sqrt(a^2 - d^2)``."""
    station = s - sections.start
    half, centre = sections.at(s)
    d = t - centre
    k2m2 = (ratio * slope) ** 2
    root = np.sqrt(np.maximum(half * half * (1.0 + k2m2) - d * d, 0.0))
    relief = ratio * (ratio * d * slope + root) / (1.0 + k2m2)
    outside = (station < -0.5) | (station > sections.half_width.size + 0.5)
    return np.where(outside, 0.0, relief)


def _confidence(height: np.ndarray, mask: np.ndarray, knee: float) -> np.ndarray:
    """Facing ratio of the relief surface, ramped to 1 at ``knee``; floor inside, 0 outside."""
    grad_v, grad_u = np.gradient(height) if min(height.shape) > 1 else (np.zeros_like(height),) * 2
    facing = 1.0 / np.sqrt(1.0 + grad_u * grad_u + grad_v * grad_v)
    ramp = np.clip(facing / knee, CONFIDENCE_FLOOR, 1.0) if knee > 0 else np.ones_like(facing)
    return np.where(mask, ramp, 0.0).astype(np.float32)
