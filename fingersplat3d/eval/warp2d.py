"""The paper's 2D baselines for carrying minutiae between views, and how their error is measured.

* **rigid 2D**: a similarity (rotation, translation and one scale; OpenCV's
  ``estimateAffinePartial2D`` with RANSAC). It includes the rigid transform, so the baseline is
  given a little more freedom than the paper's, never less.
* **TPS**: a thin-plate spline (scipy's ``RBFInterpolator``, kernel ``thin_plate_spline``) fitted to
  the RANSAC inliers of the similarity, with a small smoothing so that a near-duplicate pair of
  mates cannot fold it.

A baseline fitted to the mates it is scored on would score its own training data (an
interpolating TPS scores 0), so :func:`cross_validated_errors` fits on all mates but one fold and
scores that fold, over ``folds`` folds: every mate is scored once, by a model that did not see it.
Pure numpy/scipy/OpenCV.
"""
from __future__ import annotations

from typing import Callable

import cv2
import numpy as np

__all__ = ["fit_similarity", "fit_tps", "cross_validated_errors", "BASELINES"]

RANSAC_THRESHOLD_PX = 20.0
TPS_SMOOTHING = 1.0


def fit_similarity(source: np.ndarray, target: np.ndarray) -> tuple[Callable[[np.ndarray], np.ndarray], np.ndarray]:
    """RANSAC similarity ``source -> target``: ``(map, inlier mask)``."""
    source, target = np.asarray(source, np.float64), np.asarray(target, np.float64)
    if len(source) < 2:
        raise ValueError(f"a similarity needs at least 2 mates, got {len(source)}")
    matrix, inliers = cv2.estimateAffinePartial2D(source, target, method=cv2.RANSAC,
                                                 ransacReprojThreshold=RANSAC_THRESHOLD_PX, maxIters=4000,
                                                 confidence=0.999, refineIters=10)
    if matrix is None:  # degenerate (all points together): translation only
        matrix = np.hstack([np.eye(2), (target - source).mean(0)[:, None]])
        inliers = np.ones(len(source), bool)
    return (lambda xy: np.asarray(xy, np.float64) @ matrix[:, :2].T + matrix[:, 2]), inliers.reshape(-1).astype(bool)


def fit_tps(source: np.ndarray, target: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """Thin-plate spline ``source -> target`` on the similarity's RANSAC inliers (the similarity
    itself when fewer than 4 inliers remain)."""
    from scipy.interpolate import RBFInterpolator

    similarity, inliers = fit_similarity(source, target)
    if inliers.sum() < 4:
        return similarity
    spline = RBFInterpolator(np.asarray(source)[inliers], np.asarray(target)[inliers], kernel="thin_plate_spline",
                             smoothing=TPS_SMOOTHING, degree=1)
    return lambda xy: spline(np.asarray(xy, np.float64).reshape(-1, 2))


BASELINES = {"rigid 2D": lambda s, t: fit_similarity(s, t)[0], "TPS": fit_tps}


def cross_validated_errors(source: np.ndarray, target: np.ndarray, fit: Callable, folds: int = 5,
                           seed: int = 0) -> np.ndarray:
    """Per-mate distance (px) between ``fit``'s map of ``source`` and ``target``, each mate scored by
    a model fitted without its fold. NaN where a fold left too few mates to fit."""
    source, target = np.asarray(source, np.float64), np.asarray(target, np.float64)
    errors = np.full(len(source), np.nan)
    if len(source) < 3:
        return errors
    fold = np.random.default_rng(seed).permutation(len(source)) % min(folds, len(source))
    for k in np.unique(fold):
        test = fold == k
        try:
            mapping = fit(source[~test], target[~test])
        except ValueError:
            continue
        errors[test] = np.linalg.norm(mapping(source[test]) - target[test], axis=1)
    return errors
