"""Region helpers both finger segmentations share (pure OpenCV)."""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["fill_holes"]


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """Fill background regions that do not reach the image border."""
    count, labels = cv2.connectedComponents((~mask).view(np.uint8), connectivity=4)
    if count <= 2:
        return mask
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    outside = np.isin(labels, border[border > 0])
    return ~outside
