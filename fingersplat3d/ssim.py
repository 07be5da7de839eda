"""SSIM (Wang et al. 2004), the project's one implementation: training loss and evaluation score.

An 11x11 Gaussian window (sigma 1.5), ``C1 = 0.01^2``, ``C2 = 0.03^2`` (data range 1), the
population (not sample) covariance: the settings of the 3DGS training code and of Wang et al.'s
reference. The window is separable, so the blurred images are filtered in one batch along
rows then columns (22 taps instead of 121; the 2D convolution's backward dominated a fitting
step on the CPU), as shifted multiply-adds with a hand-written adjoint (the same blur: the window
is symmetric). The target's two (its mean and second moment) can be made once
(:func:`ssim_reference`) for a photo that many renders are compared with; the render's three
(mean, second moment, product with the target) are then all a call blurs. Borders: ``zeros`` pads with zeros as 3DGS training does; ``reflect`` mirrors the
image (without repeating the edge pixel), so that nothing outside the image counts, as an
evaluation score should. ``tests/test_ssim.py`` checks it against scikit-image's
``structural_similarity`` with Wang et al.'s settings.

Images are ``[H, W, C]`` (or ``[H, W]``, read as one channel) float tensors. Pure torch.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import torch
import torch.nn.functional as F

__all__ = ["ssim_map", "ssim_reference", "SSIMReference", "image_pair", "SSIM_WINDOW", "SSIM_SIGMA", "SSIM_C1", "SSIM_C2"]

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_C1 = 0.01 ** 2
SSIM_C2 = 0.03 ** 2


def _as_hwc(image: torch.Tensor, name: str) -> torch.Tensor:
    if image.ndim == 2:
        return image[..., None]
    if image.ndim != 3:
        raise ValueError(f"{name} must be [H, W] or [H, W, C], got shape {tuple(image.shape)}")
    return image


def image_pair(render: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Both images as ``[H, W, C]`` of one shape, ``target`` on ``render``'s dtype and device (else ``ValueError``)."""
    render, target = _as_hwc(render, "render"), _as_hwc(target, "target")
    if render.shape != target.shape:
        raise ValueError(f"render {tuple(render.shape)} and target {tuple(target.shape)} differ in shape")
    return render, target.to(dtype=render.dtype, device=render.device)


def _valid_blur(stack: torch.Tensor, taps: tuple[float, ...]) -> torch.Tensor:
    """The separable window without padding (``[..., H, W]`` -> ``[..., H - 10, W - 10]``): shifted
    multiply-adds along rows then columns, which on the CPU run ~3x faster than a grouped conv2d."""
    k = len(taps)
    height, width = stack.shape[-2] - k + 1, stack.shape[-1] - k + 1
    rows = stack[..., :, 0:width] * taps[0]
    for i in range(1, k):
        rows.add_(stack[..., :, i:i + width], alpha=taps[i])
    out = rows[..., 0:height, :] * taps[0]
    for i in range(1, k):
        out.add_(rows[..., i:i + height, :], alpha=taps[i])
    return out


class _Blur(torch.autograd.Function):
    """Zero-pad by ``pad`` then :func:`_valid_blur`. The window is symmetric, so the adjoint is the
    same blur of the gradient zero-padded by the window's full width, cropped by ``pad``."""

    @staticmethod
    def forward(ctx, stack: torch.Tensor, taps: tuple[float, ...], pad: int) -> torch.Tensor:
        ctx.taps, ctx.pad = taps, pad
        return _valid_blur(F.pad(stack, (pad, pad, pad, pad)) if pad else stack, taps)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        full = len(ctx.taps) - 1
        grad_stack = _valid_blur(F.pad(grad, (full, full, full, full)), ctx.taps)
        if ctx.pad:
            grad_stack = grad_stack[..., ctx.pad:-ctx.pad, ctx.pad:-ctx.pad]
        return grad_stack, None, None


