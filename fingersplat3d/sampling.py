"""Sampling an image or a map at sub-pixel positions (pixel centres at integer coordinates).

Pure numpy/scipy (torch, imported where used, for the differentiable sampler): no Open3D, no files.
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

__all__ = ["sample_bilinear", "sample_nearest", "sample_bilinear_torch"]


def sample_bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``image [H, W]`` at ``uv [N, 2]`` (u right, v down): bilinear, NaN outside the image or next to a NaN pixel."""
    image = np.asarray(image, np.float64)
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    height, width = image.shape
    inside = np.isfinite(uv).all(1) & (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] <= height - 1)
    values = np.full(len(uv), np.nan)
    if inside.any():
        values[inside] = map_coordinates(image, [uv[inside, 1], uv[inside, 0]], order=1, mode="nearest")
    return values


def sample_nearest(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``image [H, W]`` at ``uv [N, 2]``: the nearest pixel's value (no blending across an edge of
    a depth map), NaN outside the image."""
    image = np.asarray(image)
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    height, width = image.shape
    col, row = np.rint(uv[:, 0]), np.rint(uv[:, 1])
    inside = np.isfinite(col) & np.isfinite(row) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
    values = np.full(len(uv), np.nan)
    values[inside] = image[row[inside].astype(int), col[inside].astype(int)]
    return values


def sample_bilinear_torch(image, uv):
    """Torch ``image [H, W]`` at ``uv [N, 2]`` (u right, v down): bilinear and differentiable in both, 0 outside
    the image (what :func:`sample_bilinear` gives inside it)."""
    import torch

    h, w = image.shape[-2:]
    grid = torch.stack([2 * uv[:, 0] / max(w - 1, 1) - 1, 2 * uv[:, 1] / max(h - 1, 1) - 1], -1)
    return torch.nn.functional.grid_sample(image.reshape(1, 1, h, w), grid[None, None].to(image.dtype), mode="bilinear",
                                           padding_mode="zeros", align_corners=True)[0, 0, 0]
