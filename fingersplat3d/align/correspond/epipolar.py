"""Epipolar verification of correspondences: a robust fundamental matrix, guarded against the data.

``cv2.findFundamentalMat`` with USAC_MAGSAC raises (``!model.empty()``, "Invalid dimension of
point") rather than returning nothing on some inputs that admit no model: few, collinear or
identical points. :func:`fundamental_inliers` turns every such case into "no model" so that a
pair that cannot be estimated is a pair that failed, never a traceback.

Pure numpy/OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["fundamental_inliers", "sampson_distance"]

MIN_POINTS = 8


def fundamental_inliers(uv_a: np.ndarray, uv_b: np.ndarray, threshold_px: float,
                        confidence: float = 0.9999, iterations: int = 10000) -> tuple[np.ndarray | None, np.ndarray]:
    """MAGSAC++ fundamental matrix ``[3, 3]`` and inlier mask ``[N]``; ``(None, all False)`` when there is none."""
    uv_a = np.ascontiguousarray(np.asarray(uv_a, np.float64).reshape(-1, 2))
    uv_b = np.ascontiguousarray(np.asarray(uv_b, np.float64).reshape(-1, 2))
    none = (None, np.zeros(len(uv_a), bool))
    finite = np.isfinite(uv_a).all(1) & np.isfinite(uv_b).all(1)
    if finite.sum() < MIN_POINTS:
        return none
    try:
        F, inliers = cv2.findFundamentalMat(uv_a[finite], uv_b[finite], cv2.USAC_MAGSAC, float(threshold_px),
                                            confidence, iterations)
    except cv2.error:  # the data admit no model: a failed estimate, not an error
        return none
    if F is None or F.shape != (3, 3) or inliers is None or not np.all(np.isfinite(F)):
        return none
    mask = np.zeros(len(uv_a), bool)
    mask[np.flatnonzero(finite)] = inliers.ravel().astype(bool)
    return F, mask


def sampson_distance(F: np.ndarray, uv_a: np.ndarray, uv_b: np.ndarray) -> np.ndarray:
    """Sampson epipolar distance in pixels ``[N]``."""
    xa = np.concatenate([uv_a, np.ones((len(uv_a), 1))], axis=1)
    xb = np.concatenate([uv_b, np.ones((len(uv_b), 1))], axis=1)
    Fxa = xa @ F.T
    Ftxb = xb @ F
    numerator = np.sum(xb * Fxa, axis=1) ** 2
    denominator = Fxa[:, 0] ** 2 + Fxa[:, 1] ** 2 + Ftxb[:, 0] ** 2 + Ftxb[:, 1] ** 2
    return np.sqrt(numerator / np.maximum(denominator, 1e-30))
