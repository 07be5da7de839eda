"""Photometric losses for fitting Gaussians: masked L1, SSIM (as in 3DGS) and their mix.

Images are ``[H, W, C]`` (or ``[H, W]``, read as one channel) float tensors in [0, 1]. A mask is
``[H, W]`` (bool, or float weights in [0, 1]); every masked mean is ``sum(w * x) / max(sum(w), 1)``
so an empty mask gives a finite 0 with a finite (zero) gradient instead of 0 / 0.

SSIM is :mod:`fingersplat3d.ssim` with zero padding, as in the 3DGS training code; the SSIM map is
computed on the whole image (cropped to the mask's reach) and averaged over the mask.

Pure math: no Open3D, no files.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from ..ssim import SSIM_C1, SSIM_C2, SSIM_SIGMA, SSIM_WINDOW, SSIMReference, image_pair, ssim_map, ssim_reference

__all__ = ["ssim_map", "ssim", "masked_l1", "photometric_loss", "PhotometricTarget", "photometric_target", "SSIM_WINDOW",
           "SSIM_SIGMA", "SSIM_C1", "SSIM_C2"]


def _mask_weights(mask: torch.Tensor | None, like: torch.Tensor) -> torch.Tensor | None:
    """``[H, W]`` float weights on ``like``'s device, or None for the whole image."""
    if mask is None:
        return None
    mask = torch.as_tensor(mask, device=like.device)
    if tuple(mask.shape) != tuple(like.shape[:2]):
        raise ValueError(f"mask {tuple(mask.shape)} does not match the image {tuple(like.shape[:2])}")
    return mask.to(like.dtype)


def _masked_mean(values: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    """Mean of ``values [H, W, C]`` over the weighted pixels (and channels); 0 for an empty mask."""
    if weights is None:
        return values.mean()
    total = (values * weights[..., None]).sum()
    count = weights.sum() * values.shape[-1]
    return total / count.clamp_min(1.0)


def _mask_window(weights: torch.Tensor | None, halo: int) -> tuple[slice, slice]:
    """The window of the images that the masked SSIM mean depends on: the mask's bounding box grown
    by the filter's half-width (exact: pixels farther out never reach a masked pixel's window)."""
    whole = (slice(None), slice(None))
    if weights is None:
        return whole
    rows, cols = torch.nonzero(weights.sum(1)), torch.nonzero(weights.sum(0))
    if len(rows) == 0:
        return whole
    top, bottom = max(0, int(rows[0]) - halo), int(rows[-1]) + halo + 1
    left, right = max(0, int(cols[0]) - halo), int(cols[-1]) + halo + 1
    return slice(top, bottom), slice(left, right)


@dataclass(frozen=True, eq=False)
class PhotometricTarget:
    """A target image and its mask prepared once for :func:`photometric_loss` (a fit compares each view's photo with a
    render at every step): its mask weights, the window its SSIM mean reads and the photo's side of that SSIM."""

    image: torch.Tensor  # [H, W, C]
    weights: torch.Tensor | None  # [H, W] float, None: the whole image
    window: tuple[slice, slice]
    reference: SSIMReference  # of image[window]


def photometric_target(target: torch.Tensor, mask: torch.Tensor | None = None) -> PhotometricTarget:
    """``target`` ``[H, W]`` or ``[H, W, C]`` with its ``mask`` (None: the whole image), ready for many
    :func:`photometric_loss` calls."""
    image, _ = image_pair(target, target)
    weights = _mask_weights(mask, image)
    window = _mask_window(weights, SSIM_WINDOW // 2)
    return PhotometricTarget(image, weights, window, ssim_reference(image[window]))


def ssim(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean SSIM (scalar) over the mask (``[H, W]``; None = whole image); 0 for an empty mask."""
    render, target = image_pair(render, target)
    return _masked_mean(ssim_map(render, target), _mask_weights(mask, render))


def masked_l1(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean absolute difference (scalar) over the mask and channels; 0 for an empty mask."""
    render, target = image_pair(render, target)
    return _masked_mean((render - target).abs(), _mask_weights(mask, render))


def photometric_loss(render: torch.Tensor, target: torch.Tensor | PhotometricTarget, mask: torch.Tensor | None = None,
                     lambda_dssim: float = 0.2) -> torch.Tensor:
    """``(1 - lambda) * L1 + lambda * (1 - SSIM)`` over the finger mask (the paper's loss, lambda 0.2).

    ``render``/``target`` ``[H, W, C]``, ``mask`` ``[H, W]`` (None = whole image); or ``target`` made once by
    :func:`photometric_target` with its mask (then ``mask`` is None), the same loss to the bit. An empty mask
    gives 0 (both terms vanish) with a zero, finite gradient.
    """
    if not 0.0 <= lambda_dssim <= 1.0:
        raise ValueError(f"lambda_dssim must be in [0, 1], got {lambda_dssim}")
    if isinstance(target, PhotometricTarget):
        if mask is not None:
            raise ValueError("a prepared photometric target holds its own mask")
        prepared = target
    else:  # the target on the render's dtype and device, as a prepared one would be
        prepared = photometric_target(image_pair(render, target)[1], mask)
    render, _ = image_pair(render, prepared.image)
    image, weights = prepared.image, prepared.weights
    l1 = _masked_mean((render - image).abs(), weights)
    if lambda_dssim == 0.0:
        return l1
    window = prepared.window
    inside = None if weights is None else weights[window]
    structure = _masked_mean(1.0 - ssim_map(render[window], prepared.reference), inside)
    return (1.0 - lambda_dssim) * l1 + lambda_dssim * structure
