"""Photos turned in their own plane (``tools/degrade_photos.py --kind quarter|roll``), as a hand-held phone takes them.

A photo turned about its centre by ``a`` degrees is *exactly* the photo of the same camera rolled about its optical
axis (the principal point at the centre, square pixels), its corners cut: a pixel ``p`` moves to ``c + A (p - c)``
with ``A`` the turn, and so does every normalised ray, so the rolled camera's world-to-camera rotation is ``Rz R``
with ``Rz`` = ``A`` on x, y (:func:`roll_rotation`). The turns between cameras then change by the known rolls alone,
and a fixed set of rolls per camera is another rig: a check that nothing in the fuse assumes the finger lies along
the photo's rows, or along the same direction in every view, that needs no new ground truth. Pure OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["rolled_in_plane", "roll_rotation", "quarter_turned"]


def roll_rotation(degrees: float) -> np.ndarray:
    """``[3, 3]``: the rotation taking a camera's frame to that of the camera rolled so that its photo is the original
    turned by ``degrees`` (OpenCV's sense: counter-clockwise as the photo is shown)."""
    turn = cv2.getRotationMatrix2D((0.0, 0.0), float(degrees), 1.0)[:, :2]
    rotation = np.eye(3)
    rotation[:2, :2] = turn
    return rotation


def rolled_in_plane(image: np.ndarray, degrees: float) -> np.ndarray:
    """``image`` turned by ``degrees`` about its centre, its size kept; what the turn brings in from outside the frame
    is the median of the frame's border (the background a photo shows there, not a mirrored finger)."""
    height, width = image.shape[:2]
    warp = cv2.getRotationMatrix2D(((width - 1) / 2, (height - 1) / 2), float(degrees), 1.0)
    border = np.concatenate([image[0].reshape(-1, *image.shape[2:]), image[-1].reshape(-1, *image.shape[2:]),
                             image[:, 0].reshape(-1, *image.shape[2:]), image[:, -1].reshape(-1, *image.shape[2:])])
    fill = np.median(border, axis=0)
    fill = tuple(float(v) for v in np.atleast_1d(fill)) + (0.0,) * (4 - np.atleast_1d(fill).size)
    return cv2.warpAffine(image, warp, (width, height), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_CONSTANT,
                          borderValue=fill)


def quarter_turned(image: np.ndarray) -> np.ndarray:
    """``image`` turned a quarter clockwise (landscape to portrait), every pixel kept."""
    return np.ascontiguousarray(np.rot90(image, -1))
