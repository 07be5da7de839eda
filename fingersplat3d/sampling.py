"""Sampling an image or a map at sub-pixel positions, and resampling it onto another grid (pixel centres at integer
coordinates: a pixel ``x`` of a ``w``-wide grid is ``(x + 0.5) * W / w - 0.5`` of a ``W``-wide one, as OpenCV's
resizing has it).

Pure numpy/scipy/OpenCV (torch, imported where used, for the differentiable sampler): no Open3D, no files.
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

__all__ = ["sample_bilinear", "sample_nearest", "sample_bilinear_torch", "resized_image", "resized_mask", "map_on_grid"]


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


def resized_image(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` at ``size`` = (width, height): area averaging down, bilinear up."""
    if (image.shape[1], image.shape[0]) == tuple(size):
        return image
    shrink = size[0] < image.shape[1]
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def resized_mask(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A bool mask at ``size`` = (width, height): its coverage resampled and cut at one half (smooth edges both ways)."""
    if (mask.shape[1], mask.shape[0]) == tuple(size):
        return np.asarray(mask, bool)
    return resized_image(np.asarray(mask, np.float32), size) > 0.5


def map_on_grid(values: np.ndarray, size: tuple[int, int], mask: np.ndarray | None = None) -> np.ndarray:
    """A per-pixel map (NaN where it has no value) resampled to ``size``; NaN outside ``mask`` and where no finite
    value is near. Values are averaged over finite neighbours only, so no NaN bleeds into the finger and no
    background into its rim."""
    values = np.asarray(values, np.float32)
    if (values.shape[1], values.shape[0]) == tuple(size):
        out = values.copy()
    else:
        finite = np.isfinite(values)
        weight = resized_image(finite.astype(np.float32), size)
        total = resized_image(np.where(finite, values, 0.0).astype(np.float32), size)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = np.where(weight > 1e-3, total / weight, np.nan).astype(np.float32)
    if mask is not None:
        out[~np.asarray(mask, bool)] = np.nan
    return out
