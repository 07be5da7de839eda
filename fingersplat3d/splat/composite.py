"""Front-to-back alpha compositing over tile groups, with a hand-written backward.

For one group of G tiles whose lists hold L Gaussians (see :mod:`.binning`) and the S =
tile_size**2 pixels of a tile, every Gaussian-pixel pair of the dense ``[G, L, S]`` block is
evaluated, in tile-centred pixel coordinates:

    q     = d^T conic d                 d = pixel - mean
    alpha = min(0.99, o exp(-q / 2)),   set to 0 (skipped) where o exp(-q / 2) < 1/255
                                        (q < 0 can only come from rounding; it is clamped to 0)
    T_i   = prod_{j < i} (1 - alpha_j)  (exclusive, along L: the inclusive cumprod over 1 - alpha_i)
    w_i   = alpha_i T_i,  pixel value f = sum_i w_i feat_i  for every feature column.

Backward (per pixel, with G_i = feat_i . dL/df and R = sum_i w_i G_i = f . dL/df):

    dL/dalpha_k = T_k G_k - (R - sum_{i <= k} w_i G_i) / (1 - alpha_k)

so one more prefix sum, front to back; 1 - alpha >= 0.01 keeps the division safe. The pixel sums
that the parameter gradients need (sum_s dq dx^2, ...) are formed, on the eager path, from six pixel
moments of dq per pair, i.e. one ``[G, L, S] @ [S, 6]`` product. Padding slots point at a sentinel Gaussian with
opacity 0. The per-group kernels are plain functions of dense tensors so that
:mod:`.compiled` can hand them to ``torch.compile``; the default path runs them eagerly.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import torch
from torch import Tensor
from torch.autograd.function import once_differentiable

from .binning import TileBins
from .project import ALPHA_MAX, ALPHA_MIN

__all__ = ["EAGER_KERNELS", "GroupKernels", "backward_group", "composite_tiles", "forward_group"]


def pair_alpha(params: Tensor, grid: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """``params`` [G, L, 6] (mx, my, a, b, c, o; means tile-centred), ``grid`` [2, S] ->
    ``(alpha, raw, falloff, dx, dy)``, each [G, L, S]: alpha as composited, raw = o * falloff
    before the clamp and the threshold, falloff = exp(-max(q, 0) / 2), and the pixel offsets.
    Direct per-pair arithmetic (what the reference does); used by the fused kernels."""
    mx, my, a, b, c, o = (params[..., k:k + 1] for k in range(6))  # [G, L, 1] each
    dx = grid[0] - mx  # [G, L, S]
    dy = grid[1] - my
    q = dx * (a * dx + 2.0 * b * dy) + c * dy * dy
    falloff = torch.exp(-0.5 * q.clamp_min(0.0))
    raw = o * falloff
    alpha = torch.where(raw >= ALPHA_MIN, raw.clamp_max(ALPHA_MAX), 0.0)
    return alpha, raw, falloff, dx, dy


def _raw_alpha_eager(params: Tensor, moments_basis: Tensor) -> tuple[Tensor, Tensor]:
    """``(raw, alpha)`` [G, L, S] in few memory passes: log(o) - q/2 is a quadratic polynomial in
    the tile-centred pixel coordinates, so the whole ``[G, L, S]`` block is one ``[G, L, 6] @ [6, S]``
    product; then one exp. (Rounding differs from :func:`pair_alpha` by ~1e-7 relative in float32.)"""
    mx, my, a, b, c, o = params.unbind(-1)  # [G, L] each
    log_o = torch.log(o.clamp_min(1e-30))
    q_at_origin = mx * (a * mx + 2.0 * b * my) + c * my * my
    coefficients = torch.stack([  # of (1, x, y, x^2, x y, y^2) in log(o) - q / 2
        log_o - 0.5 * q_at_origin, a * mx + b * my, b * mx + c * my, -0.5 * a, -b, -0.5 * c], -1)
    exponent = torch.matmul(coefficients, moments_basis.T)  # [G, L, S]
    raw = torch.minimum(exponent, log_o[..., None]).exp_()  # q < 0 only by rounding: clamp q at 0
    alpha = raw.clamp_max(ALPHA_MAX).masked_fill_(raw < ALPHA_MIN, 0.0)
    return raw, alpha


def forward_group(params: Tensor, feats: Tensor, grid: Tensor, moments_basis: Tensor) -> tuple[Tensor, Tensor]:
    """``params`` [G, L, 6], ``feats`` [G, L, F], ``grid`` [2, S], ``moments_basis`` [S, 6] =
    (1, x, y, x^2, x y, y^2) -> ``(pixels [G, F, S], transmittance [G, L, S])``, the latter
    saved for the backward."""
    _, alpha = _raw_alpha_eager(params, moments_basis)
    keep = alpha.neg().add_(1.0)
    transmittance = torch.cumprod(keep, 1).div_(keep)  # exclusive product (1 - alpha >= 0.01)
    pixels = torch.bmm(feats.transpose(1, 2), alpha.mul_(transmittance))  # alpha now holds the weights
    return pixels, transmittance


def backward_group(params: Tensor, feats: Tensor, grid: Tensor, moments_basis: Tensor, transmittance: Tensor,
                   pixels: Tensor, grad_pixels: Tensor) -> Tensor:
    """Gradient ``[G, L, 6 + F]`` w.r.t. (params, feats) of ``sum(pixels * grad_pixels)``
    (``pixels``, ``grad_pixels`` [G, F, S])."""
    raw, alpha = _raw_alpha_eager(params, moments_basis)
    per_pair = torch.bmm(feats, grad_pixels)  # [G, L, S]: G_i = feat_i . dL/dpixel
    total = (pixels * grad_pixels).sum(1)  # [G, S]: R = sum_i w_i G_i
    weights = alpha * transmittance
    grad_feats = torch.bmm(weights, grad_pixels.transpose(1, 2))  # [G, L, F]
    behind = torch.cumsum(weights.mul_(per_pair), 1).neg_().add_(total[:, None, :])  # sum_{i > k} w_i G_i
    grad_alpha = per_pair.mul_(transmittance).sub_(behind.div_(alpha.neg().add_(1.0)))
    grad_alpha.masked_fill_((alpha == 0) | (raw >= ALPHA_MAX), 0.0)  # skipped or clamped pairs
    grad_q = grad_alpha.mul_(raw).mul_(-0.5)  # dL/dq = dL/draw * raw * (-1/2)
    m1, mx_, my_, mxx, mxy, myy = torch.matmul(grad_q, moments_basis).unbind(-1)  # [G, L] each
    mx, my, a, b, c, o = params.unbind(-1)
    # sum_s dq dx^2 etc. from the moments: dx = x - mx, dy = y - my.
    s_dx = mx_ - mx * m1
    s_dy = my_ - my * m1
    s_dxx = mxx - 2.0 * mx * mx_ + mx * mx * m1
    s_dxy = mxy - mx * my_ - my * mx_ + mx * my * m1
    s_dyy = myy - 2.0 * my * my_ + my * my * m1
    grad_opacity = torch.where(o > 0, -2.0 * m1 / torch.where(o > 0, o, 1.0), 0.0)  # sum_s dL/draw * falloff
    grad_params = torch.stack([-2.0 * (a * s_dx + b * s_dy), -2.0 * (b * s_dx + c * s_dy),
                               s_dxx, 2.0 * s_dxy, s_dyy, grad_opacity], -1)
    return torch.cat([grad_params, grad_feats], -1)


class GroupKernels(NamedTuple):
    forward: Callable[..., tuple[Tensor, Tensor]]
    backward: Callable[..., Tensor]


EAGER_KERNELS = GroupKernels(forward_group, backward_group)


def _grid(tile_size: int, dtype: torch.dtype, device: torch.device) -> tuple[Tensor, Tensor]:
    """Tile-centred pixel coordinates ``[2, S]`` (row-major) and their moment basis ``[S, 6]``."""
    slot = torch.arange(tile_size * tile_size, device=device)
    x = (slot % tile_size).to(dtype) - (tile_size - 1) / 2
    y = (slot // tile_size).to(dtype) - (tile_size - 1) / 2
    return torch.stack([x, y]), torch.stack([torch.ones_like(x), x, y, x * x, x * y, y * y], -1)


def _tile_centres(tiles: Tensor, bins: TileBins, dtype: torch.dtype) -> Tensor:
    s = bins.tile_size
    return torch.stack([tiles % bins.tiles_x * s, tiles // bins.tiles_x * s], -1).to(dtype) + (s - 1) / 2  # [G, 2]


class _Composite(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d: Tensor, conics: Tensor, opacities: Tensor, feats: Tensor, bins: TileBins,
                width: int, height: int, kernels: GroupKernels, block_pairs: int) -> Tensor:
        dtype, device = feats.dtype, feats.device
        grid, basis = _grid(bins.tile_size, dtype, device)
        table = torch.cat([means2d, conics, opacities[:, None], feats], 1)  # [N, 6 + F]
        table = torch.cat([table, table.new_zeros(1, table.shape[1])])  # sentinel row N: opacity 0
        blocks, pixels_all = [], []
        for group in bins.groups:
            rows = table.index_select(0, group.gaussians.reshape(-1)).view(*group.gaussians.shape, -1)
            rows[..., 0:2] -= _tile_centres(group.tiles, bins, dtype)[:, None, :]  # tile-centred means
            # Blocks of tiles small enough for the [G, L, S] temporaries to stay in cache.
            step = max(1, block_pairs // (rows.shape[1] * bins.tile_size ** 2))
            for block, members in zip(torch.split(rows, step), torch.split(group.gaussians, step)):
                params, block_feats = block[..., :6], block[..., 6:]
                pixels, transmittance = kernels.forward(params, block_feats, grid, basis)
                blocks.append((params, block_feats, transmittance, pixels, members))
                pixels_all.append(pixels)
        tiles = torch.cat([g.tiles for g in bins.groups])
        image = _untile(torch.cat(pixels_all), tiles, bins, width, height)
        ctx.bins, ctx.kernels, ctx.tiles, ctx.num, ctx.blocks = bins, kernels, tiles, means2d.shape[0], blocks
        return image

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_image: Tensor):
        bins, kernels, n = ctx.bins, ctx.kernels, ctx.num
        dtype, device = grad_image.dtype, grad_image.device
        grid, basis = _grid(bins.tile_size, dtype, device)
        grad_tiles = _tile(grad_image, ctx.tiles, bins)  # [A, F, S], tiles in block order
        grad_table = grad_image.new_zeros(n + 1, 6 + grad_image.shape[-1])  # row n: the sentinel
        start = 0
        for params, feats, transmittance, pixels, members in ctx.blocks:
            count = params.shape[0]
            grads = kernels.backward(params, feats, grid, basis, transmittance, pixels, grad_tiles[start:start + count])
            grad_table.index_add_(0, members.reshape(-1), grads.reshape(-1, grads.shape[-1]))
            start += count
        return (grad_table[:n, 0:2], grad_table[:n, 2:5], grad_table[:n, 5], grad_table[:n, 6:],
                None, None, None, None, None)


def _untile(values: Tensor, tiles: Tensor, bins: TileBins, width: int, height: int) -> Tensor:
    """``[A, F, S]`` per-tile pixel values for tiles ``tiles`` [A] -> ``[H, W, F]`` (zeros elsewhere)."""
    s, f = bins.tile_size, values.shape[1]
    full = values.new_zeros(bins.tiles_y * bins.tiles_x, f, s * s).index_copy_(0, tiles, values)
    full = full.view(bins.tiles_y, bins.tiles_x, f, s, s).permute(0, 3, 1, 4, 2)
    return full.reshape(bins.tiles_y * s, bins.tiles_x * s, f)[:height, :width]


def _tile(image: Tensor, tiles: Tensor, bins: TileBins) -> Tensor:
    """Inverse of :func:`_untile`: ``[H, W, F]`` -> ``[A, F, S]`` for tiles ``tiles`` (zero padding)."""
    s, f = bins.tile_size, image.shape[-1]
    height, width = image.shape[:2]
    padded = image.new_zeros(bins.tiles_y * s, bins.tiles_x * s, f)
    padded[:height, :width] = image
    blocks = padded.view(bins.tiles_y, s, bins.tiles_x, s, f).permute(0, 2, 4, 1, 3).reshape(-1, f, s * s)
    return blocks[tiles]


def composite_tiles(bins: TileBins, means2d: Tensor, conics: Tensor, opacities: Tensor, feats: Tensor,
                    width: int, height: int, kernels: GroupKernels = EAGER_KERNELS,
                    block_pairs: int = 1 << 18) -> Tensor:
    """Composite binned Gaussians (``means2d`` [N, 2], ``conics`` [N, 3], ``opacities`` [N],
    ``feats`` [N, F]) into an ``[H, W, F]`` image of ``sum_i w_i feat_i`` per pixel."""
    if not bins.groups:  # nothing drawn: zeros that stay in the graph (empty sums: zero gradients)
        connected = sum(t[:0].sum() for t in (means2d, conics, opacities, feats))
        return feats.new_zeros(height, width, feats.shape[1]) + connected
    return _Composite.apply(means2d, conics, opacities, feats, bins, width, height, kernels, block_pairs)
