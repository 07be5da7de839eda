"""Print enhancement by ``pyfing`` (Cappelli's fingerprint library), the alternative to :func:`.enhance.gabor_enhance`.

``pyfing`` ships learned models inside its wheel (SNFOE ridge orientation, SNFFE ridge frequency,
SNFEN enhancement; Keras 3 on the torch backend, no TensorFlow) and classical ones (GBFOE, XSFFE,
GBFEN). Two enhancers are offered here with the same contract as ``gabor_enhance`` (a float32 texture,
ridges positive, unit RMS inside the mask, 0 outside):

* ``snfen``: SNFOE orientations, the print's own ridge period, SNFEN enhancement (learned);
* ``gbfen``: GBFOE orientations, the print's own ridge period, GBFEN (a Gabor filter bank, classical).

The period map is the print's single measured period: the rolled-equivalent print is made at a fixed
scale, so its period is uniform by construction, and that one number is measured on the print itself.
Measured against the default (``tools/bench_print.py --enhance``, docs/measurements.md): see there for
which wins. ``pyfing`` and Keras are optional (``pip install fingersplat3d[learned]``) and imported on
first use, with one sentence when missing. Pure numpy apart from the library call.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..eval.learned_minutiae import load_pyfing
from ..robust import robust_sigma

__all__ = ["pyfing_enhance", "LEARNED_ENHANCERS", "ENHANCERS"]

LEARNED_ENHANCERS = {"snfen": ("SNFOE", "SNFEN"), "gbfen": ("GBFOE", "GBFEN")}
"""Enhancer name -> (pyfing orientation method, pyfing enhancement method)."""
ENHANCERS = ("gabor", *LEARNED_ENHANCERS)
"""Every print enhancer's name: the built-in Gabor filter (:func:`.enhance.gabor_enhance`), then pyfing's."""


def as_fingerprint(texture: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A texture (ridges positive, any scale) as the uint8 image fingerprint tools expect: ridges dark on a light
    ground, 3 robust standard deviations over the gray range, white outside ``mask``."""
    texture = np.asarray(texture, np.float64)
    inside = np.asarray(mask, bool)
    values = texture[inside]
    spread = robust_sigma(values)
    centred = (texture - (np.median(values) if values.size else 0.0)) / max(spread, 1e-12)
    image = np.clip(128.0 - 40.0 * centred, 0, 255)
    return np.where(inside, image, 255).astype(np.uint8)


def pyfing_enhance(texture: np.ndarray, mask: np.ndarray, period: float, method: str = "snfen", dpi: int = 500) -> np.ndarray:
    """The print texture enhanced by ``pyfing`` (module docstring): ``[H, W]`` float32, ridges positive, unit RMS
    inside ``mask``, 0 outside."""
    import torch

    if method not in LEARNED_ENHANCERS:
        raise InputError(f"unknown learned enhancer {method!r}; choose from {sorted(LEARNED_ENHANCERS)}")
    library = load_pyfing()
    orientation_method, enhancement_method = LEARNED_ENHANCERS[method]
    inside = np.asarray(mask, bool)
    if not inside.any():
        return np.zeros(inside.shape, np.float32)
    fingerprint = as_fingerprint(texture, mask)
    segmentation = np.where(inside, 255, 0).astype(np.uint8)
    periods = np.full(fingerprint.shape, float(period), np.float32)
    with torch.no_grad():  # Keras on torch returns tensors that require grad, which pyfing reads with .numpy()
        orientation = library.orientation_field_estimation(fingerprint, segmentation, dpi, method=orientation_method)
        enhanced = library.fingerprint_enhancement(fingerprint, orientation, periods, segmentation, dpi,
                                                   method=enhancement_method)
    # pyfing: ridges near-white (255), valleys near-black; here ridges positive, zero mean, unit RMS on the skin.
    signal = np.asarray(enhanced, np.float64) / 255.0 - 0.5
    signal = signal - float(signal[inside].mean())
    rms = float(np.sqrt(np.mean(signal[inside] ** 2)))
    return np.where(inside, signal / max(rms, 1e-12), 0.0).astype(np.float32)
