"""Verification error rates from genuine and impostor comparison scores (higher = more alike).

A comparison is accepted when its score is at or above the threshold ``t``:

* ``FMR(t)``: the share of impostor scores ``>= t`` (false matches);
* ``FNMR(t)``: the share of genuine scores ``< t`` (false non-matches).

Thresholds are every distinct score plus one above the largest, so both curves are exact step
functions of the data, nothing interpolated except where the EER sits between two steps.

* :func:`det_curve`: (thresholds, FMR, FNMR), FMR falling and FNMR rising with the threshold;
* :func:`equal_error_rate`: where FMR and FNMR cross, the mean of the two at the threshold that
  brings them closest (the usual estimate on step curves);
* :func:`fnmr_at_fmr`: the lowest FNMR among thresholds whose FMR is at most the target (FMR@1 %,
  FMR@0.01 %, and FMR_zero at a target of 0: the FNMR once no impostor is accepted). With ``n``
  impostor scores an FMR below ``1/n`` cannot be told from 0: :func:`fmr_resolution` says so.

Pure numpy.
"""
from __future__ import annotations

import numpy as np

__all__ = ["det_curve", "equal_error_rate", "fnmr_at_fmr", "fmr_resolution", "error_rates"]


def _scores(genuine, impostor) -> tuple[np.ndarray, np.ndarray]:
    genuine = np.asarray(genuine, np.float64).reshape(-1)
    impostor = np.asarray(impostor, np.float64).reshape(-1)
    if genuine.size == 0 or impostor.size == 0:
        raise ValueError(f"need genuine and impostor scores, got {genuine.size} genuine and {impostor.size} impostor")
    if not (np.isfinite(genuine).all() and np.isfinite(impostor).all()):
        raise ValueError("scores contain NaN or Inf")
    return genuine, impostor


def det_curve(genuine, impostor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(thresholds, fmr, fnmr)`` at every distinct score and one above the largest."""
    genuine, impostor = _scores(genuine, impostor)
    values = np.unique(np.concatenate([genuine, impostor]))
    thresholds = np.append(values, np.nextafter(values[-1], np.inf))
    fmr = 1.0 - np.searchsorted(np.sort(impostor), thresholds, side="left") / impostor.size
    fnmr = np.searchsorted(np.sort(genuine), thresholds, side="left") / genuine.size
    return thresholds, fmr, fnmr


def equal_error_rate(genuine, impostor) -> float:
    """The EER: ``(FMR + FNMR) / 2`` at the threshold where ``|FMR - FNMR|`` is smallest."""
    _, fmr, fnmr = det_curve(genuine, impostor)
    best = int(np.argmin(np.abs(fmr - fnmr)))
    return float(0.5 * (fmr[best] + fnmr[best]))


def fnmr_at_fmr(genuine, impostor, target: float) -> float:
    """The lowest FNMR over thresholds with ``FMR <= target`` (``target`` 0: FMR_zero)."""
    if not 0.0 <= target <= 1.0:
        raise ValueError(f"target FMR {target} is not in [0, 1]")
    _, fmr, fnmr = det_curve(genuine, impostor)
    return float(fnmr[fmr <= target].min())  # the threshold above every score always qualifies


def fmr_resolution(impostor_count: int) -> float:
    """The smallest non-zero FMR ``n`` impostor scores can show: ``1 / n``."""
    return 1.0 / impostor_count if impostor_count > 0 else float("nan")


def error_rates(genuine, impostor) -> dict:
    """EER, FNMR at FMR 1 % and 0.01 %, FMR_zero, and the counts, as a dict."""
    genuine, impostor = _scores(genuine, impostor)
    return {"genuine": int(genuine.size), "impostor": int(impostor.size),
            "eer": equal_error_rate(genuine, impostor), "fnmr_at_fmr_1pct": fnmr_at_fmr(genuine, impostor, 0.01),
            "fnmr_at_fmr_0.01pct": fnmr_at_fmr(genuine, impostor, 1e-4), "fmr_zero": fnmr_at_fmr(genuine, impostor, 0.0),
            "fmr_resolution": fmr_resolution(impostor.size)}
