"""The working resolution: the geometry runs at a set number of pixels per ridge period, whatever the photo's size.

Ridges are what the registration matches and what the splat fit reproduces, so what sets their accuracy is how
finely the ridges are sampled, not how many pixels the camera has. A photo that samples them much more finely (a
20-megapixel camera, an upscaled crop) is scaled down before the masks, the pointmaps, the registration and the
alignment (to :data:`RIDGE_PX`), and for the splat fit to its own :data:`SPLAT_RIDGE_PX` (the geometry needs fewer
pixels than the ridges' look); the outputs (cameras, depth maps, masks) are put back onto the photo's own pixel grid.
``docs/measurements.md`` ("Working resolution") measures the rule.

* The finger mask is found on a *survey* copy of at most :data:`SURVEY_SIDE` pixels: the mask's morphology uses
  discs that grow with the image, so its cost grows with about the fourth power of the side.
* The ridge period is measured on that copy, or, where the copy samples the ridges too coarsely to trust
  (:data:`FINE_BELOW_PX`) or the finger is too small on it to give tiles off its rims (:data:`SMALL_FINGER_PX`), on a
  crop of the finger at the photo's own resolution.
* ``factor = ridge_px / period`` (at most 1), one for every view of a capture (views that share a finger share
  its ridges); a factor above :data:`MIN_SHRINK` is not worth a resampling and stays 1, and no view's short side
  goes below :data:`MIN_SIDE`.
* A photo that is another's shrunk (the same sides' ratio, fewer pixels, and its ridges as much narrower: a camera set
  to a smaller size, a copy made smaller to send) is taken for the largest photo's camera at that size, its field of
  view the same and its focal in its own pixels as much smaller (:func:`resized_growth`): it is worked on grown to the
  largest photo's pixels, so that the views share one focal in working pixels. Taken as it is, a photo at half the
  others' size was left out (exit 3: its ridges half as wide and its focal half theirs, where the fit holds one for
  all). A photo cut about its centre at the same ratio keeps the others' ridges and focal, and is taken as it is.
* A photo larger than the survey copy whose finger covers little of it (a phone's photo) is first cut to a window
  about its centre round the finger (:mod:`fingersplat3d.working_window`, ``windows=True``): the principal point
  stays at the image's centre, so the cameras are the whole photo's.

Pixel centres are at integer coordinates (``Camera.from_focal`` puts the principal point at ``(W - 1) / 2``), so a
working pixel ``x`` is the photo's ``(x + 0.5) * W / w - 0.5``, as OpenCV's resizing has it.

Pure numpy/OpenCV: no Open3D, no files.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import cv2
import numpy as np

from .align.correspond.texture import measure_ridge_period, ridge_area
from .errors import InputError
from .sampling import resized_image, resized_mask
from .scene import View, scaled_size
from .working_window import Window, finger_window

__all__ = ["RIDGE_PX", "SPLAT_RIDGE_PX", "TUNED_PX_PER_RIDGE", "SURVEY_SIDE", "MIN_SHRINK", "MIN_SIDE", "WorkingScale",
           "resized_growth", "working_views"]

RIDGE_PX = 12.0
"""Default working pixels per ridge period of the geometry (masks, pointmaps, registration, alignment). The real
captures sample their ridges at 14-16 px at 1280x1024; measured at stop 75 (docs/measurements.md, "Working resolution"):
at 12 px per ridge (their coarser-sampled ones, over 15 px, scaled by ~0.76; the others kept, :data:`MIN_SHRINK`) the
rig's consistency is the photos' own resolution's or better (every pair's median 0.78 deg either way; the held-out
finger 1.06 / 1.16 / 1.36 against 1.25 / 1.12 / 1.36 deg), the crops without a tip the same, the ``--rig`` check
(finger 1's rig against finger 2's, stop 76) 0.38 / 0.37 / 0.09 against 0.38 / 0.42 / 0.07 deg, the geometry of a
scaled capture ~20 % faster; at 8 px per ridge (``--ridge-px 8``, a third faster) it costs 0.91 deg against 0.78. On
synthetic fingers nothing measurable at either."""
SPLAT_RIDGE_PX = 16.0
"""Default working pixels per ridge period of the splat fit, its own (``--splat-ridge-px``): with the geometry at fewer
(:data:`RIDGE_PX`, ``--ridge-px 8``) the fit still sees the ridges as the camera sampled them, so that renders and
prints keep them."""
TUNED_PX_PER_RIDGE = 16.0
"""Pixels per ridge period of the real captures the alignment's robust scale (1 px) was tuned on (14-16); a
scaled capture's robust scale keeps that share of a period (half a pixel at 8 px per ridge)."""
SURVEY_SIDE = 1280
"""Long side (pixels) at most of the copy the masks and the first ridge period are found on."""
FINE_BELOW_PX = 6.0
"""A ridge period below this on the survey copy is measured again on a photo-resolution crop of the finger."""
SMALL_FINGER_PX = 192
"""A finger narrower than this on the survey copy (two of the period's 96-px tiles) is measured on the crop as well:
its one or two tiles reach its rims, where shading can pass for a period above :data:`FINE_BELOW_PX`."""
CROP_SIDE = 1024
"""Side (pixels) at most of that crop."""
MIN_SHRINK = 0.8
"""A factor above this keeps the photo's own resolution (a resampling would cost more than it saves)."""
MIN_SIDE = 256
"""A view's short side is never scaled below this many pixels."""
RESIZED_ASPECT = 0.01
"""Photos whose short-to-long side ratios differ by less than this (relative) may be one camera's at two sizes."""
RESIZED_MIN = 1.02
"""A photo this much smaller than the largest (long side) or more is taken for it shrunk: below, the same size (a
few pixels cut off by a converter)."""
MASK_SIDE_MAX = 2560
"""Above the survey size and up to this long side, the working copy gets its own mask (sharper edges than the
survey's, at ~1 s); above it, the survey's mask is resized."""


