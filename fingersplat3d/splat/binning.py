"""Tile binning: which Gaussians touch which tile of pixels, front to back.

The image is cut into ``tile_size`` x ``tile_size`` tiles. Every Gaussian is listed in each tile its
footprint box touches (:func:`~fingersplat3d.splat.project.footprint_boxes`), in depth order.
Tiles are then grouped by list length so that each group is one dense ``[G, L]`` index tensor
(G tiles, lists padded to L with the sentinel index N): the compositor works on dense
``[G, L, tile_size**2]`` blocks, and the padding stays small because lengths within a group
differ by at most ~12 %. Integer work only; nothing here carries gradients.
"""
from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

__all__ = ["TileBins", "TileGroup", "bin_gaussians"]


class TileGroup(NamedTuple):
    tiles: Tensor  # [G] int64 tile index, row-major over (tiles_y, tiles_x)
    gaussians: Tensor  # [G, L] int64 Gaussian index, front to back; N (sentinel) pads short lists


class TileBins(NamedTuple):
    tile_size: int
    tiles_x: int
    tiles_y: int
    groups: tuple[TileGroup, ...]
    num_pairs: int  # tile-Gaussian pairs (each costs tile_size**2 Gaussian-pixel evaluations)


def _ladder(longest: int) -> list[int]:
    """List lengths 1, 2, ..., 8, then steps of ~1/8 (rounded up to multiples of 4): consecutive
    rungs differ by <= 12.5 %, which bounds the padding."""
    rungs = list(range(1, 9))
    while rungs[-1] < longest:
        rungs.append(-(-int(rungs[-1] * 1.125 + 1) // 4) * 4)
    return rungs


def bin_gaussians(boxes: Tensor, valid: Tensor, depths: Tensor, width: int, height: int,
                  tile_size: int = 4) -> TileBins:
    """Bin Gaussians (``boxes`` [N, 4] inclusive pixel boxes x0, y0, x1, y1; ``valid`` [N] bool;
    ``depths`` [N]) into tiles. Ties in depth keep index order (a stable sort), like the reference."""
    device = boxes.device
    n = boxes.shape[0]
    tiles_x, tiles_y = -(-width // tile_size), -(-height // tile_size)
    with torch.no_grad():
        visible = torch.nonzero(valid).squeeze(1)
        order = visible[torch.argsort(depths.detach()[visible], stable=True)]  # front to back
        box = torch.div(boxes.index_select(0, order), tile_size, rounding_mode="floor").int()  # [V, 4] tile boxes
        span_x = box[:, 2] - box[:, 0] + 1
        counts = span_x * (box[:, 3] - box[:, 1] + 1)
        num_pairs = int(counts.sum()) if len(counts) else 0
        if num_pairs == 0:
            return TileBins(tile_size, tiles_x, tiles_y, (), 0)
        # One row per tile-Gaussian pair, in depth order: (first tile x, first tile y, span, offset, Gaussian).
        first = torch.cumsum(counts, 0, dtype=torch.int32) - counts
        rows = torch.stack([box[:, 0], box[:, 1], span_x, first, order.int()], 1)
        rows = torch.repeat_interleave(rows, counts.long(), dim=0, output_size=num_pairs)  # [M, 5]
        local = torch.arange(num_pairs, dtype=torch.int32, device=device) - rows[:, 3]
        along_y = torch.div(local, rows[:, 2], rounding_mode="floor")
        tile = (rows[:, 1] + along_y) * tiles_x + rows[:, 0] + (local - along_y * rows[:, 2])  # [M]
        tile, by_tile = torch.sort(tile, stable=True)  # stable: depth order survives inside a tile
        gaussian = rows[:, 4].index_select(0, by_tile).long()  # [M]

        tiles, lengths = torch.unique_consecutive(tile, return_counts=True)  # [A]
        tiles = tiles.long()
        starts = torch.cumsum(lengths, 0) - lengths
        ladder = torch.tensor(_ladder(int(lengths.max())), device=device)
        rung = torch.searchsorted(ladder, lengths)  # [A] the shortest rung >= length
        rung, by_rung = torch.sort(rung, stable=True)
        _, tiles_per_rung = torch.unique_consecutive(rung, return_counts=True)
        gaussian = torch.cat([gaussian, gaussian.new_full((1,), n)])  # index num_pairs: the sentinel
        groups = []
        for tile_ids in torch.split(by_rung, tiles_per_rung.tolist()):
            group_lengths = lengths.index_select(0, tile_ids)
            longest = int(group_lengths.max())
            slot = torch.arange(longest, device=device)
            index = torch.where(slot < group_lengths[:, None], starts.index_select(0, tile_ids)[:, None] + slot,
                                num_pairs)  # [G, L]
            members = gaussian.index_select(0, index.reshape(-1)).view(index.shape)
            groups.append(TileGroup(tiles.index_select(0, tile_ids), members))
    return TileBins(tile_size, tiles_x, tiles_y, tuple(groups), num_pairs)
