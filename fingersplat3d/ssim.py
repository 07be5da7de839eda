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

Large images (a window of :data:`BANDED_MIN_PIXELS` or more: a phone photo's finger fitted at 16 px a ridge) go
through :class:`_BandedSSIM` instead, the same map (to the bit in float32) and gradient (to rounding): both worked
out a band of :data:`BAND_ROWS` rows at a time, the gradient written by hand (``dS/dmu_x``, ``dS/de_xx``,
``dS/de_xy`` blurred back and combined with the image), nothing kept for the backward pass but the two images and
the target's blurs. Autograd's graph held every intermediate map at full size (a 3717x1150 colour window: +520-560
MB and 1.5 s a loss and its gradient; banded +170-380 MB and 0.85-1.06 s, the bands' stacks staying in the cache; a
phone-like capture's fuse peaked at 4.08 GB, 3.38 GB banded: docs/measurements.md, stop 92). Under that size the
graph stays: the bands' recomputed blurs cost more than they save (640x512: 29 against 41 ms); so does a GPU's, whose
memory holds the graph and whose kernel launches the bands would multiply. The graph path is the banded one's
reference in the tests (float64, gradcheck).

Images are ``[H, W, C]`` (or ``[H, W]``, read as one channel) float tensors. Pure torch.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import torch
import torch.nn.functional as F

__all__ = ["ssim_map", "ssim_reference", "SSIMReference", "image_pair", "SSIM_WINDOW", "SSIM_SIGMA", "SSIM_C1",
           "SSIM_C2", "BANDED_MIN_PIXELS", "BAND_ROWS"]

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_C1 = 0.01 ** 2
SSIM_C2 = 0.03 ** 2
BANDED_MIN_PIXELS = 600_000
"""Windows of at least this many pixels (rows times columns) take the banded path (module docstring): measured on 2
cores (Zen 4), a loss and its gradient at 700x900 62-78 ms banded against 67-84 ms as a graph, at 1024x1280 157-210
against 274-299 ms."""
BAND_ROWS = 64
"""Rows of the map worked out at once on the banded path (16 to 256 measured at 3717 columns: 64 the quickest)."""


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
    x = render.permute(2, 0, 1)[None]  # [1, C, H, W]
    y = reference.image.to(dtype=x.dtype, device=x.device)
    mu_y, e_yy = reference.mean.to(x), reference.square.to(x)
    if x.device.type == "cpu" and render.shape[0] * render.shape[1] >= BANDED_MIN_PIXELS:  # a GPU: the graph in one go
        return _banded(x, y, mu_y, e_yy, reference.padding)[0].permute(1, 2, 0)
    return _graph(x, y, mu_y, e_yy, reference.padding)[0].permute(1, 2, 0)


def _terms(mu_x, e_xx, e_xy, mu_y, e_yy) -> tuple[torch.Tensor, ...]:
    """SSIM's four factors, ``S = a b / (c d)``: the means' and the (co)variances' numerators and denominators. (In this
    order of operations, the graph's gradient is the one the fits were measured with, to the bit.)"""
    mu_xx, mu_yy, mu_xy = mu_x * mu_x, mu_y * mu_y, mu_x * mu_y
    a = 2.0 * mu_xy + SSIM_C1
    b = 2.0 * (e_xy - mu_xy) + SSIM_C2
    c = mu_xx + mu_yy + SSIM_C1
    d = (e_xx - mu_xx) + (e_yy - mu_yy) + SSIM_C2
    return a, b, c, d


def _graph(x, y, mu_y, e_yy, padding: str) -> torch.Tensor:
    """The map ``[1, C, H, W]`` as autograd's graph of whole-image operations (small windows; the reference)."""
    channels = x.shape[1]
    mu_x, e_xx, e_xy = _blurred(torch.cat([x, x * x, x * y], dim=1), padding).split(channels, dim=1)
    a, b, c, d = _terms(mu_x, e_xx, e_xy, mu_y, e_yy)
    return (a * b) / (c * d)


def _banded(x, y, mu_y, e_yy, padding: str) -> torch.Tensor:
    """The map ``[1, C, H, W]`` by :class:`_BandedSSIM`; a reflected border is made first (its adjoint by autograd)."""
    if padding == "reflect":
        pad = SSIM_WINDOW // 2
        x, y = (F.pad(t, (pad, pad, pad, pad), mode="reflect") for t in (x, y))
        return _BandedSSIM.apply(x.contiguous(), y.contiguous(), mu_y, e_yy, 0)
    return _BandedSSIM.apply(x.contiguous(), y.contiguous(), mu_y, e_yy, SSIM_WINDOW // 2)


def _rows(image: torch.Tensor, first: int, last: int) -> torch.Tensor:
    """Rows ``first .. last - 1`` of ``image [..., H, W]``, rows outside ``0 .. H - 1`` zero."""
    height = image.shape[-2]
    inner = image[..., max(first, 0):min(last, height), :]
    above, below = max(0, -first), max(0, last - height)
    return F.pad(inner, (0, 0, above, below)) if above or below else inner


def _band_moments(x, y, first: int, last: int, pad: int) -> tuple[torch.Tensor, ...]:
    """``mu_x, e_xx, e_xy`` on the map's rows ``first .. last - 1``: the images zero-padded by ``pad`` on every side
    (already padded where ``pad`` is 0), read from ``first - pad`` to ``last + window - 1 - pad``."""
    reach = SSIM_WINDOW - 1
    xb, yb = _rows(x, first - pad, last + reach - pad), _rows(y, first - pad, last + reach - pad)
    stack = torch.cat([xb, xb * xb, xb * yb], dim=1)
    if pad:
        stack = F.pad(stack, (pad, pad, 0, 0))
    return _valid_blur(stack, _taps()).chunk(3, dim=1)


class _BandedSSIM(torch.autograd.Function):
    """The map of images ``x``, ``y`` ``[1, C, Hs, Ws]`` (zero-padded by ``pad``, or padded already where it is 0) with
    the target's blurs ``mu_y``, ``e_yy`` ``[1, C, H, W]``, band by band; the gradient w.r.t. ``x`` written out:
    ``dx = blur'(g dS/dmu_x) + 2 x blur'(g dS/de_xx) + y blur'(g dS/de_xy)`` (``blur'`` the window's adjoint), with
    ``dS/dmu_x = 2 mu_y (b - a) / (c d) - 2 mu_x S (1/c - 1/d)``, ``dS/de_xx = -S / d``, ``dS/de_xy = 2 a / (c d)``."""

    @staticmethod
    def forward(ctx, x, y, mu_y, e_yy, pad):
        reach = SSIM_WINDOW - 1
        height, width = x.shape[-2] + 2 * pad - reach, x.shape[-1] + 2 * pad - reach
        out = torch.empty((1, x.shape[1], height, width), dtype=x.dtype, device=x.device)
        for first in range(0, height, BAND_ROWS):
            last = min(height, first + BAND_ROWS)
            moments = _band_moments(x, y, first, last, pad)
            a, b, c, d = _terms(*moments, mu_y[..., first:last, :], e_yy[..., first:last, :])
            out[..., first:last, :] = a.mul_(b).div_(c.mul_(d))
        ctx.save_for_backward(x, y, mu_y, e_yy)
        ctx.pad = pad
        return out

    @staticmethod
    def backward(ctx, grad):
        x, y, mu_y, e_yy = ctx.saved_tensors
        pad, reach = ctx.pad, SSIM_WINDOW - 1
        height = grad.shape[-2]
        dx = torch.empty_like(x)
        for top in range(0, x.shape[-2], BAND_ROWS):  # x's rows top .. bottom - 1 take from the map's first .. last - 1
            bottom = min(x.shape[-2], top + BAND_ROWS)
            first, last = top + pad - reach, bottom + pad
            inner = (max(0, first), min(height, last))
            mu_x, e_xx, e_xy = _band_moments(x, y, *inner, pad)
            band_mu_y, g = mu_y[..., inner[0]:inner[1], :], grad[..., inner[0]:inner[1], :]
            a, b, c, d = _terms(mu_x, e_xx, e_xy, band_mu_y, e_yy[..., inner[0]:inner[1], :])
            cd = c * d
            s = a * b / cd
            partials = torch.cat([g * (2.0 * band_mu_y * (b - a) / cd - 2.0 * mu_x * s * (1.0 / c - 1.0 / d)),
                                  g * (-s / d), g * (2.0 * a / cd)], dim=1)
            spread = _valid_blur(F.pad(partials, (reach, reach, inner[0] - first, last - inner[1])), _taps())
            if pad:
                spread = spread[..., :, pad:-pad]
            d_mu, d_xx, d_xy = spread.chunk(3, dim=1)
            dx[..., top:bottom, :] = d_mu + 2.0 * x[..., top:bottom, :] * d_xx + y[..., top:bottom, :] * d_xy
        return dx, None, None, None, None
