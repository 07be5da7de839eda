"""Finger segmentation (classical, for dark backgrounds) and the silhouette's swept-section description."""
from .masks import finger_mask, mask_iou
from .silhouette import (TIP_BASES, Sections, SilhouetteFrame, capture_axes, chord_sections, finger_axis, orient_frames,
                         principal_axis, silhouette_frame)

__all__ = ["finger_mask", "mask_iou", "Sections", "SilhouetteFrame", "capture_axes", "chord_sections", "finger_axis", "principal_axis",
           "silhouette_frame", "orient_frames", "TIP_BASES"]
