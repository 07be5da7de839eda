"""Minutiae by pyfing's LEADER (a learned end-to-end extractor), the alternative to mindtct, and pyfing's loader.

``pyfing`` (Cappelli's fingerprint library) ships LEADER's weights inside its wheel; Keras 3 runs it on the torch
backend (no TensorFlow). :func:`leader_minutiae` gives what mindtct gives (:func:`.fingerprint.analyse`): each
minutia's pixel, direction (degrees, counter-clockwise from +x with y up: LEADER's radians in mindtct's convention,
checked on the same prints to a few degrees), kind and a 0-1 quality. Minutiae off the print's skin (its white
ground, 255, as everywhere in the project) are dropped, as mindtct's are by its own map (LEADER put none there on the
prints measured, 2-7 within 8 px of the skin's edge).

Measured against mindtct (docs/measurements.md, stop 83; bozorth3 on the same extractor's minutiae both sides):
mindtct stays the default. LEADER finds about half as many minutiae and locates the true ones as often or more
(synthetic model prints: median 76 % either way; photo prints 69 / 72 % against 63 / 67 %), but bozorth3 scores the
same finger's pairs lower: model prints against their true prints 81 against 155 (impostors 5 against 15 at most),
photo prints unrolled 66 against 116 with the lowest genuine score (4) under the highest impostor's (21), another
group's renders unrolled (IMPOSE) 51 against 72; on the real dev captures 43.8 / 37.5 / 41.6 % EER against 30.8 /
36.2 / 45.9 % (photos, rolled prints, rolled prints against photos; all near chance).
"""
from __future__ import annotations

import os

import numpy as np

from ..errors import InputError

__all__ = ["MINUTIAE_EXTRACTORS", "load_pyfing", "leader_minutiae"]

MINUTIAE_EXTRACTORS = ("mindtct", "leader")
"""The minutiae bozorth3 compares (:func:`.fingerprint.analyse`): NIST's mindtct (the default) or LEADER."""


def load_pyfing():
    """The ``pyfing`` module, imported on first use with Keras on the torch backend; one sentence when missing."""
    os.environ.setdefault("KERAS_BACKEND", "torch")  # before Keras is first imported: no TensorFlow needed
    try:
        import pyfing
    except ImportError as error:
        raise InputError("pyfing's learned models need pyfing and Keras 3: pip install 'fingersplat3d[learned]' "
                         f"({error})") from None
    return pyfing


def leader_minutiae(image: np.ndarray, dpi: int = 500) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], np.ndarray]:
    """``(xy [N, 2], angles_deg [N], kinds, quality [N])`` of the minutiae LEADER finds on the skin of an 8-bit print
    (ridges dark, white outside the finger, ~``dpi``)."""
    import cv2
    import torch

    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 2:
        raise ValueError(f"LEADER reads an 8-bit gray print, got {image.dtype} of shape {image.shape}")
    library = load_pyfing()
    skin = cv2.erode((image < 255).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    with torch.no_grad():  # Keras on torch returns tensors that require grad, which pyfing reads with .numpy()
        found = library.minutiae_extraction(image, dpi, method="LEADER")
    height, width = image.shape
    kept = [m for m in found if 0 <= m.x < width and 0 <= m.y < height and skin[int(m.y), int(m.x)]]
    xy = np.array([[m.x, m.y] for m in kept], np.float64).reshape(-1, 2)
    angles = np.array([np.degrees(m.direction) % 360.0 for m in kept], np.float64)
    kinds = tuple("bifurcation" if m.type == "B" else "ending" for m in kept)
    quality = np.array([m.quality for m in kept], np.float64)
    return xy, angles, kinds, quality
