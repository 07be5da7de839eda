"""Colour statistics and GrabCut, shared by the cuts of a finger on any background
(:mod:`~fingersplat3d.segment.any_background`, :mod:`~fingersplat3d.segment.filled_frame`). Pure numpy/OpenCV."""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["GRABCUT_ITERATIONS"]

GRABCUT_ITERATIONS = 5


def _gray(image: np.ndarray) -> np.ndarray:
    return image if image.ndim == 2 else image @ np.array([0.299, 0.587, 0.114], np.float32)


def _colour_floor(colour: np.ndarray) -> float:
    """The spread added to each channel's standard deviation in the colour distances: 0.02 of the range (5 of 255 in
    8-bit levels), so that a flat sample does not make every other colour infinitely far."""
    return 5.0 if colour.dtype == np.uint8 else 0.02


def _colour_distance(colour: np.ndarray, seed: np.ndarray, strict: bool = False) -> np.ndarray:
    """Per pixel, the Mahalanobis distance of ``colour`` from the colours of the ``seed`` pixels (their mean and
    covariance, :func:`_colour_floor` squared added to each channel's variance); ``strict``: at least their distance
    in standard deviations per channel too.

    Skin varies along its own colour, with the ridges and the shading: in standard deviations per channel a saturated
    thing as bright as the skin came out as near as a shade of it (a grey finger's ridges spread every channel alike,
    so purple clutter lay within 4 of them and went with the finger: real views on clutter at IoU 0.72). Across the
    skin's colour its spread is small, and the covariance sees that; along it, it is more lenient, so ``strict``
    (what may be *sure* finger) keeps the per-channel distance as a bound as well (a bright desk is a lighter grey)."""
    skin = colour[seed].astype(np.float64)
    floor = _colour_floor(colour)
    spread = np.atleast_2d(np.cov(skin, rowvar=False)) if len(skin) > 1 else np.zeros((skin.shape[1],) * 2)
    whiten = np.linalg.cholesky(np.linalg.inv(spread + floor * floor * np.eye(skin.shape[1])))
    offset = colour.astype(np.float32) - skin.mean(0).astype(np.float32)
    distance = np.linalg.norm(offset @ whiten.astype(np.float32), axis=-1)
    if strict:
        per_channel = offset / (skin.std(0) + floor).astype(np.float32)
        distance = np.maximum(distance, np.linalg.norm(per_channel, axis=-1))
    return distance


def _grab_cut(colour8: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """OpenCV's GrabCut from ``labels`` (changed in place); what it keeps as finger, sure or probable."""
    cv2.setRNGSeed(0)  # GrabCut's mixture models start from k-means: the same photo gives the same mask
    background_model, foreground_model = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.grabCut(colour8, labels, None, background_model, foreground_model, GRABCUT_ITERATIONS, cv2.GC_INIT_WITH_MASK)
    return (labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD)
