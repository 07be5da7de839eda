"""Discs for the morphology of masks and images: the one elliptic structuring element every module grows, shrinks or
opens with (OpenCV's ``MORPH_ELLIPSE``), so that "a radius of r pixels" means the same shape everywhere."""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["disc", "eroded", "dilated", "outline"]


def disc(radius: int) -> np.ndarray:
    """``[2r+1, 2r+1]`` uint8 elliptic structuring element of ``radius`` pixels (0: the single pixel): OpenCV's, as it
    is (its top and bottom rows hold one pixel where its side columns hold a few: not its own transpose, and every mask
    threshold was measured with it)."""
    radius = int(radius)
    if radius < 0:
        raise ValueError(f"a disc's radius must be 0 or more, got {radius}")
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def eroded(mask: np.ndarray, radius: int, iterations: int = 1) -> np.ndarray:
    """``mask`` (bool) eroded by :func:`disc` of ``radius``, ``iterations`` times; pixels beyond the frame count as
    set (OpenCV's default), so a mask touching the frame is not eaten from it."""
    return cv2.erode(np.asarray(mask, np.uint8), disc(radius), iterations=iterations) > 0


def dilated(mask: np.ndarray, radius: int) -> np.ndarray:
    """``mask`` (bool) dilated by :func:`disc` of ``radius``."""
    return cv2.dilate(np.asarray(mask, np.uint8), disc(radius)) > 0


def outline(mask: np.ndarray) -> np.ndarray:
    """The pixels of ``mask`` (bool) with one of their eight neighbours outside it: its one-pixel, 8-connected rim (a
    3×3 square, not :func:`disc`, whose 4-neighbour cross would leave the rim's diagonal steps out). Pixels beyond the
    frame count as set, so the frame's edge is no outline."""
    mask = np.asarray(mask, bool)
    return mask & ~(cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
