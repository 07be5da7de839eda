"""The CPU tile rasterizer's kernels (numba): binning, forward compositing, backward.

Organised as gsplat's CUDA kernels are, for CPU threads instead of thread blocks:

* **Binning.** The image is cut into ``TILE`` x ``TILE`` tiles. A Gaussian is listed in a tile only
  where its alpha >= 1/255 ellipse really meets the tile (exact ellipse-tile overlap per band of
  rows, not its bounding box). Gaussians are visited front to back, so a stable counting sort by
  tile leaves every tile's list in depth order.
* **Forward.** One tile at a time per thread; each Gaussian of the list is evaluated on its pixel
  box inside the tile, the falloff formed by products along rows and columns (three exps per
  tile-Gaussian pair, not one per pixel; measured as fast as clipping every row to the ellipse,
  which costs a square root and two divisions per row). Front-to-back compositing with early
  termination: a pixel stops after the Gaussian that brings its transmittance below
  ``min_transmittance``, so the weight it leaves out is below that (3DGS and gsplat stop *before*
  that Gaussian at 1e-4, which can leave out up to 1e-4 / (1 - 0.99) = 1 %); 0 gives the exact
  sum, identical to the reference rasterizer. The final transmittance (opacity = 1 - it) and, for
  pixels that stopped, where they stopped are saved for the backward.
* **Backward.** Each tile's list is walked back to front from the saved final transmittance
  (T_k = T_{k+1} / (1 - alpha_k), 1 - alpha >= 0.01), with the colour behind each Gaussian
  accumulated on the way; gradients of one Gaussian are summed over the tile's pixels into that
  (tile, Gaussian) pair's row, and a last pass sums each Gaussian's pairs (no atomics, no
  per-thread buffers, the same result for any thread count).
* **Memory order.** Gaussians are packed once into records in depth order and the tile lists
  into consecutive rows, so every pass reads in sequence; the random accesses happen in two
  parallel passes, where they are independent: each record written to its row, and the tile
  lists gathered from the records.

Per-pair arithmetic is float64 whatever the input dtype (it keeps the 1/255 threshold and the
transmittance product exact to rounding). Formulas and thresholds are those of :mod:`.composite`
(see there for the derivation). With two or four feature columns (a grayscale or RGB colour plus
depth: every render of the fit) the compositing runs as :mod:`.cpu_lanes`' kernels, the same
arithmetic vectorised across a tile row; the general ones here take any other count.

Pure numpy in, numpy out; no torch. Compiled on first use and cached on disk (``cache=True``:
next to this file, or in numba's user cache directory when the package is read-only).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .cpu_lanes import LANE_KERNELS
from .cpu_project import alpha_q_max
from .cpu_tile_math import (A, B, C, EA, EB, EC, EXPONENT_RANGE, FEATS, MX, MY, O, QMAX, TILE, X0, X1, Y0, Y1,
                            conic_terms, falloff_exact, falloff_start, load_pair, quadratic_at, tile_rect)
from .project import ALPHA_MAX, ALPHA_MIN

__all__ = ["TILE", "bin_tiles", "composite_backward", "composite_forward", "gather_pairs", "prepare", "radix_order",
           "reduce_pairs"]

_EDGE = 1e-6
"""Ellipse crossings are widened by this many pixels: rounding never drops a pixel the alpha test keeps."""


RADIX_BITS = 11
"""Bits of the key sorted per pass of :func:`radix_order`: three passes cover a float32's 32."""


@njit(cache=True)
def radix_order(keys, index):
    """``index`` ordered by ``keys`` (uint32, ``[V]`` each), ties in their given order: a least-significant-digit radix
    sort, :data:`RADIX_BITS` a pass (a positive float32's bits order as the float does). Measured on 200k Gaussians
    (Zen 4): 1.8 ms against 8.3 ms for numpy's sort of 64-bit keys (depth bits above index bits), the rasterizer's
    depth order before it."""
    width = 1 << RADIX_BITS
    source_keys, source_index = keys.copy(), index.copy()
    target_keys, target_index = np.empty_like(source_keys), np.empty_like(source_index)
    for shift in range(0, 32, RADIX_BITS):
        counts = np.zeros(width + 1, np.int64)
        for m in range(source_keys.shape[0]):
            counts[((source_keys[m] >> shift) & (width - 1)) + 1] += 1
        for digit in range(width):
            counts[digit + 1] += counts[digit]
        for m in range(source_keys.shape[0]):  # in order: each digit's slots filled as the keys come (stable)
            digit = (source_keys[m] >> shift) & (width - 1)
            place = counts[digit]
            counts[digit] = place + 1
            target_keys[place], target_index[place] = source_keys[m], source_index[m]
        source_keys, target_keys = target_keys, source_keys
        source_index, target_index = target_index, source_index
    return source_index


