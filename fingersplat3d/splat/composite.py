"""Front-to-back alpha compositing over tile groups, with a hand-written backward.

For one group of G tiles whose lists hold L Gaussians (see :mod:`.binning`) and the S =
tile_size**2 pixels of a tile, every Gaussian-pixel pair of the dense ``[G, L, S]`` block is
evaluated, in tile-centred pixel coordinates:

    q     = d^T conic d                 d = pixel - mean
    alpha = min(0.99, o exp(-q / 2)),   set to 0 (skipped) where o exp(-q / 2) < 1/255 or q < 0
    T_i   = prod_{j < i} (1 - alpha_j)  (exclusive, along L, as exp(cumsum(log(1 - alpha))))
    w_i   = alpha_i T_i,  pixel value f = sum_i w_i feat_i  for every feature column.

Backward (per pixel, with G_i = feat_i . dL/df and R = sum_i w_i G_i = f . dL/df):

    dL/dalpha_k = T_k G_k - (R - sum_{i <= k} w_i G_i) / (1 - alpha_k)

so one more prefix sum, front to back; 1 - alpha >= 0.01 keeps the division safe. The pixel sums
that the parameter gradients need (sum_s dq dx^2, ...) are formed from six pixel moments of dq per
pair, i.e. one ``[G, L, S] @ [S, 6]`` product. Padding slots point at a sentinel Gaussian with
opacity 0. The per-group kernels are plain functions of dense tensors so that
:mod:`.compiled` can hand them to ``torch.compile``; the default path runs them eagerly.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import torch
from torch import Tensor

from .binning import TileBins
from .project import ALPHA_MAX, ALPHA_MIN

__all__ = ["composite_tiles", "forward_group", "backward_group", "GroupKernels", "EAGER_KERNELS"]


def pair_alpha(params: Tensor, grid: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """``params`` [G, L, 6] (mx, my, a, b, c, o; means tile-centred), ``grid`` [S, 2] ->
    ``(alpha, raw, falloff, dx, dy)``, each [G, L, S]: alpha as composited, raw = o * falloff
    unclamped, falloff = exp(-q / 2) with q clamped at 0, and the pixel offsets."""
    mx, my, a, b, c, o = (params[..., k:k + 1] for k in range(6))  # [G, L, 1] each
    dx = grid[:, 0] - mx  # [G, L, S]
    dy = grid[:, 1] - my
    q = dx * (a * dx + 2.0 * b * dy) + c * dy * dy
    falloff = torch.exp(-0.5 * q.clamp_min(0.0))
    raw = o * falloff
    alpha = torch.where((q >= 0) & (raw >= ALPHA_MIN), raw.clamp_max(ALPHA_MAX), 0.0)
    return alpha, raw, falloff, dx, dy


def forward_group(params: Tensor, feats: Tensor, grid: Tensor) -> tuple[Tensor, Tensor]:
    """``params`` [G, L, 6], ``feats`` [G, L, F], ``grid`` [S, 2] -> ``(pixels [G, S, F],
    transmittance [G, L, S])``, the latter saved for the backward."""
    alpha = pair_alpha(params, grid)[0]
    log_keep = torch.log1p(-alpha)
    transmittance = torch.exp(torch.cumsum(log_keep, 1) - log_keep)  # exclusive product
    pixels = torch.bmm((alpha * transmittance).transpose(1, 2), feats)
    return pixels, transmittance


def backward_group(params: Tensor, feats: Tensor, grid: Tensor, moments_basis: Tensor, transmittance: Tensor,
                   pixels: Tensor, grad_pixels: Tensor) -> tuple[Tensor, Tensor]:
    """Gradients ``([G, L, 6] w.r.t. params, [G, L, F] w.r.t. feats)`` of ``sum(pixels * grad_pixels)``.
    ``moments_basis`` [S, 6] = (1, x, y, x^2, x y, y^2) of ``grid``."""
    alpha, raw, falloff, dx, dy = pair_alpha(params, grid)
    weights = alpha * transmittance  # [G, L, S]
    per_pair = torch.bmm(feats, grad_pixels.transpose(1, 2))  # [G, L, S]: G_i = feat_i . dL/dpixel
    total = (pixels * grad_pixels).sum(-1)  # [G, S]: R = sum_i w_i G_i
    behind = total[:, None, :] - torch.cumsum(weights * per_pair, 1)  # sum over i > k of w_i G_i
    grad_alpha = transmittance * per_pair - behind / (1.0 - alpha)
    grad_raw = torch.where((alpha > 0) & (raw < ALPHA_MAX), grad_alpha, 0.0)
    grad_opacity = (grad_raw * falloff).sum(-1)  # [G, L]
    grad_q = -0.5 * grad_raw * raw  # [G, L, S]
    m1, mx_, my_, mxx, mxy, myy = torch.matmul(grad_q, moments_basis).unbind(-1)  # [G, L] each
    mx, my, a, b, c, _ = params.unbind(-1)
    # sum_s dq dx^2 etc. from the moments: dx = x - mx, dy = y - my.
    s_dx = mx_ - mx * m1
    s_dy = my_ - my * m1
    s_dxx = mxx - 2.0 * mx * mx_ + mx * mx * m1
    s_dxy = mxy - mx * my_ - my * mx_ + mx * my * m1
    s_dyy = myy - 2.0 * my * my_ + my * my * m1
    grad_params = torch.stack([-2.0 * (a * s_dx + b * s_dy), -2.0 * (b * s_dx + c * s_dy),
                               s_dxx, 2.0 * s_dxy, s_dyy, grad_opacity], -1)
    grad_feats = torch.bmm(weights, grad_pixels)  # [G, L, F]
    return grad_params, grad_feats


class GroupKernels(NamedTuple):
    forward: Callable[..., tuple[Tensor, Tensor]]
    backward: Callable[..., tuple[Tensor, Tensor]]


EAGER_KERNELS = GroupKernels(forward_group, backward_group)


def _grid(tile_size: int, dtype: torch.dtype, device: torch.device) -> tuple[Tensor, Tensor]:
    """Tile-centred pixel coordinates ``[S, 2]`` (row-major) and their moment basis ``[S, 6]``."""
    slot = torch.arange(tile_size * tile_size, device=device)
    x = (slot % tile_size).to(dtype) - (tile_size - 1) / 2
    y = (slot // tile_size).to(dtype) - (tile_size - 1) / 2
    return torch.stack([x, y], -1), torch.stack([torch.ones_like(x), x, y, x * x, x * y, y * y], -1)


def _tile_centres(tiles: Tensor, bins: TileBins, dtype: torch.dtype) -> Tensor:
    s = bins.tile_size
    return torch.stack([tiles % bins.tiles_x * s, tiles // bins.tiles_x * s], -1).to(dtype) + (s - 1) / 2  # [G, 2]


class _Composite(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d: Tensor, conics: Tensor, opacities: Tensor, feats: Tensor, bins: TileBins,
                width: int, height: int, kernels: GroupKernels) -> Tensor:
        dtype, device = feats.dtype, feats.device
        grid, basis = _grid(bins.tile_size, dtype, device)
        table = _pair_table(means2d, conics, opacities)  # [N + 1, 6] with the sentinel row
        feats_table = torch.cat([feats, feats.new_zeros(1, feats.shape[1])])
        pixels_all, saved = [], []
        for group in bins.groups:
            params = _group_params(table, group.gaussians, _tile_centres(group.tiles, bins, dtype))
            pixels, transmittance = kernels.forward(params, feats_table[group.gaussians], grid)
            pixels_all.append(pixels)
            saved.append(transmittance)
        tiles = torch.cat([g.tiles for g in bins.groups])
        image = _untile(torch.cat(pixels_all), tiles, bins, width, height)
        ctx.bins, ctx.kernels, ctx.saved_transmittance, ctx.pixels = bins, kernels, saved, pixels_all
        ctx.tiles = tiles
        ctx.save_for_backward(means2d, conics, opacities, feats)
        return image

    @staticmethod
    def backward(ctx, grad_image: Tensor):
        means2d, conics, opacities, feats = ctx.saved_tensors
        bins, kernels = ctx.bins, ctx.kernels
        dtype, device = feats.dtype, feats.device
        grid, basis = _grid(bins.tile_size, dtype, device)
        table = _pair_table(means2d, conics, opacities)
        feats_table = torch.cat([feats, feats.new_zeros(1, feats.shape[1])])
        grad_tiles = _tile(grad_image.contiguous(), ctx.tiles, bins)  # [A, S, F]
        n = means2d.shape[0]
        grad_table = torch.zeros(n + 1, 6, dtype=dtype, device=device)
        grad_feats = torch.zeros(n + 1, feats.shape[1], dtype=dtype, device=device)
        start = 0
        for group, transmittance, pixels in zip(bins.groups, ctx.saved_transmittance, ctx.pixels):
            count = len(group.tiles)
            params = _group_params(table, group.gaussians, _tile_centres(group.tiles, bins, dtype))
            g_params, g_feats = kernels.backward(params, feats_table[group.gaussians], grid, basis, transmittance,
                                                 pixels, grad_tiles[start:start + count])
            start += count
            index = group.gaussians.reshape(-1)
            grad_table.index_add_(0, index, g_params.reshape(-1, 6))
            grad_feats.index_add_(0, index, g_feats.reshape(-1, feats.shape[1]))
        return (grad_table[:n, 0:2], grad_table[:n, 2:5], grad_table[:n, 5], grad_feats[:n],
                None, None, None, None)


def _pair_table(means2d: Tensor, conics: Tensor, opacities: Tensor) -> Tensor:
    """``[N + 1, 6]`` (mx, my, a, b, c, o) per Gaussian plus an all-zero sentinel row (opacity 0)."""
    table = torch.cat([means2d, conics, opacities[:, None]], 1)
    return torch.cat([table, table.new_zeros(1, 6)])


def _group_params(table: Tensor, gaussians: Tensor, centres: Tensor) -> Tensor:
    """``[G, L, 6]`` pair parameters with means relative to each tile's centre ``centres`` [G, 2]."""
    params = table[gaussians]
    params[..., 0:2] -= centres[:, None, :]
    return params


