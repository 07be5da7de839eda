"""The ridge texture of a finger photo, made comparable across views: period, glints, band-pass.

* :func:`estimate_ridge_period`: the dominant ridge period in pixels, as the weighted median over
  tiles of the finger of each tile's strongest spectral peak (a ridge tile has one sharp oriented
  peak; a radially averaged spectrum of the whole finger mixes ridge curvature, shading and
  creases, and on real photos lands on sub-harmonics).
* :func:`suppress_glints`: small specular highlights on skin (bright specks of a few pixels that
  move with the viewpoint) replaced by the local median, so they do not pull matches.
* :func:`ridge_texture`: a difference of Gaussians around the ridge frequency, normalised to unit
  local RMS, computed by normalised convolution inside the finger mask (no bright halo along the
  silhouette for a matcher to lock onto). Shading and exposure differences between views drop out.

Pure numpy/OpenCV: no Open3D, no files.
"""
from __future__ import annotations

import cv2
import numpy as np

from ...errors import InputError
from ...robust import robust_sigma
from ...segment.morphology import dilated, disc, eroded
from ...structure_tensor import masked_blur

__all__ = ["as_gray", "estimate_ridge_period", "measure_ridge_period", "ridge_area", "suppress_glints", "ridge_texture",
           "DEFAULT_PERIOD_PX", "MIN_RIDGES_ACROSS", "no_ridges"]

DEFAULT_PERIOD_PX = 8.0
"""Period returned when no ridge peak stands out (a featureless image)."""
MIN_RIDGES_ACROSS = 18.0
"""A finger is at least this many ridge periods wide: measured 28-48 on the real dev captures, the IMPOSE renders and
the synthetic samples (an adult finger 14-22 mm wide, ridges 0.4-0.55 mm apart). A coarser 'period' is the skin's
shading or blur, not ridges: a photo blurred beyond its ridges (σ 6 px on a 14 px period) reads 33 px on a finger
525 px wide (16 across)."""
_TILE = 96  # pixels per side of a spectrum tile (several ridge periods at any usual resolution)
_FFT = 256  # padded size of the tile spectrum (frequency resolution)
_MIN_PEAK_CONTRAST = 4.0  # a tile's peak must stand this far above its band's mean power
RIDGE_AREA_WIDTHS = 1.4  # the ridge period is measured within this many finger widths of the tip
RMS_FLOOR = 1e-3  # intensity: below this local band RMS there is no texture to normalise (a quarter grey level)


def as_gray(image: np.ndarray, name: str = "image") -> np.ndarray:
    """``[H, W]`` or ``[H, W, 3]`` in [0, 1] (or uint8/uint16) -> float32 ``[H, W]`` in [0, 1]."""
    array = np.asarray(image)
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[..., 0]
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] != 3):
        raise InputError(f"{name} must be HxW or HxWx3, got shape {array.shape}")
    if array.dtype == np.uint8:
        array = array.astype(np.float32) / 255.0
    elif array.dtype == np.uint16:
        array = array.astype(np.float32) / 65535.0
    else:
        array = array.astype(np.float32)
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name} contains NaN or Inf")
    if array.ndim == 3:  # luminance
        array = array @ np.array([0.299, 0.587, 0.114], np.float32)
    return array


def estimate_ridge_period(gray: np.ndarray, mask: np.ndarray | None = None, min_period: float = 3.0,
                          max_period: float = 40.0) -> float:
    """Dominant ridge period in pixels (see the module docstring); ``DEFAULT_PERIOD_PX`` when none."""
    period = measure_ridge_period(gray, mask, min_period, max_period)
    return DEFAULT_PERIOD_PX if period is None else period


