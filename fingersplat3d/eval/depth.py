"""Depth error of a predicted depth map against ground truth, after an optional scale/shift fit.

Monocular and uncalibrated reconstructions recover depth only up to a scale (and, for relative
depth, a shift), so a prediction is first aligned to the ground truth by least squares
(``align="scale_shift"``: ``scale * pred + shift``; ``"scale"``: ``scale * pred``; ``"none"``)
and the errors are measured on the aligned prediction, in the ground truth's units (mm).

Pixels count when both maps are finite there (and ``mask``, when given, is true). ``coverage``
is how much of the ground truth the prediction covers: the fraction of pixels with finite ground
truth (inside ``mask``) where the prediction is finite too.

"Weighted depth error" (the paper's Table on PolyU 3D+) is not defined there. Here it is the
error under per-pixel ``weights`` (typically the prediction's confidence): the alignment becomes
a weighted least-squares fit, and every statistic (mean, RMS, median, 90th percentile) is taken
over the weighted distribution of absolute errors. With ``weights=None`` every pixel weighs 1.

Pure numpy: no Open3D, no files.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ALIGNMENTS", "DepthErrors", "BackedErrors", "align_scale_shift", "align_scale", "depth_errors",
           "errors_by_backing", "split_by_backing"]

ALIGNMENTS = ("scale_shift", "scale", "none")


@dataclass(frozen=True)
class DepthErrors:
    """Errors of an aligned prediction (units of the ground truth)."""

    mae: float  # mean absolute error
    rmse: float  # root mean square error
    median_abs: float  # median absolute error
    p90_abs: float  # 90th percentile of the absolute error
    coverage: float  # fraction of valid ground-truth pixels where the prediction is finite
    n: int  # pixels compared (finite in both, inside the mask, weight > 0)
    scale: float  # the fitted scale (1 for align="none")
    shift: float  # the fitted shift (0 unless align="scale_shift")
    weighted: bool  # whether per-pixel weights were applied

    def as_dict(self) -> dict[str, float | int | bool]:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


def _overlap(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None,
             weights: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validated float64 ``pred``, ``gt``, ``weights`` over the compared pixels, and the gt-valid mask."""
    pred = np.asarray(pred, np.float64)
    gt = np.asarray(gt, np.float64)
    if pred.shape != gt.shape:
        raise ValueError(f"prediction has shape {pred.shape} but ground truth has shape {gt.shape}")
    valid_gt = np.isfinite(gt)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != gt.shape:
            raise ValueError(f"mask has shape {mask.shape} but ground truth has shape {gt.shape}")
        valid_gt &= mask.astype(bool)
    used = valid_gt & np.isfinite(pred)
    if weights is not None:
        weights = np.asarray(weights, np.float64)
        if weights.shape != gt.shape:
            raise ValueError(f"weights have shape {weights.shape} but ground truth has shape {gt.shape}")
        if np.any(weights[used] < 0) or not np.all(np.isfinite(weights[used])):
            raise ValueError("weights must be finite and non-negative where both depths are finite")
        used &= weights > 0
    if not used.any():
        raise ValueError("prediction and ground truth have no pixel in common (finite in both and inside the mask)")
    w = np.ones(int(used.sum())) if weights is None else weights[used]
    return pred[used], gt[used], w, valid_gt


def _fit(p: np.ndarray, g: np.ndarray, w: np.ndarray, align: str) -> tuple[float, float]:
    """Weighted least squares of ``scale * p + shift ~ g`` on flat arrays."""
    if align == "none":
        return 1.0, 0.0
    if align == "scale":
        denominator = np.sum(w * p * p)
        return (float(np.sum(w * p * g) / denominator), 0.0) if denominator > 0 else (1.0, 0.0)
    # Centre first: the normal equations on raw depths (~300 mm, spread ~5 mm) lose digits.
    total = w.sum()
    p_mean, g_mean = np.sum(w * p) / total, np.sum(w * g) / total
    dp, dg = p - p_mean, g - g_mean
    variance = np.sum(w * dp * dp)
    # A constant prediction fixes no scale; keep 1 and fit the shift (its error is then the
    # ground truth's own spread, which is the honest score of a flat map).
    scale = np.sum(w * dp * dg) / variance if variance > 1e-12 * max(np.sum(w * p * p), 1e-300) else 1.0
    return float(scale), float(g_mean - scale * p_mean)


def align_scale_shift(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None,
                      weights: np.ndarray | None = None) -> tuple[float, float]:
    """``(scale, shift)`` minimising ``sum w (scale * pred + shift - gt)^2`` over the common pixels.

    ``pred``, ``gt``: ``[H, W]`` (any equal shapes) with NaN where there is no depth;
    ``mask``: optional bool of the same shape; ``weights``: optional non-negative, same shape.
    """
    p, g, w, _ = _overlap(pred, gt, mask, weights)
    return _fit(p, g, w, "scale_shift")


