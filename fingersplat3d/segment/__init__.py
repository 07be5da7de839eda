"""Finger segmentation (classical, for dark backgrounds) and the silhouette's swept-section description."""
from .masks import finger_mask, mask_iou
from .silhouette import (TIP_BASES, Sections, SilhouetteFrame, capture_axes, chord_sections, finger_axis, orient_frames,
                         principal_axis, silhouette_frame)
from .side_cut import capture_frames, side_cut_widths

__all__ = ["finger_mask", "mask_iou", "Sections", "SilhouetteFrame", "capture_axes", "chord_sections", "finger_axis", "principal_axis",
           "silhouette_frame", "orient_frames", "capture_frames", "side_cut_widths", "TIP_BASES"]
