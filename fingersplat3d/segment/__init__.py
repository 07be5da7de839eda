"""Finger segmentation (classical, for dark backgrounds)."""
from .masks import finger_mask, mask_iou

__all__ = ["finger_mask", "mask_iou"]
