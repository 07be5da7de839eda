"""A finger silhouette as a swept section: its axis, tip, and chord width and centre along the axis.

A distal phalanx is close to a *generalised cylinder*: a cross-section swept along a nearly
straight axis, shrinking over the fingertip cap. Its silhouette is described by

* the axis: the line between the frame's two cuts on a crop cut at both ends, else the principal
  direction of the mask pixels (:func:`finger_axis`: a crop shorter along the finger than across it
  keeps its axis), or on crops cut inside the frame the way along which the capture's views agree in
  length (:func:`capture_axes`), oriented toward the
  fingertip (the end of the silhouette that the image border does not cut; on a crop cut at both
  ends, the end the finger narrows toward, agreed over all views of a capture; see
  :func:`silhouette_frame` and :func:`orient_frames`);
* at every 1-pixel station ``s`` along the axis, the chord across the silhouette: half-width
  ``w(s)`` and centre ``c(s)`` in the across coordinate ``t``; chords cut by the image border are
  completed from their neighbours (the finger goes on beyond the frame), or where the border cuts a view along its
  side from the capture's other views (:mod:`fingersplat3d.segment.side_cut`), both are median filtered
  and ``w^2`` is fitted by local quadratics (no 1-px terraces; exact on an ellipsoidal cap).

Used by the ``prior`` pointmap backend (relief from the chords) and by the cylinder charts of
:mod:`fingersplat3d.align.correspond.chart` (surface coordinates from the chords). Pure numpy/scipy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import cv2
import numpy as np
from scipy.ndimage import median_filter

__all__ = ["Sections", "SilhouetteFrame", "principal_axis", "finger_axis", "capture_axes", "capture_finger_axes", "chord_sections",
           "silhouette_frame", "orient_frames", "along_axis", "raw_chords", "WidthReference", "local_quadratic",
           "widest_disc", "outline_swell", "OUTLINE_SWELL", "mask_pixels", "axis_coordinates", "TIP_BASES",
           "SIDE_CUT_WIDTHS"]

TIP_BASES = {
    "outline": "the outline closes at this end and the image border cuts the other",
    "taper": "neither end is told apart by the outline; the finger narrows toward this end",
    "other views": "neither end is told apart by the outline; this end points the way of the tip in the other views",
}
"""How the tip end of a silhouette was chosen (:attr:`SilhouetteFrame.tip_basis`), in words."""
SIDE_CUT_WIDTHS = "the frame cuts this view along its side: its widths there were taken from the other views"
"""What ``report.json`` says of a view whose chords took their widths from the others (:attr:`SilhouetteFrame.widths_from_views`)."""


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


CUT_DOMINANCE = 2.0
"""An image edge cuts the finger (:func:`finger_axis`) when it holds this many times as many of the mask's pixels as
each edge that does not."""
ALONG_SIDE = 0.5
""":func:`finger_axis`: where the mask lies along two adjacent image edges, each over this share of its own extent that
way (its pixels on the left or right edge against its rows' extent, on the top or bottom against its columns'), the
frame cuts the finger along a side as well as across: a tight crop or a close-up the finger fills across its width,
cut along one flank or both and at its base. The frame's cuts then say nothing of the axis (the long flank outweighs
the base's cut, and two cut flanks read as a crop cut at both ends), and the mask keeps its principal direction:
real dev side views cropped to 0.8 of the finger's width about the image centre had their axes taken across the
finger, every chart vote of theirs lost (docs/measurements.md, stop 104). A fingertip entering the frame, or a crop
cut at both ends, lies along no two adjacent edges so (no mask of IMPOSE's renders, the real dev views whole or cut
to no tip, or the shipped samples does); a fingertip entering at a corner and lying along the second edge over half
its depth is taken by its principal direction too."""


OUTLINE_SWELL = 1.3
"""A finger's widest chord across its axis is at most this many times its median one; a mask wider somewhere holds
something beside the finger. Measured (docs/measurements.md, stop 88), masks found on the photos: the real dev frames
1.03-1.16 (54), another group's renders 1.05-1.11, ``fs3d synth`` views 1.01-1.19 (uwa, adult and wide shapes, and
cfpose: 66), the shipped samples 1.03-1.11, phone-like photos of another make 1.04-1.10 where the mask is right, and
1.38-3.18 where it kept clutter touching the finger (IoU 0.45-0.91; 1.24 at IoU 0.97 passes)."""
_MIN_WHOLE_CHORDS = 16  # fewer chords across the whole finger than this say nothing of its width


def mask_pixels(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A mask's pixels: their columns ``u``, rows ``v`` and whether each lies on the image border (where the frame,
    not the finger's outline, ends a chord)."""
    rows, cols = mask.shape
    v, u = np.nonzero(mask)
    return u, v, (u == 0) | (v == 0) | (u == cols - 1) | (v == rows - 1)


