"""Ridge enhancement of a print: a Gabor filter turned to the local ridge flow (Hong, Wan & Jain 1998).

A band-pass at the ridge period keeps what has the ridges' size but no direction: the pores on the
crests and, where two photos blend, the cross-hatch of two slightly shifted ridge patterns. Both break
ridges into dots that mindtct reads as minutiae. A filter that is a cosine *across* the ridges and a
long Gaussian *along* them keeps only ridges running the local way:

1. the ridge direction per pixel from the structure tensor of the texture (gradients, smoothed over
   :data:`ORIENTATION_PERIODS` ridge periods inside the mask);
2. a bank of :data:`ORIENTATIONS` zero-mean Gabor kernels (cosine of the ridge period across, Gaussian
   envelope of :data:`SIGMA_ACROSS` periods across and :data:`SIGMA_ALONG` along); each pixel takes the
   response of its direction, interpolated between the two nearest kernels;
3. unit local RMS over one period (masked), 0 outside the mask.

Written here with OpenCV's ``filter2D`` rather than taken from a fingerprint library: ``pyfing``'s
enhancers need Keras (and its ~85 MB wheel), and this is the textbook filter in thirty lines. Pure
numpy/OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..structure_tensor import masked_blur, structure_products

__all__ = ["gabor_enhance", "ridge_coherence", "ORIENTATIONS", "SIGMA_ACROSS", "SIGMA_ALONG", "ORIENTATION_PERIODS"]

ORIENTATIONS = 16
SIGMA_ACROSS = 0.45  # periods: Hong et al.'s 4 px at a 9 px period
SIGMA_ALONG = 0.9  # periods: longer along the ridges, over a pore or a break
ORIENTATION_PERIODS = 1.5  # smoothing of the structure tensor, periods


def _structure_tensor(texture: np.ndarray, weight: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(gxx, gyy, gxy)``: the texture's structure tensor averaged over ``sigma`` pixels inside ``weight``."""
    gxx, gxy, gyy = np.moveaxis(structure_products(texture, sigma, weight), -1, 0)
    return gxx, gyy, gxy


def _kernel(angle: float, period: float) -> np.ndarray:
    """Zero-mean Gabor kernel whose ridges run along ``angle`` (radians, image x right, y down)."""
    half = int(np.ceil(3 * SIGMA_ALONG * period))
    y, x = np.mgrid[-half:half + 1, -half:half + 1].astype(np.float64)
    along = x * np.cos(angle) + y * np.sin(angle)
    across = -x * np.sin(angle) + y * np.cos(angle)
    envelope = np.exp(-0.5 * (along / (SIGMA_ALONG * period)) ** 2 - 0.5 * (across / (SIGMA_ACROSS * period)) ** 2)
    kernel = envelope * np.cos(2 * np.pi * across / period)
    kernel -= envelope * (kernel.sum() / envelope.sum())  # no response to flat grey
    return (kernel / np.abs(kernel).sum()).astype(np.float32)


def gabor_enhance(texture: np.ndarray, mask: np.ndarray, period: float) -> np.ndarray:
    """The enhanced texture ``[H, W]`` float32 (module docstring); ridges keep the sign they have in ``texture``."""
    texture = np.asarray(texture, np.float32)
    weight = np.asarray(mask, np.float32)
    period = float(max(period, 3.0))
    gxx, gyy, gxy = _structure_tensor(texture, weight, ORIENTATION_PERIODS * period)
    ridge_angle = (0.5 * np.arctan2(2 * gxy, gxx - gyy) + 0.5 * np.pi) % np.pi  # gradients run across the ridges
    position = ridge_angle / np.pi * ORIENTATIONS
    low = np.floor(position).astype(int) % ORIENTATIONS
    share = (position - np.floor(position)).astype(np.float32)
    response = np.zeros_like(texture)
    for k in range(ORIENTATIONS):
        filtered = cv2.filter2D(texture * weight, -1, _kernel(k * np.pi / ORIENTATIONS, period), borderType=cv2.BORDER_CONSTANT)
        response += np.where(low == k, 1.0 - share, 0.0) * filtered
        response += np.where((low + 1) % ORIENTATIONS == k, share, 0.0) * filtered
    rms = np.sqrt(masked_blur(response * response, weight, period) + 1e-12)
    return np.where(weight > 0, response / rms, 0.0).astype(np.float32)


def ridge_coherence(texture: np.ndarray, mask: np.ndarray, period: float, periods: float = 3.0) -> np.ndarray:
    """How consistently ridges run one way around each pixel, in [0, 1]: ``(l1 - l2) / (l1 + l2)`` of the structure
    tensor smoothed over ``periods`` ridge periods (1 for parallel ridges, ~0 for noise or a blend of two
    misregistered patterns; cores and deltas are low too, over about a period)."""
    texture = np.asarray(texture, np.float32)
    weight = np.asarray(mask, np.float32)
    gxx, gyy, gxy = _structure_tensor(texture, weight, periods * max(float(period), 3.0))
    coherence = np.sqrt((gxx - gyy) ** 2 + 4 * gxy * gxy) / np.maximum(gxx + gyy, 1e-12)
    return np.where(weight > 0, np.clip(coherence, 0.0, 1.0), 0.0).astype(np.float32)