def align_scale(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None,
                weights: np.ndarray | None = None) -> float:
    """The ``scale`` minimising ``sum w (scale * pred - gt)^2`` over the common pixels."""
    p, g, w, _ = _overlap(pred, gt, mask, weights)
    return _fit(p, g, w, "scale")[0]


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """Quantile of the weighted sample: each value sits at the middle of its share of the total weight.

    With equal weights this is numpy's ``method="hazen"``: the median equals ``np.median`` and
    other quantiles differ from ``np.quantile``'s default by less than one gap between samples.
    """
    order = np.argsort(values)
    values, weights = values[order], weights[order]
    position = (np.cumsum(weights) - 0.5 * weights) / weights.sum()
    return float(np.interp(q, position, values))


def depth_errors(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None,
                 align: str = "scale_shift", weights: np.ndarray | None = None) -> DepthErrors:
    """Errors of ``pred`` against ``gt`` after aligning it (see the module docstring).

    ``pred``, ``gt``: ``[H, W]`` depth, NaN = none; ``mask``: optional ``[H, W]`` bool restricting
    the comparison; ``weights``: optional ``[H, W]`` non-negative per-pixel weights (confidence).
    Raises ``ValueError`` on mismatched shapes, an unknown ``align`` or no common pixel.
    """
    if align not in ALIGNMENTS:
        raise ValueError(f"align must be one of {', '.join(ALIGNMENTS)}, got {align!r}")
    p, g, w, valid_gt = _overlap(pred, gt, mask, weights)
    scale, shift = _fit(p, g, w, align)
    error = np.abs(scale * p + shift - g)
    total = w.sum()
    if weights is None:
        median, p90 = np.percentile(error, [50, 90])
    else:
        median, p90 = _weighted_quantile(error, w, 0.5), _weighted_quantile(error, w, 0.9)
    pred_finite = np.isfinite(np.asarray(pred, np.float64))
    return DepthErrors(
        mae=float(np.sum(w * error) / total),
        rmse=float(np.sqrt(np.sum(w * error * error) / total)),
        median_abs=float(median),
        p90_abs=float(p90),
        coverage=float(np.count_nonzero(valid_gt & pred_finite) / np.count_nonzero(valid_gt)),
        n=int(len(error)),
        scale=scale,
        shift=shift,
        weighted=weights is not None,
    )


@dataclass(frozen=True)
class BackedErrors:
    """Mean absolute errors split by where a second view backs the surface (NaN where a part has no pixel)."""

    share_two_views: float  # of the scored pixels, the share a second view backs
    mae_two_views: float  # over the skin a second view backs: its depth measured from the photos
    mae_one_view: float  # over the skin this view alone sees: its depth the pointmap's guess


def errors_by_backing(error: np.ndarray, backing: np.ndarray) -> BackedErrors:
    """The absolute errors ``error [H, W]`` (NaN where not scored, e.g. ``|scale * pred + shift - gt|``) split by
    ``backing [H, W]`` (``1`` backed by a second view, ``0`` seen by one view alone, ``-1`` no surface: those pixels
    count in neither part). Raises ``ValueError`` when the shapes differ."""
    error = np.asarray(error, np.float64)
    backing = np.asarray(backing)
    if error.shape != backing.shape:
        raise ValueError(f"error map has shape {error.shape} but backing map has shape {backing.shape}")
    scored = np.isfinite(error)
    two, one = scored & (backing == 1), scored & (backing == 0)
    counted = int(two.sum() + one.sum())
    mean = lambda part: float(error[part].mean()) if part.any() else float("nan")  # noqa: E731
    return BackedErrors(float(two.sum()) / counted if counted else float("nan"), mean(two), mean(one))


def split_by_backing(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None, fit: DepthErrors,
                     backing: np.ndarray) -> BackedErrors:
    """:func:`errors_by_backing` of ``pred`` aligned to ``gt`` as ``fit`` (:func:`depth_errors`' scale and shift over
    the whole view) inside ``mask`` (None: everywhere), ``backing`` a
    :func:`~fingersplat3d.align.transfer.multi_view_backing` map at any stride over the same image."""
    from ..align.transfer import backing_on

    error = np.abs(fit.scale * np.asarray(pred, np.float64) + fit.shift - np.asarray(gt, np.float64))
    if mask is not None:
        error = np.where(np.asarray(mask, bool), error, np.nan)
    return errors_by_backing(error, backing_on(backing, error.shape))