def prepare(order, means2d, conics, opacities, boxes, feats):
    """One record per drawn Gaussian, in ``order`` (front to back), ``[V, 14 + F]`` in the input
    dtype: mx, my, a, b, c, o; q_max, the largest q = d^T conic d at which o exp(-q/2) still
    reaches 1/255 (a hair wider, as in :func:`.project.footprint_boxes`; -1 when it never does);
    exp(-a), exp(-b), exp(-c), the falloff's second-difference factors (all 0 where the falloff
    must be evaluated per pixel, see :func:`falloff_start`); the inclusive pixel box x0, y0, x1,
    y1; the features. Later passes read records in sequence instead of gathering from five arrays
    per list entry.

    The records are made in the inputs' order, each written straight to its row in depth order (one
    cache line a record): made in depth order, every record gathered from six arrays at random, 3-4
    times slower at 200k Gaussians; made in index order and then moved whole, one pass more. The
    logarithm and exponentials come from numpy's vectorised ones, computed first for all Gaussians:
    numba calls the scalar ones, four a Gaussian, most of this pass's time."""
    row = np.full(means2d.shape[0], -1, np.int64)
    row[order] = np.arange(order.shape[0])
    with np.errstate(over="ignore", invalid="ignore"):
        exps = np.exp(-conics.astype(np.float64))  # used only where every exponent is in range (_records)
    return _records(means2d, conics, opacities, boxes, feats, alpha_q_max(opacities), exps, row, order.shape[0])


@njit(cache=True, parallel=True)
def _records(means2d, conics, opacities, boxes, feats, q_max, exps, row, drawn):
    """:func:`prepare`'s records, Gaussian g's at ``row[g]`` (``drawn`` rows; a Gaussian at -1 is not drawn);
    ``q_max`` from :func:`alpha_q_max`, ``exps`` = exp(-conics)."""
    n_feats = feats.shape[1]
    records = np.empty((drawn, FEATS + n_feats), feats.dtype)
    for g in prange(means2d.shape[0]):
        r = row[g]
        if r < 0:
            continue
        mx, my = float(means2d[g, 0]), float(means2d[g, 1])
        a, b, c, o = float(conics[g, 0]), float(conics[g, 1]), float(conics[g, 2]), float(opacities[g])
        records[r, MX], records[r, MY], records[r, A], records[r, B], records[r, C], records[r, O] = mx, my, a, b, c, o
        records[r, QMAX] = q_max[g]
        # Largest exponent magnitude over the box: q (convex) and the two linear steps peak at corners.
        largest = 0.0
        for cx in (boxes[g, 0], boxes[g, 2]):
            for cy in (boxes[g, 1], boxes[g, 3]):
                dx, dy = cx - mx, cy - my
                q = quadratic_at(a, b, c, dx, dy)
                step_x = a * (2.0 * dx + 1.0) + 2.0 * b * dy
                step_y = c * (2.0 * dy + 1.0) + 2.0 * b * dx
                largest = max(largest, abs(q), abs(step_x), abs(step_y), abs(a), abs(b), abs(c))
        incremental = largest < EXPONENT_RANGE
        records[r, EA] = exps[g, 0] if incremental else 0.0
        records[r, EB] = exps[g, 1] if incremental else 0.0
        records[r, EC] = exps[g, 2] if incremental else 0.0
        for k in range(4):
            records[r, X0 + k] = boxes[g, k]
        for f in range(n_feats):
            records[r, FEATS + f] = feats[g, f]
    return records


@njit(cache=True, inline="always")
def _crossing(mx: float, my: float, a: float, b: float, c: float, q_max: float, y: float, side: float) -> float:
    """x where row ``y`` crosses the ellipse q = q_max (``side`` -1: left, +1: right); the centre of
    the row's chord when the row only grazes it."""
    dy = y - my
    disc = max(a * q_max - dy * dy * (a * c - b * b), 0.0)
    return mx + (-b * dy + side * math.sqrt(disc)) / a


