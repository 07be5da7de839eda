"""Photos of a finger thicker or thinner than the one taken (``tools/degrade_photos.py --kind thin|thick``).

Photos stretched across the finger by ``s`` about their centres are *exactly* the photos of the finger scaled by ``s``
about its axis, taken by cameras moved out with it whose focal is ``s`` times theirs, wherever each camera's rows
(columns) run along the finger, as a ring's do: with ``y = f Y / Z``, scaling ``Y``, ``Z`` and ``f`` by ``s`` scales
``y`` by ``s`` and keeps ``x = f X / Z``. So the relative rotations of the stretched views are the original ones and
their focal ``s`` times it: a check that nothing in the fuse assumes a finger's width in pixels, or its width against
its length, that needs no new ground truth. Pure OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["stretched_across", "FINGER_AXES"]

FINGER_AXES = ("auto", "horizontal", "vertical")


def stretched_across(image: np.ndarray, factor: float, finger_axis: str = "auto") -> np.ndarray:
    """``image`` scaled by ``factor`` across the finger about its centre, its size kept (edges mirrored); the finger
    along the rows (``horizontal``), the columns (``vertical``) or the long side (``auto``, as in a rig's frames)."""
    if finger_axis not in FINGER_AXES:
        raise ValueError(f"finger_axis must be one of {FINGER_AXES}, not {finger_axis!r}")
    height, width = image.shape[:2]
    centre = ((width - 1) / 2, (height - 1) / 2)
    along_rows = finger_axis == "horizontal" or (finger_axis == "auto" and width >= height)
    sx, sy = (1.0, factor) if along_rows else (factor, 1.0)
    warp = np.array([[sx, 0, centre[0] * (1 - sx)], [0, sy, centre[1] * (1 - sy)]])
    return cv2.warpAffine(image, warp, (width, height), flags=cv2.INTER_AREA if factor < 1 else cv2.INTER_CUBIC,
                          borderMode=cv2.BORDER_REFLECT_101)