def measure_ridge_period(gray: np.ndarray, mask: np.ndarray | None = None, min_period: float = 3.0,
                         max_period: float = 40.0) -> float | None:
    """Dominant ridge period in pixels, or None when no tile shows a ridge peak (a featureless image, or ridges
    finer than ``min_period``).

    Tiles of 96 px lying inside the (eroded) mask, shading removed by a high-pass, Hann window;
    each tile votes its strongest peak between ``min_period`` and ``max_period`` with the peak's
    contrast as weight, refined by a parabola through its neighbours.
    """
    gray = as_gray(gray).astype(np.float64)
    mask = np.ones(gray.shape, bool) if mask is None else np.asarray(mask, bool)
    if mask.shape != gray.shape:
        raise InputError(f"mask is {mask.shape[1]}x{mask.shape[0]}, image is {gray.shape[1]}x{gray.shape[0]}")
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return None
    mask = ridge_area(mask)
    extent = min(int(np.ptp(rows)) + 1, int(np.ptp(cols)) + 1)
    margin = int(min(max_period, 0.1 * extent))  # off the silhouette's edge, where shading drops
    inner = mask if mask.all() or margin < 1 else cv2.erode(mask.astype(np.uint8), np.ones((2 * margin + 1,) * 2, np.uint8)) > 0
    tile = min(_TILE, extent - 2 * margin)
    if tile < 16:
        return None
    # The shading blurred in float32 (a fifth of float64's time at 1280x1024: 0.03 against 0.15 s; it is only
    # subtracted, and its rounding is far below a photo's 8 bits)
    high_pass = gray - cv2.GaussianBlur(gray.astype(np.float32), (0, 0), max_period / 2.0)
    window = np.outer(np.hanning(tile), np.hanning(tile))
    yy, xx = np.indices((_FFT, _FFT))
    radius = np.hypot(yy - _FFT // 2, xx - _FFT // 2)
    band = (radius > _FFT / max_period) & (radius < _FFT / min_period)
    periods, weights = [], []
    inner_rows, inner_cols = np.nonzero(inner)
    if inner_rows.size == 0:
        return None
    step = max(8, tile // 2)
    for top in range(int(inner_rows.min()), int(inner_rows.max()) - tile + 2, step):
        for left in range(int(inner_cols.min()), int(inner_cols.max()) - tile + 2, step):
            if inner[top:top + tile, left:left + tile].mean() < 0.95:
                continue
            patch = high_pass[top:top + tile, left:left + tile]
            power = np.abs(np.fft.fftshift(np.fft.fft2((patch - patch.mean()) * window, (_FFT, _FFT)))) ** 2
            in_band = np.where(band, power * radius, 0.0)  # whitened: shading's 1/f falloff does not outvote ridges
            y, x = np.unravel_index(int(np.argmax(in_band)), power.shape)
            contrast = in_band[y, x] / max(float(in_band[band].mean()), 1e-30)
            if contrast < _MIN_PEAK_CONTRAST:
                continue
            y, x = _climb(power, y, x)  # the peak itself, on the unweighted spectrum
            if not (0 < y < _FFT - 1 and 0 < x < _FFT - 1):
                continue
            fy = y + _parabola(power[y - 1, x], power[y, x], power[y + 1, x])
            fx = x + _parabola(power[y, x - 1], power[y, x], power[y, x + 1])
            period = _FFT / max(np.hypot(fy - _FFT // 2, fx - _FFT // 2), 1e-9)
            if not min_period <= period <= max_period:  # the climb left the band: shading, not ridges
                continue
            periods.append(period)
            weights.append(contrast)
    if not periods:
        return None
    order = np.argsort(periods)
    cumulative = np.cumsum(np.asarray(weights)[order])
    return float(np.asarray(periods)[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])


def no_ridges(period_px: float | None, finger_width_px: float) -> str | None:
    """Why a finger ``finger_width_px`` wide (its widest disc) whose measured period is ``period_px`` (None or NaN:
    no ridge peak) shows no ridges, in words; None when it shows them (:data:`MIN_RIDGES_ACROSS`)."""
    if period_px is None or not np.isfinite(period_px):
        return "no ridges found on the finger (out of focus, blurred or too small to measure)"
    if finger_width_px > 0 and finger_width_px / period_px < MIN_RIDGES_ACROSS:
        return (f"no ridges on the finger: its finest pattern repeats every {period_px:.0f} px, where a finger "
                f"{finger_width_px:.0f} px wide has ridges about {finger_width_px / 35:.0f} px apart (out of focus or "
                "blurred)")
    return None


def ridge_area(mask: np.ndarray) -> np.ndarray:
    """The part of a finger mask where ridges are: within ``RIDGE_AREA_WIDTHS`` finger widths of the tip.

    Friction ridges cover the distal phalanx up to its crease, ~1.4-1.8 widths from the tip;
    behind it, skin creases and wrinkles have periods of their own that would outvote the ridges
    on a finger photographed far back. The whole mask when no tip is found (no border cuts one end).
    """
    from ...segment.silhouette import silhouette_frame

    if mask.all() or mask.sum() < 64:
        return mask
    frame = silhouette_frame(mask)
    if not frame.tip_found:
        return mask
    rows, cols = np.nonzero(mask)
    s, _ = frame.coordinates(np.stack([cols, rows], 1).astype(np.float64))
    width = 2.0 * float(np.median(frame.sections.half_width))
    area = np.zeros_like(mask)
    area[rows, cols] = (frame.s_tip - s) < RIDGE_AREA_WIDTHS * width
    return area


def _climb(power: np.ndarray, y: int, x: int, steps: int = 4) -> tuple[int, int]:
    """From ``(y, x)`` uphill on ``power`` to a local maximum (at most ``steps`` moves)."""
    for _ in range(steps):
        window = power[max(y - 1, 0):y + 2, max(x - 1, 0):x + 2]
        dy, dx = np.unravel_index(int(np.argmax(window)), window.shape)
        ny, nx = max(y - 1, 0) + int(dy), max(x - 1, 0) + int(dx)
        if (ny, nx) == (y, x):
            break
        y, x = ny, nx
    return y, x


def _parabola(left: float, centre: float, right: float) -> float:
    denominator = left - 2.0 * centre + right
    return float(np.clip(0.5 * (left - right) / denominator, -0.5, 0.5)) if denominator < 0 else 0.0


def suppress_glints(gray: np.ndarray, mask: np.ndarray, radius: int = 1, factor: float = 4.0) -> np.ndarray:
    """``gray`` with specular specks replaced by the surrounding skin.

    A glint is smaller than a ridge: it is what a grey opening with a disc of ``radius`` removes
    (the top-hat), by more than ``factor`` times the local RMS of the top-hat (the shaving every
    ridge crest gets), and more than the sensor noise could. Ridges stay as they are.
    """
    gray = np.asarray(gray, np.float32)
    opened = cv2.morphologyEx(gray, cv2.MORPH_OPEN, disc(radius))
    top_hat = gray - opened
    inside = top_hat[mask]
    if inside.size < 16:
        return gray
    local = np.sqrt(cv2.GaussianBlur(top_hat * top_hat, (0, 0), 6.0 * (radius + 1)))
    noise = robust_sigma(inside)
    inner = eroded(mask, radius, iterations=2)  # the outline's step is no glint
    glint = dilated((top_hat > factor * np.maximum(local, noise)) & inner, radius)
    return np.where(glint, opened, gray)


def ridge_texture(gray: np.ndarray, mask: np.ndarray, period: float) -> np.ndarray:
    """Band-passed ridge texture ``[H, W]`` float32 with unit local RMS inside ``mask``, 0 outside."""
    gray = as_gray(gray)
    weight = np.asarray(mask, np.float32)
    clean = suppress_glints(gray, np.asarray(mask, bool), radius=max(1, int(round(period / 12)))) * weight
    band = (masked_blur(clean, weight, 0.18 * period) - masked_blur(clean, weight, 0.6 * period)) * weight
    rms = np.sqrt(masked_blur(band * band, weight, period) + RMS_FLOOR ** 2)
    return (band / rms * weight).astype(np.float32)
