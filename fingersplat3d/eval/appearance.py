"""How a finger photo looks, in numbers: the statistics ``fs3d synth`` is matched to real captures by.

:func:`image_statistics` measures one view (image in [0, 1] and its finger mask):

* ``skin``: median intensity on the finger; ``background`` and ``noise``: median and robust
  deviation (:func:`~fingersplat3d.robust.robust_sigma`, 1.4826 MAD) of the background away from the finger;
* ``ridge_contrast``: RMS of the ridge band (difference of Gaussians around the ridge period) in the
  finger's core, over the skin level: how visible the ridges are;
* ``ridge_period_px``: :func:`~fingersplat3d.align.correspond.texture.estimate_ridge_period`;
* ``edge_blur_px``: the Gaussian sigma that explains the silhouette's edge, from the steepest
  gradient across it, ``sigma = step / (sqrt(2 pi) * max |grad|)`` (median along the outline;
  includes the skin darkening toward the rim, so it is an upper bound of the optics' blur);
* ``rim_shading``: skin intensity next to the silhouette (2-6 % of the finger width in) over the
  intensity in the core (beyond 25 %): below 1 when the sides are darker;
* ``width_fraction``: median finger width across its axis over the image's short side;
* ``glints``: share of finger pixels that are specular specks
  (:func:`~fingersplat3d.align.correspond.texture.suppress_glints`'s test).

Pure numpy/OpenCV.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np

from ..align.correspond.texture import as_gray, estimate_ridge_period, suppress_glints
from ..robust import robust_sigma
from ..segment.morphology import outline
from ..segment.silhouette import silhouette_frame

__all__ = ["ImageStatistics", "image_statistics"]


@dataclass(frozen=True)
class ImageStatistics:
    skin: float
    background: float
    noise: float
    ridge_contrast: float
    ridge_period_px: float
    edge_blur_px: float
    rim_shading: float
    width_fraction: float
    glints: float

    def as_dict(self) -> dict:
        return asdict(self)


def image_statistics(image: np.ndarray, mask: np.ndarray) -> ImageStatistics:
    """The statistics of one view (see the module docstring)."""
    gray = as_gray(image).astype(np.float32)
    mask = np.asarray(mask, bool)
    inside = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5)
    outside = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    frame = silhouette_frame(mask)
    width = 2.0 * float(np.median(frame.sections.half_width))
    skin = float(np.median(gray[mask]))
    far = outside > max(10.0, 0.05 * width)
    background_values = gray[far] if far.any() else gray[~mask]
    background = float(np.median(background_values)) if background_values.size else 0.0
    noise = robust_sigma(background_values, background)
    period = estimate_ridge_period(gray, mask)
    core = inside > 0.25 * width
    band = cv2.GaussianBlur(gray, (0, 0), 0.18 * period) - cv2.GaussianBlur(gray, (0, 0), 0.6 * period)
    contrast = float(np.sqrt(np.mean(band[core] ** 2)) / max(skin, 1e-6)) if core.any() else float("nan")
    rim = (inside > 0.02 * width) & (inside < 0.06 * width)
    rim_shading = float(np.median(gray[rim]) / max(np.median(gray[core]), 1e-6)) if rim.any() and core.any() else float("nan")
    return ImageStatistics(skin, background, noise, contrast, period, _edge_blur(gray, mask, skin, background),
                           rim_shading, width / min(mask.shape), _glint_share(gray, mask))


def _edge_blur(gray: np.ndarray, mask: np.ndarray, skin: float, background: float) -> float:
    """Median over the outline of ``step / (sqrt(2 pi) max |grad|)`` within 4 px of it."""
    smooth = cv2.GaussianBlur(gray, (0, 0), 0.7)
    grad = np.hypot(cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3)) / 8.0
    peak = cv2.dilate(grad, np.ones((9, 9), np.uint8))
    edge = outline(mask)
    rows, cols = mask.shape
    edge[[0, -1], :] = False
    edge[:, [0, -1]] = False
    edge &= (np.arange(rows)[:, None] > 4) & (np.arange(rows)[:, None] < rows - 5)
    edge &= (np.arange(cols)[None, :] > 4) & (np.arange(cols)[None, :] < cols - 5)
    steepest = peak[edge]
    if steepest.size == 0:
        return float("nan")
    step = max(skin - background, 1e-6)
    return float(np.median(step / (np.sqrt(2 * np.pi) * np.maximum(steepest, 1e-6))))


def _glint_share(gray: np.ndarray, mask: np.ndarray) -> float:
    cleaned = suppress_glints(gray, mask)
    return float(np.mean((cleaned != gray)[mask])) if mask.any() else 0.0
