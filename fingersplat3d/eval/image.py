"""Image-quality scores for rendered views: masked PSNR, masked SSIM, alpha leaking off the mask.

Images are numpy ``[H, W]`` or ``[H, W, C]`` floats in [0, 1] (data range 1); masks ``[H, W]``
bool (None = the whole image). Scores are plain floats.

* PSNR = ``10 log10(1 / MSE)`` with the MSE over the mask pixels and all channels
  (``inf`` for identical images).
* SSIM: :func:`fingersplat3d.ssim.ssim_map` (Wang et al. 2004, the same SSIM that trains the
  splats), the map computed per channel on the *full* image (reflected borders, so nothing
  outside the image counts) and then averaged over the mask pixels and channels. Near the mask
  edge the window also sees pixels just outside the mask, as it would for any crop of the image.

numpy in, floats out; no Open3D, no files.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["ImageScores", "image_scores", "masked_psnr", "masked_ssim", "ssim_map", "fraction_alpha_outside"]

class ImageScores(NamedTuple):
    """Quality of one rendered view against its photo, inside the mask."""

    psnr: float  # dB; inf when identical inside the mask
    ssim: float  # mean SSIM inside the mask, in [-1, 1]
    pixels: int  # mask pixels scored


def image_scores(render: np.ndarray, target: np.ndarray, mask: np.ndarray | None = None) -> ImageScores:
    """PSNR and SSIM of ``render`` against ``target`` inside ``mask``."""
    render, target, mask = _validate(render, target, mask)
    return ImageScores(_psnr(render, target, mask), _mean_in_mask(ssim_map(render, target), mask),
                       int(np.count_nonzero(mask)))


def masked_psnr(render: np.ndarray, target: np.ndarray, mask: np.ndarray | None = None) -> float:
    """PSNR (dB, data range 1) over the mask pixels and all channels."""
    return _psnr(*_validate(render, target, mask))


def masked_ssim(render: np.ndarray, target: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean SSIM inside the mask, the SSIM map computed on the full image."""
    render, target, mask = _validate(render, target, mask)
    return _mean_in_mask(ssim_map(render, target), mask)


def ssim_map(render: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Per-pixel SSIM ``[H, W, C]`` of two ``[H, W, C]`` float64 images (reflected borders)."""
    import torch

    from ..ssim import ssim_map as torch_ssim_map

    return torch_ssim_map(torch.from_numpy(np.asarray(render, np.float64)), torch.from_numpy(np.asarray(target, np.float64)),
                          padding="reflect").numpy()


def fraction_alpha_outside(alpha: np.ndarray, mask: np.ndarray) -> float:
    """The share of the rendered opacity ``alpha [H, W]`` that lies outside ``mask [H, W]``.

    ``sum(alpha outside) / sum(alpha)``; 0 for an empty render. Measures how much a splat leaks
    onto the background (what mask voting removes).
    """
    alpha = np.asarray(alpha, np.float64)
    mask = np.asarray(mask, bool)
    if alpha.shape != mask.shape or alpha.ndim != 2:
        raise ValueError(f"alpha {alpha.shape} and mask {mask.shape} must be the same [H, W] shape")
    total = float(alpha.sum())
    return 0.0 if total <= 0 else float(alpha[~mask].sum()) / total


def _validate(render: np.ndarray, target: np.ndarray, mask: np.ndarray | None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    render = np.asarray(render, np.float64)
    target = np.asarray(target, np.float64)
    if render.shape != target.shape:
        raise ValueError(f"render {render.shape} and target {target.shape} differ in shape")
    if render.ndim == 2:
        render, target = render[..., None], target[..., None]
    if render.ndim != 3:
        raise ValueError(f"images must be [H, W] or [H, W, C], got {render.shape}")
    if not (np.all(np.isfinite(render)) and np.all(np.isfinite(target))):
        raise ValueError("images contain NaN or Inf")
    if mask is None:
        mask = np.ones(render.shape[:2], bool)
    mask = np.asarray(mask, bool)
    if mask.shape != render.shape[:2]:
        raise ValueError(f"mask {mask.shape} does not match the images {render.shape[:2]}")
    if not mask.any():
        raise ValueError("the mask is empty: there is nothing to score")
    return render, target, mask


def _psnr(render: np.ndarray, target: np.ndarray, mask: np.ndarray) -> float:
    mse = float(((render - target) ** 2)[mask].mean())
    return float("inf") if mse == 0 else 10.0 * np.log10(1.0 / mse)


def _mean_in_mask(values: np.ndarray, mask: np.ndarray) -> float:
    return float(values[mask].mean())
