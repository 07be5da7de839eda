"""Region helpers both finger segmentations share (pure OpenCV)."""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["fill_holes", "largest_component", "local_sums", "gradient_magnitude", "crest_level", "CREST_POWER"]

CREST_POWER = 4
"""A crest level's pixels weigh by gradient magnitude to this power: the crest dominates, a ramp or ridge does not."""


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """Fill background regions that do not reach the image border."""
    count, labels = cv2.connectedComponents((~mask).view(np.uint8), connectivity=4)
    if count <= 2:
        return mask
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    outside = np.isin(labels, border[border > 0])
    return ~outside


def largest_component(mask8: np.ndarray) -> np.ndarray | None:
    """The largest 8-connected piece of ``mask8`` (uint8) as a bool mask; None when it has none."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask8, connectivity=8)
    if count < 2:
        return None
    return labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))


def local_sums(weight: np.ndarray, weighted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian local sums (sigma ~1.5 % of the long side) of ``weight`` ``[H, W]`` and ``weighted`` (weight times a
    value, ``[H, W]`` or ``[H, W, C]``), on a grid a few times coarser than the image, which is all such a smooth map
    needs: their ratio is the value's local weighted mean. Both float32, the coarse grid's shape."""
    height, width = weight.shape
    sigma = max(2.0, 0.015 * max(height, width))
    factor = max(1, int(sigma // 2))
    coarse = (max(1, -(-width // factor)), max(1, -(-height // factor)))
    mass = cv2.GaussianBlur(cv2.resize(weight, coarse, interpolation=cv2.INTER_AREA), (0, 0), sigma / factor)
    total = cv2.GaussianBlur(cv2.resize(weighted, coarse, interpolation=cv2.INTER_AREA), (0, 0), sigma / factor)
    return mass, total


def gradient_magnitude(image: np.ndarray) -> np.ndarray:
    """The Sobel gradient's magnitude of a float32 ``[H, W]`` image (borders replicated)."""
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE)
    return cv2.magnitude(gx, gy)


def crest_level(values: np.ndarray, magnitude: np.ndarray, band: np.ndarray, fallback: np.ndarray,
                power: float = CREST_POWER) -> np.ndarray | None:
    """The local level of ``values`` at the crest of an edge: their local mean over ``band`` weighted by the gradient
    ``magnitude`` (over its peak in the band) to ``power``, so that the crest outweighs a ramp or the ridges;
    ``fallback`` where no crest is near. Wherever a step is blurred symmetrically its gradient peaks on the true edge,
    the value there the midpoint of the two sides. Float32 at the image's size; None when the band has no gradient."""
    peak = float(magnitude[band].max()) if band.any() else 0.0
    if not peak > 0.0:
        return None
    weight = np.where(band, magnitude / peak, 0.0).astype(np.float32) ** power
    mass, total = local_sums(weight, weight * values)
    before = cv2.resize(fallback, mass.shape[::-1], interpolation=cv2.INTER_AREA)
    level = np.where(mass > 1e-3 * float(mass.max()), total / np.maximum(mass, 1e-30), before).astype(np.float32)
    return cv2.resize(level, values.shape[::-1], interpolation=cv2.INTER_LINEAR)
