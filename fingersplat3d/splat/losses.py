"""Photometric losses for fitting Gaussians: masked L1, SSIM (as in 3DGS) and their mix.

Images are ``[H, W, C]`` (or ``[H, W]``, read as one channel) float tensors in [0, 1]. A mask is
``[H, W]`` (bool, or float weights in [0, 1]); every masked mean is ``sum(w * x) / max(sum(w), 1)``
so an empty mask gives a finite 0 with a finite (zero) gradient instead of 0 / 0.

SSIM follows the 3DGS training code: an 11x11 Gaussian window (sigma 1.5) applied per channel
(separably) with zero padding, ``C1 = 0.01^2``, ``C2 = 0.03^2``; the SSIM
map is computed on the whole image and averaged over the mask.

Pure math: no Open3D, no files.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["gaussian_window", "ssim_map", "ssim", "masked_l1", "photometric_loss",
           "SSIM_WINDOW", "SSIM_SIGMA", "SSIM_C1", "SSIM_C2"]

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_C1 = 0.01 ** 2
SSIM_C2 = 0.03 ** 2


def gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA, *, dtype: torch.dtype = torch.float32,
                    device: torch.device | str | None = None) -> torch.Tensor:
    """The normalised separable Gaussian window ``[size, size]`` (sums to 1)."""
    x = torch.arange(size, dtype=torch.float64) - (size - 1) / 2.0
    g = torch.exp(-(x * x) / (2.0 * sigma * sigma))
    g = g / g.sum()
    return torch.outer(g, g).to(dtype=dtype, device=device)


def _as_hwc(image: torch.Tensor, name: str) -> torch.Tensor:
    if image.ndim == 2:
        return image[..., None]
    if image.ndim != 3:
        raise ValueError(f"{name} must be [H, W] or [H, W, C], got shape {tuple(image.shape)}")
    return image


def _check_pair(render: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    render, target = _as_hwc(render, "render"), _as_hwc(target, "target")
    if render.shape != target.shape:
        raise ValueError(f"render {tuple(render.shape)} and target {tuple(target.shape)} differ in shape")
    return render, target.to(dtype=render.dtype, device=render.device)


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


def ssim_map(render: torch.Tensor, target: torch.Tensor, *, window_size: int = SSIM_WINDOW,
             sigma: float = SSIM_SIGMA) -> torch.Tensor:
    """Per-pixel SSIM ``[H, W, C]`` of two ``[H, W, C]`` images (3DGS formulation, zero padding).

    The 2D Gaussian window is separable: the five blurred images are filtered in one batch, first
    along rows then along columns (22 taps instead of 121; the 2D convolution's backward dominated
    a fitting step on the CPU).
    """
    render, target = _check_pair(render, target)
    channels = render.shape[-1]
    x = render.permute(2, 0, 1)[None]  # [1, C, H, W]
    y = target.permute(2, 0, 1)[None]
    pad = window_size // 2
    taps = torch.arange(window_size, dtype=torch.float64) - (window_size - 1) / 2.0
    g = torch.exp(-(taps * taps) / (2.0 * sigma * sigma))
    g = (g / g.sum()).to(dtype=render.dtype, device=render.device)
    stack = torch.cat([x, y, x * x, y * y, x * y], dim=1)  # [1, 5C, H, W]
    groups = stack.shape[1]
    rows = F.conv2d(stack, g.view(1, 1, 1, -1).expand(groups, 1, 1, window_size), padding=(0, pad), groups=groups)
    blurred = F.conv2d(rows, g.view(1, 1, -1, 1).expand(groups, 1, window_size, 1), padding=(pad, 0), groups=groups)
    mu_x, mu_y, e_xx, e_yy, e_xy = blurred.split(channels, dim=1)
    mu_xx, mu_yy, mu_xy = mu_x * mu_x, mu_y * mu_y, mu_x * mu_y
    var_x = e_xx - mu_xx
    var_y = e_yy - mu_yy
    cov_xy = e_xy - mu_xy
    numerator = (2.0 * mu_xy + SSIM_C1) * (2.0 * cov_xy + SSIM_C2)
    denominator = (mu_xx + mu_yy + SSIM_C1) * (var_x + var_y + SSIM_C2)
    return (numerator / denominator)[0].permute(1, 2, 0)


def _crop_to_mask(render: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None, halo: int):
    """The window of the images that the masked SSIM mean depends on: the mask's bounding box grown
    by the filter's half-width (exact: pixels farther out never reach a masked pixel's window)."""
    if weights is None:
        return render, target, weights
    rows, cols = torch.nonzero(weights.sum(1)), torch.nonzero(weights.sum(0))
    if len(rows) == 0:
        return render, target, weights
    top, bottom = max(0, int(rows[0]) - halo), int(rows[-1]) + halo + 1
    left, right = max(0, int(cols[0]) - halo), int(cols[-1]) + halo + 1
    return render[top:bottom, left:right], target[top:bottom, left:right], weights[top:bottom, left:right]


def ssim(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean SSIM (scalar) over the mask (``[H, W]``; None = whole image); 0 for an empty mask."""
    render, target = _check_pair(render, target)
    return _masked_mean(ssim_map(render, target), _mask_weights(mask, render))


def masked_l1(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean absolute difference (scalar) over the mask and channels; 0 for an empty mask."""
    render, target = _check_pair(render, target)
    return _masked_mean((render - target).abs(), _mask_weights(mask, render))


def photometric_loss(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None,
                     lambda_dssim: float = 0.2) -> torch.Tensor:
    """``(1 - lambda) * L1 + lambda * (1 - SSIM)`` over the finger mask (the paper's loss, lambda 0.2).

    ``render``/``target`` ``[H, W, C]``, ``mask`` ``[H, W]`` (None = whole image). An empty mask
    gives 0 (both terms vanish) with a zero, finite gradient.
    """
    if not 0.0 <= lambda_dssim <= 1.0:
        raise ValueError(f"lambda_dssim must be in [0, 1], got {lambda_dssim}")
    render, target = _check_pair(render, target)
    weights = _mask_weights(mask, render)
    l1 = _masked_mean((render - target).abs(), weights)
    if lambda_dssim == 0.0:
        return l1
    render, target, weights = _crop_to_mask(render, target, weights, SSIM_WINDOW // 2)
    structure = _masked_mean(1.0 - ssim_map(render, target), weights)
    return (1.0 - lambda_dssim) * l1 + lambda_dssim * structure