@njit(cache=True)
def _gaussian_tiles(rec, tiles_x, out, offset, write) -> int:
    """Tiles the Gaussian of record ``rec`` really touches (its ellipse q <= q_max meets the tile's
    pixel centres, up to a row's rounding); written to ``out[offset:]`` when ``write``. Returns the
    count. The ellipse's x-extent over a band of rows is its extreme point's when that lies in the
    band, else the nearer band edge's crossing (each crossing is convex in y)."""
    mx, my, a, b, c = float(rec[MX]), float(rec[MY]), float(rec[A]), float(rec[B]), float(rec[C])
    q_max = float(rec[QMAX])
    x0, y0, x1, y1 = int(rec[X0]), int(rec[Y0]), int(rec[X1]), int(rec[Y1])
    det = a * c - b * b
    exact = a > 0.0 and c > 0.0 and det > 0.0 and math.isfinite(det) and q_max > 0.0
    half_width = math.sqrt(q_max * c / det) if exact else 0.0
    y_left = my + b * half_width / c if exact else 0.0  # rows of the leftmost and rightmost points
    y_right = my - b * half_width / c if exact else 0.0
    count = 0
    for ty in range(y0 // TILE, y1 // TILE + 1):
        lo, hi = x0, x1
        if exact:
            top, bottom = max(y0, ty * TILE), min(y1, ty * TILE + TILE - 1)
            left = mx - half_width if top <= y_left <= bottom else min(
                _crossing(mx, my, a, b, c, q_max, top, -1.0), _crossing(mx, my, a, b, c, q_max, bottom, -1.0))
            right = mx + half_width if top <= y_right <= bottom else max(
                _crossing(mx, my, a, b, c, q_max, top, 1.0), _crossing(mx, my, a, b, c, q_max, bottom, 1.0))
            if math.isfinite(left) and math.isfinite(right):
                lo = max(x0, int(math.ceil(left - _EDGE)))
                hi = min(x1, int(math.floor(right + _EDGE)))
        for tx in range(lo // TILE, hi // TILE + 1):
            if write:
                out[offset + count] = ty * tiles_x + tx
            count += 1
    return count


@njit(cache=True, parallel=True)
def bin_tiles(records, tiles_x, tiles_y):
    """Tile lists of the drawn Gaussians (``records`` from :func:`prepare`, front to back).

    Returns ``(starts [tiles + 1], ranks [M], offsets [V + 1], slots [M])``: tile t's list is
    ``ranks[starts[t]:starts[t + 1]]`` (record rows, front to back); Gaussian r's pairs sit at
    ``slots[offsets[r]:offsets[r + 1]]`` of the tile-ordered pair arrays."""
    n_drawn = records.shape[0]
    counts = np.zeros(n_drawn + 1, np.int64)
    dummy = np.zeros(1, np.int32)
    for r in prange(n_drawn):
        counts[r + 1] = _gaussian_tiles(records[r], tiles_x, dummy, 0, False)
    offsets = np.cumsum(counts)
    pair_tile = np.empty(offsets[-1], np.int32)
    for r in prange(n_drawn):
        _gaussian_tiles(records[r], tiles_x, pair_tile, offsets[r], True)
    # Stable counting sort by tile: pairs are in depth order, so lists stay front to back.
    num_tiles = tiles_x * tiles_y
    starts = np.zeros(num_tiles + 1, np.int64)
    for m in range(pair_tile.shape[0]):
        starts[pair_tile[m] + 1] += 1
    starts = np.cumsum(starts)
    cursor = starts[:-1].copy()
    ranks = np.empty(pair_tile.shape[0], np.int32)
    slots = np.empty(pair_tile.shape[0], np.int64)
    for r in range(n_drawn):
        for m in range(offsets[r], offsets[r + 1]):
            t = pair_tile[m]
            ranks[cursor[t]] = r
            slots[m] = cursor[t]
            cursor[t] += 1
    return starts, ranks, offsets, slots


@njit(cache=True, parallel=True)
def gather_pairs(records, ranks):
    """``records[ranks]``: each tile's list as consecutive rows (read in sequence by the compositing)."""
    pairs = np.empty((ranks.shape[0], records.shape[1]), records.dtype)
    for m in prange(ranks.shape[0]):
        r = ranks[m]
        for k in range(records.shape[1]):
            pairs[m, k] = records[r, k]
    return pairs


@njit(cache=True, parallel=True)
def _general_forward(starts, pairs, width, height, tiles_x, min_transmittance, chunks):
    """:func:`composite_forward` for any feature count, in scalar code. Two and four feature columns take
    :mod:`.cpu_lanes`' kernels instead; the tests check those against these."""
    n_feats = pairs.shape[1] - FEATS
    image = np.zeros((height, width, n_feats))
    final = np.ones((height, width))
    consumed = np.zeros((height, width), np.int32)
    num_tiles = starts.shape[0] - 1
    for chunk in prange(chunks):
        trans = np.empty((TILE, TILE))
        acc = np.empty((TILE, TILE, n_feats))
        used = np.empty((TILE, TILE), np.int32)
        feat = np.empty(n_feats)
        for t in range(chunk, num_tiles, chunks):
            first, end = starts[t], starts[t + 1]
            if first == end:
                continue
            tx0, ty0, tx1, ty1 = tile_rect(t, tiles_x, width, height)
            trans[:] = 1.0
            acc[:] = 0.0
            used[:] = end - first  # a pixel that never stops walks the whole list
            alive = (tx1 - tx0 + 1) * (ty1 - ty0 + 1)
            for j in range(first, end):
                mx, my, a, b, c, o, ea, eb, ec, bx0, by0, bx1, by1 = load_pair(pairs[j], feat, tx0, ty0, tx1, ty1)
                row_falloff, row_ratio, ratio_y = falloff_start(mx, my, a, b, c, bx0, by0)
                for y in range(by0, by1 + 1):
                    falloff, ratio = row_falloff, row_ratio
                    py = y - ty0
                    for x in range(bx0, bx1 + 1):
                        if ea == 0.0:  # outside the incremental range: one exp per pixel
                            falloff = falloff_exact(mx, my, a, b, c, x, y)
                        raw = o * falloff
                        falloff *= ratio
                        ratio *= ea
                        px = x - tx0
                        if raw < ALPHA_MIN or trans[py, px] < min_transmittance:
                            continue
                        alpha = min(raw, ALPHA_MAX)
                        weight = alpha * trans[py, px]
                        for f in range(n_feats):
                            acc[py, px, f] += weight * feat[f]
                        trans[py, px] *= 1.0 - alpha
                        if trans[py, px] < min_transmittance:
                            used[py, px] = j - first + 1
                            alive -= 1
                    row_falloff *= ratio_y
                    ratio_y *= ec
                    row_ratio *= eb
                if alive == 0:
                    break
            for y in range(ty0, ty1 + 1):
                for x in range(tx0, tx1 + 1):
                    final[y, x] = trans[y - ty0, x - tx0]
                    consumed[y, x] = used[y - ty0, x - tx0]
                    for f in range(n_feats):
                        image[y, x, f] = acc[y - ty0, x - tx0, f]
    return image, final, consumed

@njit(cache=True, parallel=True, fastmath={"contract"})
def _general_backward(starts, pairs, width, height, tiles_x, final, consumed, grad_image, grad_alpha_image, chunks):
    """:func:`composite_backward` for any feature count, in scalar code (see :func:`_general_forward`)."""
    n_feats = pairs.shape[1] - FEATS
    pair_grads = np.zeros((pairs.shape[0], 6 + n_feats))
    num_tiles = starts.shape[0] - 1
    for chunk in prange(chunks):
        trans = np.empty((TILE, TILE))
        behind = np.empty((TILE, TILE, n_feats))
        upstream = np.empty((TILE, TILE, n_feats))
        used = np.empty((TILE, TILE), np.int32)
        opacity_up = np.empty((TILE, TILE))  # dL/d(1 - T_final) * T_final per pixel
        feat = np.empty(n_feats)
        local_feat = np.empty(n_feats)  # the pair's feature gradients, summed over its pixels
        for t in range(chunk, num_tiles, chunks):
            first, end = starts[t], starts[t + 1]
            if first == end:
                continue
            tx0, ty0, tx1, ty1 = tile_rect(t, tiles_x, width, height)
            deepest = 0
            for y in range(ty0, ty1 + 1):
                for x in range(tx0, tx1 + 1):
                    py, px = y - ty0, x - tx0
                    trans[py, px] = final[y, x]
                    opacity_up[py, px] = grad_alpha_image[y, x] * final[y, x]
                    used[py, px] = consumed[y, x]
                    deepest = max(deepest, consumed[y, x])
                    for f in range(n_feats):
                        behind[py, px, f] = 0.0
                        upstream[py, px, f] = grad_image[y, x, f]
            for k in range(deepest - 1, -1, -1):
                g_mx = g_my = g_a = g_b = g_c = g_o = 0.0
                for f in range(n_feats):
                    local_feat[f] = 0.0
                mx, my, a, b, c, o, ea, eb, ec, bx0, by0, bx1, by1 = load_pair(pairs[first + k], feat, tx0, ty0,
                                                                                tx1, ty1)
                row_falloff, row_ratio, ratio_y = falloff_start(mx, my, a, b, c, bx0, by0)
                for y in range(by0, by1 + 1):
                    falloff, ratio = row_falloff, row_ratio
                    row_falloff *= ratio_y
                    ratio_y *= ec
                    row_ratio *= eb
                    dy = y - my
                    py = y - ty0
                    for x in range(bx0, bx1 + 1):
                        dx = x - mx
                        if ea == 0.0:  # outside the incremental range: one exp per pixel
                            falloff = falloff_exact(mx, my, a, b, c, x, y)
                        here_falloff = falloff
                        falloff *= ratio
                        ratio *= ea
                        px = x - tx0
                        raw = o * here_falloff
                        if k >= used[py, px] or raw < ALPHA_MIN:
                            continue
                        alpha = min(raw, ALPHA_MAX)
                        inverse = 1.0 / (1.0 - alpha)
                        before = trans[py, px] * inverse  # T_k, the transmittance in front of Gaussian k
                        trans[py, px] = before
                        weight = alpha * before
                        grad_alpha = opacity_up[py, px] * inverse
                        for f in range(n_feats):
                            up = upstream[py, px, f]
                            local_feat[f] += weight * up
                            grad_alpha += (feat[f] * before - behind[py, px, f] * inverse) * up
                            behind[py, px, f] += feat[f] * weight
                        if raw >= ALPHA_MAX:  # clamped: alpha does not depend on the parameters
                            continue
                        g_o += grad_alpha * here_falloff
                        if quadratic_at(a, b, c, dx, dy) <= 0.0:  # q clamped at 0 (rounding only)
                            continue
                        t_mx, t_my, t_a, t_b, t_c = conic_terms(-0.5 * grad_alpha * raw, a, b, c, dx, dy)
                        g_mx += t_mx
                        g_my += t_my
                        g_a += t_a
                        g_b += t_b
                        g_c += t_c
                local = pair_grads[first + k]
                local[0], local[1], local[2], local[3], local[4], local[5] = g_mx, g_my, g_a, g_b, g_c, g_o
                for f in range(n_feats):
                    local[6 + f] = local_feat[f]
    return pair_grads


_KERNELS = {**LANE_KERNELS, 0: (_general_forward, _general_backward)}
"""The compositing kernels by feature count: a grayscale or RGB colour plus depth (vectorised across tile rows,
:mod:`.cpu_lanes`), and any other (the general kernels above, the lanes' reference in the tests)."""


def composite_forward(starts, pairs, width, height, tiles_x, min_transmittance, chunks):
    """Front-to-back compositing of the tile lists (``pairs`` from :func:`gather_pairs`). Returns
    ``(image [H, W, F] float64, final transmittance [H, W] float64, consumed [H, W] int32)``:
    ``consumed`` = list entries a pixel walked before it stopped (the whole list where it never
    did; only the entries it composited matter to the backward, which re-tests the same alpha
    threshold). The accumulated opacity is ``1 - final``: no feature column of ones is needed.
    Tiles are dealt to ``chunks`` interleaved chunks, one parallel task each."""
    forward, _ = _KERNELS.get(pairs.shape[1] - FEATS, _KERNELS[0])
    return forward(starts, pairs, width, height, tiles_x, min_transmittance, chunks)


def composite_backward(starts, pairs, width, height, tiles_x, final, consumed, grad_image, grad_alpha_image, chunks):
    """Gradients of ``sum(image * grad_image) + sum((1 - final) * grad_alpha_image)`` per tile pair:
    ``[M, 6 + F]`` float64, columns (mx, my, a, b, c, opacity, feats...), rows as ``pairs`` (see
    :func:`reduce_pairs`). d(1 - T_final)/d alpha_k = T_final / (1 - alpha_k). Products are
    contracted into fused multiply-adds (``fastmath={"contract"}``: rounding only, ~10 % faster)."""
    _, backward = _KERNELS.get(pairs.shape[1] - FEATS, _KERNELS[0])
    return backward(starts, pairs, width, height, tiles_x, final, consumed, grad_image, grad_alpha_image, chunks)


@njit(cache=True, parallel=True)
def reduce_pairs(pair_grads, offsets, slots):
    """Per drawn Gaussian (record row), the sum of its tile pairs' gradients: ``[V, 6 + F]``."""
    n_drawn = offsets.shape[0] - 1
    grads = np.zeros((n_drawn, pair_grads.shape[1]))
    for r in prange(n_drawn):
        for m in range(offsets[r], offsets[r + 1]):
            slot = slots[m]
            for k in range(pair_grads.shape[1]):
                grads[r, k] += pair_grads[slot, k]
    return grads
