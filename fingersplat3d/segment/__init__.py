"""Finger segmentation (classical, for dark backgrounds) and multi-view mask voting of Gaussians."""
from .masks import finger_mask, mask_iou
from .voting import CleanConfig, CleanStats, Votes, clean_with_masks, split_gaussians, straddle_axes, vote_labels

__all__ = ["finger_mask", "mask_iou",
           "CleanConfig", "CleanStats", "Votes", "clean_with_masks", "split_gaussians", "straddle_axes", "vote_labels"]
