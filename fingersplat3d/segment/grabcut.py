"""Colour statistics and GrabCut, shared by the cuts of a finger on any background
(:mod:`~fingersplat3d.segment.any_background`, :mod:`~fingersplat3d.segment.filled_frame`). Pure numpy/OpenCV."""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["GRABCUT_ITERATIONS"]

GRABCUT_ITERATIONS = 5
COARSE_MIN_SIDE = 96
"""Images whose short side is under this many pixels are cut once at their size (:func:`_grab_cut`)."""
REFINE_ITERATIONS = 2
"""GrabCut's iterations at the full size after the coarse cut (:func:`_grab_cut`)."""


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
    """OpenCV's GrabCut from ``labels`` (changed in place); what it keeps as finger, sure or probable.

    Coarse to fine: the cut at half the size (:func:`_coarse_labels`), then :data:`REFINE_ITERATIONS` more at the full
    size, every pixel not given as sure starting as the coarse cut left it, as probable finger or probable background.
    GrabCut's max-flow is what costs, and on a photo whose skin and background are near in colour over large areas
    its first iterations, from mixture models fitted to the seeds alone, were slow beyond the pixels' count: a real
    view on a bright desk 6.1 s at 512x640, one cropped to the finger on clutter 22 s over its seven cuts; started from
    the coarse cut, the full size's iterations take a fraction of that (docs/measurements.md, stop 105). Held to a band
    about the coarse outline instead, the cut kept a clutter ellipse the full size drops (GrabCut's smoothness weighs
    twice as much against its colour term at half the size): the full size has the last word everywhere. Images under
    :data:`COARSE_MIN_SIDE` are cut once at their size."""
    if min(labels.shape) < COARSE_MIN_SIDE:
        return _cut_once(colour8, labels, GRABCUT_ITERATIONS)
    small = cv2.resize(colour8, (labels.shape[1] // 2, labels.shape[0] // 2), interpolation=cv2.INTER_AREA)
    coarse = _coarse_labels(labels, small.shape[:2])
    if not _both_sides(coarse):
        return _cut_once(colour8, labels, GRABCUT_ITERATIONS)
    finger = cv2.resize(_cut_once(small, coarse, GRABCUT_ITERATIONS).view(np.uint8), labels.shape[::-1],
                        interpolation=cv2.INTER_LINEAR).view(bool)
    given = (labels == cv2.GC_BGD) | (labels == cv2.GC_FGD)
    start = np.where(finger, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    start[given] = labels[given]
    labels[:] = start
    if not _both_sides(labels):  # the coarse cut kept all or nothing, and no seed says otherwise: its answer stands
        return _kept(labels)
    return _cut_once(colour8, labels, REFINE_ITERATIONS)


def _cut_once(colour8: np.ndarray, labels: np.ndarray, iterations: int) -> np.ndarray:
    """``iterations`` of OpenCV's GrabCut from ``labels`` (changed in place) at their size; what it keeps as finger."""
    cv2.setRNGSeed(0)  # GrabCut's mixture models start from k-means: the same photo gives the same mask
    background_model, foreground_model = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.grabCut(colour8, labels, None, background_model, foreground_model, iterations, cv2.GC_INIT_WITH_MASK)
    return _kept(labels)


def _kept(labels: np.ndarray) -> np.ndarray:
    """What ``labels`` hold as finger, sure or probable."""
    return (labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD)


def _coarse_labels(labels: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``labels`` at half the size (``shape``): a pixel of each 2x2 block, sure background where any of the block is,
    else sure finger where any of it is (a sure label a pixel wide, the border ring's inner edge, is not lost)."""
    size = shape[::-1]
    coarse = cv2.resize(labels, size, interpolation=cv2.INTER_NEAREST)
    for label in (cv2.GC_FGD, cv2.GC_BGD):  # background last: it wins a block holding both
        coarse[cv2.resize((labels == label).astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.0] = label
    return coarse


def _both_sides(labels: np.ndarray) -> bool:
    """Whether ``labels`` give GrabCut samples of both the finger and the background (it fails on either empty)."""
    finger = _kept(labels)
    return bool(finger.any()) and not bool(finger.all())