def axis_coordinates(u: np.ndarray, v: np.ndarray, axis: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels' coordinates from ``origin`` along ``axis`` (``s``) and across it (``t``, along the axis turned by +90
    degrees in the image: x right, y down)."""
    du, dv = u - origin[0], v - origin[1]
    return du * axis[0] + dv * axis[1], du * -axis[1] + dv * axis[0]


def outline_swell(mask: np.ndarray) -> float | None:
    """The widest chord across the finger's axis over the median one, over the chords the image border does not cut
    (:func:`raw_chords` along :func:`finger_axis`); None when fewer than half of them are whole. A finger narrows
    toward its tip and widens a little toward its base; a patch of something else joined to it makes one stretch much wider
    (:data:`OUTLINE_SWELL`)."""
    mask = np.asarray(mask, bool)
    if mask.sum() < 64:
        return None
    axis, origin = finger_axis(mask)
    u, v, on_border = mask_pixels(mask)
    s, t = axis_coordinates(u, v, axis, origin)
    low, high, present, cut_low, cut_high = raw_chords(s, t, on_border, float(s.min()))
    whole = present & ~cut_low & ~cut_high
    if whole.sum() < max(_MIN_WHOLE_CHORDS, 0.5 * present.sum()):  # a finger the frame cuts along its side: its
        return None  # whole chords are the tip's, narrower than the finger
    widths = (high - low)[whole] + 1.0
    return float(widths.max() / np.median(widths))


def widest_disc(mask: np.ndarray) -> float:
    """Diameter (pixels) of the widest disc inside ``mask``, the image border not counting as its edge: the finger's
    width, whether the frame cuts it or not (on a crop cut at both ends shorter along the finger than across it, the
    mask's box is shorter than the finger is wide). 0 for an empty mask or one with no edge in the frame."""
    padded = np.pad(np.asarray(mask, bool), 1, mode="edge").astype(np.uint8)  # the border continues the mask
    if not padded.any() or padded.all():
        return 0.0
    return 2.0 * float(cv2.distanceTransform(padded, cv2.DIST_L2, 5).max())


def finger_axis(mask: np.ndarray, hint: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unit axis direction of a finger mask and the centroid of its pixels (x axis when undefined).

    A finger that the frame cuts at two opposite edges (a crop cut at both ends) runs from the middle of one cut to the
    middle of the other, whatever the crop's shape: a crop cut shorter along the finger than across it has its
    longest direction across the finger, and a short crop of an inclined finger has it far off the finger. Otherwise
    the axis is the principal direction of the pixels (:func:`principal_axis`), unless the frame cuts the finger at
    one edge and that direction runs more than 45 degrees off the way from the cut's middle to the centroid (a
    fingertip entering the frame less far than it is wide): the axis is then that way. The frame's cuts are the edges
    holding :data:`CUT_DOMINANCE` times as many mask pixels as any other edge; a finger whole in the frame, or cut at
    two adjacent edges (or lying along both, :data:`ALONG_SIDE`: a finger filling the frame), keeps its principal
    direction. ``hint``: for a mask the frame does not cut, the axis the capture's views agree on
    (:func:`capture_axes`), taken instead of the principal direction. The sign is arbitrary (see
    :func:`silhouette_frame`).
    """
    mask = np.asarray(mask, bool)
    v, u = np.nonzero(mask)
    axis, centre = principal_axis(u, v)
    if u.size < 2:
        return axis, centre
    by_frame = _frame_axis(u, v, mask.shape, axis, centre)
    if by_frame is not None:
        return by_frame, centre
    if hint is not None and float(np.linalg.norm(hint)) > 0:
        return np.asarray(hint, np.float64) / float(np.linalg.norm(hint)), centre
    return axis, centre


def _on_edges(u: np.ndarray, v: np.ndarray, shape: tuple[int, int]) -> list[np.ndarray]:
    """Which of the pixels ``(u, v)`` lie on the image's top, bottom, left and right edge."""
    rows, cols = shape
    return [v == 0, v == rows - 1, u == 0, u == cols - 1]


def _frame_axis(u: np.ndarray, v: np.ndarray, shape: tuple[int, int], axis: np.ndarray, centre: np.ndarray) -> np.ndarray | None:
    """The axis the frame's cuts give (:func:`finger_axis`), None where they give none (no cut, or a principal direction
    that already runs within 45 degrees of the way in from a single cut)."""
    edges = _on_edges(u, v, shape)  # top, bottom, left, right: opposite ones paired
    counts = np.array([int(edge.sum()) for edge in edges])
    along = counts >= ALONG_SIDE * (np.array([np.ptp(u), np.ptp(u), np.ptp(v), np.ptp(v)]) + 1)
    if along[:2].any() and along[2:].any():
        return None  # two adjacent edges cut along the mask (a finger filling the frame): its principal direction holds

    def cuts(chosen: list[int]) -> bool:
        others = [counts[i] for i in range(4) if i not in chosen]
        return bool(counts[chosen].min() > 0 and counts[chosen].min() >= CUT_DOMINANCE * max(others))

    def middle(i: int) -> np.ndarray:
        return np.array([u[edges[i]].mean(), v[edges[i]].mean()])

    for pair in ([0, 1], [2, 3]):
        through = middle(pair[1]) - middle(pair[0]) if cuts(pair) else np.zeros(2)
        if float(np.linalg.norm(through)) >= 1.0:  # (a one-pixel strip is cut by both edges at once)
            return through / np.linalg.norm(through)
    for i in range(4):
        inward = centre - middle(i) if cuts([i]) else np.zeros(2)
        length = float(np.linalg.norm(inward))
        if length >= 1.0 and abs(float(np.dot(axis, inward))) < np.sqrt(0.5) * length:
            return inward / length  # the longest direction is more than 45 degrees off the way in
    return None


AXES_AGREEMENT_DEG = 20.0
""":func:`capture_axes`: the uncut views' outlines must run one way within this (up to a quarter turn), as cameras
turned about a finger, or a finger rolled before one camera, see its axis one way in every view."""
EXTENT_STEADINESS = 2.0
""":func:`capture_axes`: the views' lengths along the axis taken vary this many times less than across it."""
MIN_EXTENT_SPREAD = 0.02
""":func:`capture_axes`: the least spread (standard deviation of the log lengths) of the varying direction: below it
the views' outlines say nothing (a round section, views seen alike)."""


def capture_axes(masks: Sequence[np.ndarray]) -> list[np.ndarray | None]:
    """Per view of one capture, the axis its uncut outline is given (:func:`finger_axis`'s ``hint``), or None.

    A crop cut straight across at both ends *inside* the frame (a finger cut out on a black background) may be
    shorter along the finger than across it, and no outline alone tells its ends from its sides. A capture does:
    cut across the finger, every view shows the same stretch of it, so its length along the finger is the same in
    every view, while the width across it changes with the view as the section turns (wider than high).

    So when two or more views are uncut by the frame and their outlines run one way (:data:`AXES_AGREEMENT_DEG`, up
    to a quarter turn), each view's length along their mean direction and across it is measured from the middle of
    one end to the middle of the other (:func:`_end_to_end`). The direction whose lengths stay steadier over the views
    by :data:`EXTENT_STEADINESS` (the other's spreading by at least :data:`MIN_EXTENT_SPREAD`) runs along the finger.
    An uncut view whose own principal direction runs more than :data:`AXES_AGREEMENT_DEG` off its line between the
    ends that way (across the finger, or along a near-square crop's diagonal) takes that line for its axis, as a
    crop takes the line between the frame's cuts; the others keep theirs. Otherwise (one uncut view, views seen
    alike, outlines that run different ways) no view gets one.
    """
    hints: list[np.ndarray | None] = [None] * len(masks)
    free = []
    for index, mask in enumerate(masks):
        mask = np.asarray(mask, bool)
        v, u = np.nonzero(mask)
        if u.size < 16:
            continue
        axis, centre = principal_axis(u, v)
        if any(edge.any() for edge in _on_edges(u, v, mask.shape)):
            continue  # the frame cuts it: its own cuts say more
        free.append((index, axis, _outline(mask, centre)))
    if len(free) < 2:
        return hints
    # Each view's outline direction up to a quarter turn (along the finger or across it: the tangents' 4 theta
    # averaged; a near-square crop's principal direction can run along its diagonal), then theirs averaged alike.
    angles = np.array([np.angle(np.exp(4j * np.arctan2(tangents[:, 1], tangents[:, 0])).sum()) / 4.0
                       for _, _, (_, tangents) in free])
    mean = float(np.angle(np.exp(4j * angles).sum())) / 4.0
    off = np.abs((angles - mean + np.pi / 4.0) % (np.pi / 2.0) - np.pi / 4.0)
    if off.max() > np.radians(AXES_AGREEMENT_DEG):
        return hints
    first, second = np.array([np.cos(mean), np.sin(mean)]), np.array([-np.sin(mean), np.cos(mean)])
    spans = [[_end_to_end(*outline, d) for d in (first, second)] for _, _, outline in free]
    lengths = np.array([[float(np.linalg.norm(span)) + 1.0 for span in pair] for pair in spans])
    spread_first, spread_second = np.std(np.log(lengths), axis=0)
    if max(spread_first, spread_second) < MIN_EXTENT_SPREAD:
        return hints
    if spread_first * EXTENT_STEADINESS <= spread_second:
        along = 0  # the first direction's extent holds steady over the views: the finger runs along it
    elif spread_second * EXTENT_STEADINESS <= spread_first:
        along = 1
    else:
        return hints
    for (index, axis, _), pair in zip(free, spans):
        length = float(np.linalg.norm(pair[along]))
        if length >= 1.0 and abs(float(axis @ pair[along])) < np.cos(np.radians(AXES_AGREEMENT_DEG)) * length:
            hints[index] = pair[along] / length  # its longest direction runs across the finger, or along a diagonal
    return hints


END_TANGENT = 0.5
""":func:`_end_to_end`: an outline point belongs to an end when its tangent runs within 30 degrees of across the
direction (the cosine between them below this)."""


def capture_finger_axes(masks: Sequence[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each view's :func:`finger_axis` ``(unit direction, centroid)``, an outline the frame does not cut taking the axis
    the capture's views agree on (:func:`capture_axes`): the axes the prior sweeps its sections along."""
    masks = [np.asarray(mask, bool) for mask in masks]
    return [finger_axis(mask, hint) for mask, hint in zip(masks, capture_axes(masks))]


def _outline(mask: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The outer outline of a mask's largest piece, ``[K, 2]`` (u, v) about ``centre``, and its unit tangents (over
    a hundredth of its length either way, three pixels at least)."""
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    points = max(contours, key=len)[:, 0, :].astype(np.float64)
    step = max(3, len(points) // 100)
    tangent = np.roll(points, -step, axis=0) - np.roll(points, step, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    return points - centre, tangent


def _end_to_end(points: np.ndarray, tangents: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """From the middle of a mask's end toward ``-direction`` to the middle of its end toward ``direction``: each end the
    outline points on its side whose tangent runs across ``direction`` (:data:`END_TANGENT`), so a straight cut is
    one whatever its skew, and the line between them is the finger's axis as the frame's two cuts give it
    (:func:`finger_axis`). Zero when either end has no such point."""
    across = np.abs(tangents @ direction) < END_TANGENT
    s = points @ direction
    low, high = across & (s < 0), across & (s > 0)
    if not (low.any() and high.any()):
        return np.zeros(2)
    return points[high].mean(0) - points[low].mean(0)


def chord_sections(s: np.ndarray, t: np.ndarray, on_border: np.ndarray, smoothing: float,
                   expected: Callable[[np.ndarray], np.ndarray] | None = None) -> Sections:
    """Per-station (1 px along the axis) chord half-width and centre, completed and smoothed.

    ``expected``: the half-widths the capture's other views give at stations ``s`` (NaN where they give none,
    :func:`~fingersplat3d.segment.side_cut.side_cut_widths`); a chord the frame cuts takes it where given, and its neighbours' otherwise."""
    s0 = float(s.min())
    low, high, present, cut_low, cut_high = raw_chords(s, t, on_border, s0)
    count = low.size
    with np.errstate(invalid="ignore"):  # stations with no chord hold inf bounds: NaN there, as meant
        half_width = np.where(present, 0.5 * (high - low) + 0.5, np.nan)  # +0.5: pixels have extent
        centre = np.where(present, 0.5 * (high + low), np.nan)
    whole = present & ~cut_low & ~cut_high
    cut = present & ~whole
    stations = np.arange(count)
    if cut.any() and whole.any():
        # Complete the width from the nearest whole chords (or the other views') and keep the seen end where it is
        # (a chord cut at both ends takes its centre from its neighbours too).
        completed = np.interp(stations[cut], stations[whole], half_width[whole])
        if expected is not None:
            given = np.asarray(expected(s0 + stations[cut] + 0.5), np.float64)
            completed = np.where(np.isfinite(given), given, completed)
        half_width[cut] = np.maximum(completed, half_width[cut])
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
            half_width = np.sqrt(np.maximum(local_quadratic(half_width ** 2, window), 0.25))
            centre = local_quadratic(centre, window)
    return Sections(s0, half_width, centre)


def raw_chords(s: np.ndarray, t: np.ndarray, on_border: np.ndarray, s0: float):
    """Per 1-px station from ``s0``: the chord's lowest and highest ``t``, whether it has pixels, and whether the image
    border cuts its low or high end (the frame's cut, not the finger's outline)."""
    index = np.floor(s - s0).astype(np.int64)
    count = int(index.max()) + 1
    low = np.full(count, np.inf)
    high = np.full(count, -np.inf)
    np.minimum.at(low, index, t)
    np.maximum.at(high, index, t)
    present = np.isfinite(low)
    border_low = np.full(count, np.inf)
    border_high = np.full(count, -np.inf)
    np.minimum.at(border_low, index[on_border], t[on_border])
    np.maximum.at(border_high, index[on_border], t[on_border])
    return low, high, present, present & (border_low <= low + 1.0), present & (border_high >= high - 1.0)


def local_quadratic(values: np.ndarray, window: int) -> np.ndarray:
    """Savitzky-Golay smoothing of order 2 over an odd ``window`` (<= ``len(values)``), the ends taken from the quadratic
    fitted to the first and last windows: ``scipy.signal.savgol_filter(values, window, 2, mode="interp")``.

    Written here because importing ``scipy.signal`` (it pulls ``scipy.stats``) cost 0.8 s of every command's start;
    ``tests/test_silhouette.py`` checks it against scipy's.
    """
    values = np.asarray(values, np.float64)
    half = window // 2
    offsets = np.arange(-half, half + 1, dtype=np.float64)
    weights = np.linalg.pinv(np.vander(offsets, 3, increasing=True))[0]  # the fitted quadratic's value at the centre
    out = np.empty_like(values)
    out[half:len(values) - half] = np.convolve(values, weights[::-1], mode="valid")
    ends = np.arange(window, dtype=np.float64)
    out[:half] = np.polyval(np.polyfit(ends, values[:window], 2), ends[:half])
    out[len(values) - half:] = np.polyval(np.polyfit(ends, values[-window:], 2), ends[window - half:])
    return out


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
    """Whether one end was told apart as the tip by the outline (False: both or neither end is cut
    by the border; the tip is then the end the finger narrows toward, or the other views' way)."""
    taper: float = 0.0
    """How much the chord narrows toward the tip over the silhouette's length, as a share of its
    median width (straight line fitted to the middle 80 % of stations; ~0.2 on a distal phalanx)."""
    tip_basis: str = "outline"
    """Which rule chose the tip end: a key of :data:`TIP_BASES`."""
    widths_from_views: bool = False
    """Whether the frame cuts this view along its side and its chords there took their widths from the capture's
    other views (:func:`~fingersplat3d.segment.side_cut.side_cut_widths`)."""

    @property
    def tip_side(self) -> str:
        """The image side the tip points to: ``top``, ``bottom``, ``left`` or ``right``."""
        du, dv = self.axis
        if abs(dv) >= abs(du):
            return "top" if dv < 0 else "bottom"
        return "left" if du < 0 else "right"

    def coordinates(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Axis ``s`` and across ``t`` coordinates of pixels ``uv [..., 2]``."""
        offset = np.asarray(uv, np.float64) - self.origin
        return offset @ self.axis, offset @ self.normal

    def pixels(self, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Pixels ``[..., 2]`` at axis and across coordinates ``s``, ``t``."""
        s, t = np.asarray(s, np.float64), np.asarray(t, np.float64)
        return self.origin + s[..., None] * self.axis + t[..., None] * self.normal


def _taper(sections: Sections) -> float:
    """Narrowing of the chord toward increasing ``s`` over the whole length, per median width (the
    middle 80 % of stations: the ends of a crop cut askew are slivers, not the finger's width)."""
    width = sections.half_width
    count = width.size
    low, high = count // 10, count - count // 10
    if high - low < 3:
        return 0.0
    slope = np.polyfit(np.arange(low, high, dtype=np.float64), width[low:high], 1)[0]
    return float(-slope * count / max(float(np.median(width)), 1e-9))


def silhouette_frame(mask: np.ndarray, smoothing: float = 0.15, toward: np.ndarray | None = None,
                     hint: np.ndarray | None = None, widths: WidthReference | None = None) -> SilhouetteFrame:
    """The axis frame and chord sections of a finger mask (see the module docstring).

    The tip is the end of the silhouette whose last stations do not touch the image border. When
    both or neither touch (a crop cut at both ends, a finger wholly in frame), it is the end that
    ``toward`` (an image direction) points to when given, else the end the chords narrow toward
    (a distal phalanx tapers by ~20 % to its tip). The axis points to the tip (increasing ``s``). The
    sign of the axis fixes the sign of ``normal``, so two views of one finger from cameras turned
    about it get frames that agree: their surface angles (:mod:`fingersplat3d.align.correspond.chart`)
    differ by the turn. ``hint``: the axis of an outline the frame does not cut, from the capture's views
    (:func:`capture_axes`); ``widths``: the chord half-widths the capture's other views give where the frame cuts
    this one along its side (:func:`~fingersplat3d.segment.side_cut.side_cut_widths`).
    """
    mask = np.asarray(mask, bool)
    u, v, on_border = mask_pixels(mask)
    axis, origin = finger_axis(mask, hint)

    def chords(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray, Sections]:
        normal = np.array([-direction[1], direction[0]])
        s, t = axis_coordinates(u, v, direction, origin)
        return s, normal, chord_sections(s, t, on_border, smoothing, along_axis(widths, origin, direction))

    s, normal, sections = chords(axis)
    end = max(2.0, 0.01 * float(np.ptp(s)))
    cut_low = bool(np.any(on_border & (s < s.min() + end)))
    cut_high = bool(np.any(on_border & (s > s.max() - end)))
    tip_found = cut_low != cut_high
    taper = _taper(sections)
    if tip_found:
        flip, basis = cut_high, "outline"  # the high end is cut by the frame: the tip is at the low end
    elif toward is not None:
        flip, basis = float(np.dot(axis, toward)) < 0.0, "other views"
    else:
        flip, basis = taper < 0.0, "taper"
    if flip:
        axis = -axis
        s, normal, sections = chords(axis)
        taper = -taper
    return SilhouetteFrame(axis, normal, origin, sections, float(s.max()) + 0.5, tip_found, taper, basis, widths is not None)


def orient_frames(masks: list[np.ndarray], smoothing: float = 0.15) -> list[SilhouetteFrame]:
    """The frames of the views of one capture, their tips agreeing wherever one view cannot tell.

    A view whose outline shows the tip keeps it. The others point their axes the way of the tip in
    the views that show it; when none does (a capture of crops cut at both ends), the way the views'
    tapers agree on, each weighted by how clearly it tapers. Cameras turned about a finger see its
    axis the same way round, and one view's taper can be lost in the noise of its outline where the
    capture's is not. Outlines the frame does not cut take the axis the views agree on (:func:`capture_axes`).
    A view the frame cuts along its side keeps its own widths here (see
    :func:`~fingersplat3d.segment.side_cut.capture_frames`).
    """
    hints = capture_axes(masks)
    frames = [silhouette_frame(mask, smoothing, hint=hint) for mask, hint in zip(masks, hints)]
    seen = [frame for frame in frames if frame.tip_found]
    if len(seen) == len(frames):
        return frames
    toward = sum(frame.axis for frame in seen) if seen else sum(frame.axis * abs(frame.taper) for frame in frames)
    if float(np.linalg.norm(toward)) < 1e-9:
        return frames
    oriented = []
    for mask, frame, hint in zip(masks, frames, hints):
        if frame.tip_found or (not seen and float(np.dot(frame.axis, toward)) > 0.0):
            oriented.append(frame)  # its own outline or its own taper already agrees
        else:
            oriented.append(silhouette_frame(mask, smoothing, toward=toward, hint=hint))
    return oriented


WidthReference = Callable[[np.ndarray], np.ndarray]
"""Pixels ``uv [N, 2]`` on a view's axis -> the chord half-widths expected there (NaN where none is known)."""


def along_axis(widths: WidthReference | None, origin: np.ndarray, axis: np.ndarray) -> Callable[[np.ndarray], np.ndarray] | None:
    """``widths`` read at axis coordinates ``s`` of a frame (``origin + s * axis``), for :func:`chord_sections`."""
    if widths is None:
        return None
    return lambda s: widths(np.asarray(origin, np.float64) + np.asarray(s, np.float64)[:, None] * np.asarray(axis, np.float64))