@dataclass(frozen=True, eq=False)
class SSIMReference:
    """A fixed image's side of SSIM, made once: the image ``[1, C, H, W]`` (padded as ``padding`` asks) and its blurred
    mean and second moment. A fit compares every render of a view with one photo: its two blurs need not be redone for
    each step, nor their adjoints (two fifths of SSIM's blurring either way); the map is the same to the bit."""

    image: torch.Tensor
    mean: torch.Tensor
    square: torch.Tensor
    padding: str
    shape: tuple[int, ...]
    """The image's ``[H, W, C]``."""


@functools.cache
def _taps() -> tuple[float, ...]:
    """The window's 1D weights (made once: every SSIM call of a fit reads them)."""
    taps = torch.arange(SSIM_WINDOW, dtype=torch.float64) - (SSIM_WINDOW - 1) / 2.0
    g = torch.exp(-(taps * taps) / (2.0 * SSIM_SIGMA * SSIM_SIGMA))
    return tuple((g / g.sum()).tolist())


def _blurred(stack: torch.Tensor, padding: str) -> torch.Tensor:
    """The window over ``stack`` ``[1, K, H, W]`` -> ``[1, K, H, W]``, its borders as ``padding`` says."""
    pad = SSIM_WINDOW // 2
    if padding == "reflect":
        return _Blur.apply(F.pad(stack, (pad, pad, pad, pad), mode="reflect"), _taps(), 0)
    return _Blur.apply(stack, _taps(), pad)


def _check_padding(padding: str) -> None:
    if padding not in ("zeros", "reflect"):
        raise ValueError(f"padding must be 'zeros' or 'reflect', got {padding!r}")


def ssim_reference(target: torch.Tensor, *, padding: str = "zeros") -> SSIMReference:
    """``target``'s side of :func:`ssim_map` (``[H, W]`` or ``[H, W, C]``), for comparing many renders with it."""
    _check_padding(padding)
    target = _as_hwc(target, "target")
    y = target.permute(2, 0, 1)[None]  # [1, C, H, W]
    mean, square = _blurred(torch.cat([y, y * y], dim=1), padding).split(target.shape[-1], dim=1)
    return SSIMReference(y, mean, square, padding, tuple(target.shape))


def ssim_map(render: torch.Tensor, target: torch.Tensor | SSIMReference, *, padding: str | None = None) -> torch.Tensor:
    """Per-pixel SSIM ``[H, W, C]`` of two images of one shape; ``padding``: ``zeros`` (the default) or ``reflect``.
    ``target`` may be made once by :func:`ssim_reference`, which holds its padding."""
    if isinstance(target, SSIMReference):
        if padding is not None and padding != target.padding:
            raise ValueError(f"padding {padding!r} asked of a reference made with {target.padding!r}")
        render = _as_hwc(render, "render")
        if tuple(render.shape) != target.shape:
            raise ValueError(f"render {tuple(render.shape)} and target {target.shape} differ in shape")
        reference = target
    else:
        render, target = image_pair(render, target)
        reference = ssim_reference(target, padding=padding or "zeros")
    channels = render.shape[-1]
    x = render.permute(2, 0, 1)[None]  # [1, C, H, W]
    y = reference.image.to(dtype=x.dtype, device=x.device)
    mu_x, e_xx, e_xy = _blurred(torch.cat([x, x * x, x * y], dim=1), reference.padding).split(channels, dim=1)
    mu_y, e_yy = reference.mean.to(x), reference.square.to(x)
    mu_xx, mu_yy, mu_xy = mu_x * mu_x, mu_y * mu_y, mu_x * mu_y
    numerator = (2.0 * mu_xy + SSIM_C1) * (2.0 * (e_xy - mu_xy) + SSIM_C2)
    denominator = (mu_xx + mu_yy + SSIM_C1) * ((e_xx - mu_xx) + (e_yy - mu_yy) + SSIM_C2)
    return (numerator / denominator)[0].permute(1, 2, 0)