def _untile(values: Tensor, tiles: Tensor, bins: TileBins, width: int, height: int) -> Tensor:
    """``[A, S, F]`` per-tile pixel values for tiles ``tiles`` [A] -> ``[H, W, F]`` (zeros elsewhere)."""
    s, f = bins.tile_size, values.shape[-1]
    full = values.new_zeros(bins.tiles_y * bins.tiles_x, s * s, f).index_copy_(0, tiles, values)
    full = full.view(bins.tiles_y, bins.tiles_x, s, s, f).permute(0, 2, 1, 3, 4)
    return full.reshape(bins.tiles_y * s, bins.tiles_x * s, f)[:height, :width]


def _tile(image: Tensor, tiles: Tensor, bins: TileBins) -> Tensor:
    """Inverse of :func:`_untile`: ``[H, W, F]`` -> ``[A, S, F]`` for tiles ``tiles`` (zero padding)."""
    s, f = bins.tile_size, image.shape[-1]
    height, width = image.shape[:2]
    padded = image.new_zeros(bins.tiles_y * s, bins.tiles_x * s, f)
    padded[:height, :width] = image
    blocks = padded.view(bins.tiles_y, s, bins.tiles_x, s, f).permute(0, 2, 1, 3, 4).reshape(-1, s * s, f)
    return blocks[tiles]


def composite_tiles(bins: TileBins, means2d: Tensor, conics: Tensor, opacities: Tensor, feats: Tensor,
                    width: int, height: int, kernels: GroupKernels = EAGER_KERNELS) -> Tensor:
    """Composite binned Gaussians (``means2d`` [N, 2], ``conics`` [N, 3], ``opacities`` [N],
    ``feats`` [N, F]) into an ``[H, W, F]`` image of ``sum_i w_i feat_i`` per pixel."""
    if not bins.groups:  # nothing drawn: zeros that stay in the graph (empty sums: zero gradients)
        connected = sum(t[:0].sum() for t in (means2d, conics, opacities, feats))
        return feats.new_zeros(height, width, feats.shape[1]) + connected
    return _Composite.apply(means2d, conics, opacities, feats, bins, width, height, kernels)