@dataclass(frozen=True)
class WorkingScale:
    """How a capture's photos were scaled for the geometry."""

    factor: float
    """Working pixels per photo pixel (1: the photo's own grid)."""
    period_px: float
    """The finger's ridge period in photo pixels (median over the views)."""
    ridge_px: float | None
    """The pixels per ridge asked for (None: the photo's own resolution)."""
    view_periods_px: tuple[float, ...] = ()
    """Each view's ridge period in photo pixels (NaN: no ridges measured; empty: not measured)."""
    surveyed_whole: bool = False
    """Whether every view's survey copy was the photo itself (photos of at most :data:`SURVEY_SIDE` px)."""
    windows: tuple[Window | None, ...] = ()
    """Each view's working window on its photo (None, or empty: the whole photo; :mod:`fingersplat3d.working_window`)."""
    growth: tuple[float, ...] = ()
    """Each view's photo grown by this on top of :attr:`factor` (:func:`resized_growth`: a photo that is the largest
    one's shrunk; empty: 1 for every view)."""

    def grown(self, index: int) -> float:
        return self.growth[index] if index < len(self.growth) else 1.0

    @property
    def regrown(self) -> bool:
        """Whether any view's photo is grown onto the largest one's pixels."""
        return any(g != 1.0 for g in self.growth)

    def view_factor(self, index: int) -> float:
        """View ``index``'s working pixels per photo pixel."""
        return self.factor * self.grown(index)

    def window(self, index: int) -> Window | None:
        return self.windows[index] if index < len(self.windows) else None

    @property
    def windowed(self) -> bool:
        return any(window is not None for window in self.windows)

    def region_sizes(self, sizes: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
        """The part of each photo of ``sizes`` the geometry works on, in photo pixels: its window, or the photo."""
        return [size if self.window(i) is None else self.window(i).size for i, size in enumerate(sizes)]

    def working_view_periods_px(self) -> tuple[float, ...] | None:
        """Each view's ridge period in working pixels when it was measured exactly as the later stages measure it
        (on the working images themselves: every view measured, photos kept as they are), else None."""
        periods = np.asarray(self.view_periods_px, np.float64)
        if (self.factor != 1.0 or self.regrown or not self.surveyed_whole or not periods.size
                or not np.isfinite(periods).all()):
            return None
        return tuple(float(p) for p in periods)

    def working_period_px(self) -> float | None:
        """The capture's ridge period in working pixels (the median of :meth:`working_view_periods_px`), or None."""
        periods = self.working_view_periods_px()
        return None if periods is None else float(np.median(periods))

    def at(self, ridge_px: float | None, sizes: Sequence[tuple[int, int]]) -> "WorkingScale":
        """The same photos at another number of working pixels per ridge (None: their own resolution)."""
        grown = [scaled_size(size, self.grown(i)) for i, size in enumerate(self.region_sizes(sizes))]
        return WorkingScale(_factor(self.period_px, ridge_px, grown), self.period_px, ridge_px, self.view_periods_px,
                            self.surveyed_whole, self.windows, self.growth)

    def size(self, size: tuple[int, int], index: int) -> tuple[int, int]:
        """View ``index``'s working size, its photo (or window) of ``size``."""
        factor = self.view_factor(index)
        return size if factor == 1.0 else scaled_size(size, factor)

    def as_report(self, photo_sizes: Sequence[tuple[int, int]]) -> dict:
        report = {"factor": round(self.factor, 4),
                  "ridge_period_photo_px": round(self.period_px, 2) if np.isfinite(self.period_px) else None,
                  "ridge_px_asked": self.ridge_px,
                  "sizes": [list(self.size(size, i)) for i, size in enumerate(self.region_sizes(photo_sizes))]}
        if self.regrown:  # each view's photo grown onto the largest one's pixels (1: as it is)
            report["photos_grown"] = [round(self.grown(i), 4) for i in range(len(photo_sizes))]
        if self.windowed:  # [left, top, width, height] in photo pixels, None for a photo worked on whole
            report["windows"] = [None if self.window(i) is None else self.window(i).as_report()
                                 for i in range(len(photo_sizes))]
        return report


@dataclass(frozen=True)
class _Survey:
    """One view's survey copy: its scale, its image and the finger mask on it (the photo's own when it has one)."""

    factor: float
    image: np.ndarray
    mask: np.ndarray


def _survey(view: View) -> _Survey:
    from .segment.masks import finger_mask

    factor = min(1.0, SURVEY_SIDE / max(view.width, view.height))
    size = scaled_size((view.width, view.height), factor)
    image = resized_image(view.image, size)
    if view.mask is not None:
        return _Survey(factor, image, resized_mask(view.mask, size))
    return _Survey(factor, image, finger_mask(image, name=f"view {view.name!r}"))


def _photo_period(view: View, survey: _Survey) -> float:
    """The view's ridge period in photo pixels, from its survey copy or a photo-resolution crop of the finger;
    NaN when neither shows ridges."""
    factor, mask = survey.factor, survey.mask
    period = measure_ridge_period(survey.image, mask)
    if factor == 1.0:
        return float("nan") if period is None else period
    seen = period is not None and period >= FINE_BELOW_PX
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return float("nan")
    if seen and min(np.ptp(rows), np.ptp(cols)) + 1 >= SMALL_FINGER_PX:
        return period / factor
    # the crop's centre: the ridges' (the finger's distal part, where its outline shows the tip), away from the rims; a
    # long finger's middle, as a phone's photo shows it from far back, is skin without ridges whose pixel noise and
    # creases gave periods of 3-40 px where the ridges are 13 (docs/measurements.md, stop 89)
    ridges = ridge_area(mask)
    rows, cols = np.nonzero(ridges if ridges.any() else mask)
    centre = np.array([np.median(cols), np.median(rows)]) / factor
    half = CROP_SIDE // 2
    left = int(np.clip(centre[0] - half, 0, max(0, view.width - CROP_SIDE)))
    top = int(np.clip(centre[1] - half, 0, max(0, view.height - CROP_SIDE)))
    width, height = min(CROP_SIDE, view.width - left), min(CROP_SIDE, view.height - top)
    if view.mask is not None:
        crop_mask = view.mask[top:top + height, left:left + width]
    else:  # the survey mask carried up onto the crop only
        crop_mask = _survey_mask_on(mask, (factor, factor), (left, top), (1.0, 1.0), (width, height))
    fine = measure_ridge_period(view.image[top:top + height, left:left + width], crop_mask)
    if fine is not None:
        return fine
    return period / factor if seen else float("nan")


def _survey_mask_on(mask: np.ndarray, survey_per_photo: tuple[float, float], corner: tuple[int, int],
                    grid_per_photo: tuple[float, float], size: tuple[int, int]) -> np.ndarray:
    """A survey copy's ``mask`` carried onto a grid of ``size`` = (width, height) that covers the photo from its pixel
    ``corner`` = (left, top) at ``grid_per_photo`` grid pixels per photo pixel (x, y); ``survey_per_photo``: the survey
    copy's pixels per photo pixel (x, y). Grid pixel x is photo pixel ``(x + 0.5) / g - 0.5 + left``, and photo pixel x
    is survey pixel ``(x + 0.5) s - 0.5``; linear, cut at one half."""
    (sx, sy), (left, top), (gx, gy) = survey_per_photo, corner, grid_per_photo
    onto_survey = np.array([[sx / gx, 0.0, sx * (0.5 / gx + left) - 0.5], [0.0, sy / gy, sy * (0.5 / gy + top) - 0.5]])
    return cv2.warpAffine(mask.astype(np.float32), onto_survey, size, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP) > 0.5


def _factor(period_px: float, ridge_px: float | None, sizes: Sequence[tuple[int, int]]) -> float:
    if ridge_px is None or not np.isfinite(period_px) or period_px <= 0:
        return 1.0
    factor = max(ridge_px / period_px, max(MIN_SIDE / min(size) for size in sizes))
    return 1.0 if factor > MIN_SHRINK else float(factor)


def resized_growth(sizes: Sequence[tuple[int, int]], periods: Sequence[float] | None = None) -> tuple[float, ...]:
    """Each photo of ``sizes`` (width, height) grown by this onto the largest one's pixels: the largest photo's long
    side over its own where the two have one sides' ratio (:data:`RESIZED_ASPECT`; either way up) and it is at least
    :data:`RESIZED_MIN` smaller, else 1. Empty where every photo stays as it is.

    ``periods``: each photo's ridge period in its own pixels (NaN: not measured). A photo cut from a larger one about
    its centre at the same sides' ratio (a crop, its focal in pixels the larger one's) has that size too, but its ridges
    as wide as the others': a smaller photo is taken for shrunk only where its ridges are nearer the others' shrunk by
    its size than the others' as they are (in ratio), and its ridges and theirs were measured. Grown by its size, a
    real side view cut to 0.75 about its centre had turned 2.2-3.3 degrees off (docs/measurements.md, stop 106)."""
    if len(set(sizes)) <= 1:
        return ()
    largest = max(sizes, key=lambda size: size[0] * size[1])
    ratio = min(largest) / max(largest)
    growth = [max(largest) / max(size) if abs(min(size) / max(size) / ratio - 1.0) < RESIZED_ASPECT
              and max(largest) / max(size) >= RESIZED_MIN else 1.0 for size in sizes]
    if periods is not None:
        periods = np.asarray(periods, np.float64)
        whole = [p for p, g in zip(periods, growth) if g == 1.0 and np.isfinite(p) and p > 0]
        for v, (g, period) in enumerate(zip(growth, periods)):
            if g == 1.0:
                continue
            if not whole or not (np.isfinite(period) and period > 0):
                growth[v] = 1.0  # nothing to tell a shrunk photo from a cut one by: taken as it is, as before
                continue
            seen = float(np.median(whole)) / period  # how much wider the others' ridges are than this photo's
            growth[v] = g if abs(np.log(seen / g)) < abs(np.log(seen)) else 1.0
    return tuple(growth) if any(g != 1.0 for g in growth) else ()


def working_views(views: Sequence[View], ridge_px: float | None = RIDGE_PX, factor: float | None = None,
                  windows: bool | Sequence[Window | None] = False, growth: tuple[float, ...] | None = None
                  ) -> tuple[list[View], list[View], WorkingScale]:
    """``(photo views, working views, scale)``: both with finger masks (the photos' own where given).

    ``ridge_px``: working pixels per ridge period (None: the photos' own resolution); ``factor``: a scale to use
    instead of measuring one (a rig calibration scales all its captures alike); ``windows``: True cuts each photo
    larger than :data:`SURVEY_SIDE` to its finger's window where that keeps little of it
    (:func:`~fingersplat3d.working_window.finger_window`), or each view's window to use (None: the whole photo);
    ``growth``: each photo's growth onto the largest one's pixels to use instead of finding it (:func:`resized_growth`:
    the splat fit's grid takes the geometry's).
    """
    if ridge_px is not None and not (np.isfinite(ridge_px) and ridge_px > 0):
        raise InputError(f"pixels per ridge must be a positive number, got {ridge_px}")
    from .device import per_item  # here, not at the top: the CLI reads this module's defaults without loading torch

    surveys = per_item(_survey, views)
    for view, survey in zip(views, surveys):
        if survey.mask.sum() < 16:
            raise InputError(f"view {view.name!r}: the finger mask has only {int(survey.mask.sum())} pixels")
    sizes = [(view.width, view.height) for view in views]
    if windows is True:
        windows = _finger_windows(surveys, sizes)
    windows = tuple(windows) if windows else ()
    period, periods = float("nan"), []  # not measured when nothing depends on it
    if ridge_px is not None or (growth is None and resized_growth(sizes)):  # views without ridges do not vote
        periods = per_item(lambda pair: _photo_period(*pair), list(zip(views, surveys)))
    growth = resized_growth(sizes, periods) if growth is None else tuple(growth)
    if ridge_px is not None:  # none measured at all: the photos as they are
        grown = np.asarray(periods) * np.asarray(growth or [1.0] * len(views))  # in the largest photo's pixels
        period = float(np.nanmedian(grown)) if np.isfinite(grown).any() else float("nan")
    scale = WorkingScale(1.0, period, ridge_px, tuple(float(p) for p in periods),
                         all(survey.factor == 1.0 for survey in surveys), windows, growth)
    factor = scale.at(ridge_px, sizes).factor if factor is None else factor
    scale = replace(scale, factor=float(factor))

    def both(index: int) -> tuple[View, View]:
        view, survey, window, factor = views[index], surveys[index], scale.window(index), scale.view_factor(index)
        if window is not None:
            return _windowed(view, survey, window, factor)
        size = scale.size((view.width, view.height), index)
        same = size == (survey.image.shape[1], survey.image.shape[0])  # the survey copy is the working one
        image = survey.image if same else resized_image(view.image, size)
        if view.mask is not None:
            mask = resized_mask(view.mask, size)
        elif factor > survey.factor and max(size) <= MASK_SIDE_MAX:
            from .segment.masks import finger_mask

            mask = finger_mask(image, name=f"view {view.name!r}")
        else:
            mask = resized_mask(survey.mask, size)
        photo_mask = view.mask if view.mask is not None else resized_mask(
            mask if factor >= survey.factor else survey.mask, (view.width, view.height))
        photo = view.with_(mask=photo_mask)
        return photo, (photo if factor == 1.0 else View(view.name, image, mask))

    pairs = per_item(both, range(len(views)))
    photo, working = [p for p, _ in pairs], [w for _, w in pairs]
    return photo, working, scale


def _finger_windows(surveys: Sequence[_Survey], sizes: Sequence[tuple[int, int]]) -> tuple[Window | None, ...]:
    """Each view's window (:func:`~fingersplat3d.working_window.finger_window`) on photos larger than the survey copy:
    photos of one size share one, round all their fingers (one working size for all: one focal in working pixels is
    one in photo pixels for every view, to the pixel's rounding)."""
    if len(set(sizes)) == 1 and len({survey.mask.shape for survey in surveys}) == 1:
        if max(sizes[0]) <= SURVEY_SIDE:
            return ()
        union = np.logical_or.reduce([survey.mask for survey in surveys])
        return (finger_window(union, sizes[0]),) * len(sizes)
    return tuple(finger_window(survey.mask, size) if max(size) > SURVEY_SIDE else None
                 for survey, size in zip(surveys, sizes))


def _windowed(view: View, survey: _Survey, window: Window, factor: float) -> tuple[View, View]:
    """``(photo view, working view)`` of a view worked on in ``window``: the working image is the window's part of the
    photo at ``factor``; its mask the photo's own cut to the window, else found again on the working copy where the
    whole photo's would be (:func:`working_views`), else the survey copy's carried onto it; the photo's mask the
    working one put back in the window, nothing outside it."""
    size = scaled_size(window.size, factor) if factor != 1.0 else window.size
    image = resized_image(window.cut(view.image), size)
    if view.mask is not None:
        return view, View(view.name, image, resized_mask(window.cut(view.mask), size))
    if factor > survey.factor and max(scaled_size((view.width, view.height), factor)) <= MASK_SIDE_MAX:
        from .segment.masks import finger_mask  # found again on the working copy, as the whole photo's would be

        mask = finger_mask(image, name=f"view {view.name!r}")
        return view.with_(mask=window.padded(resized_mask(mask, window.size), fill=False)), View(view.name, image, mask)
    mask = _survey_mask_on(survey.mask, (survey.mask.shape[1] / view.width, survey.mask.shape[0] / view.height),
                           (window.left, window.top), (size[0] / window.width, size[1] / window.height), size)
    photo_mask = window.padded(resized_mask(mask, window.size), fill=False)
    return view.with_(mask=photo_mask), View(view.name, image, mask)
