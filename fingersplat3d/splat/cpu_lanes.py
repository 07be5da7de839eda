"""The compositing kernels for two or four feature columns, vectorised across a tile row (numba).

The same passes, formulas and thresholds as :mod:`.cpu_composite`'s general kernels, arranged so that
LLVM's loop vectoriser turns the per-pixel work into SIMD instructions (8 float64 lanes with AVX-512):
each Gaussian of a tile's list is applied one tile row at a time, as one loop of known length over the
row's pixels with no branch and no call in it.

* **The falloff carried down the columns.** A pair's falloff exp(-q/2) is still formed by products
  (three exps per tile pair), but along x once, on the box's first row, and then down every column at
  once: each lane holds its pixel's falloff and the factor to the pixel below, both multiplied once a
  row (the factor by exp(-c)). Lanes outside the box hold 0 and drop out at the alpha threshold.
* **Masks, not branches.** A pixel that does not composite the Gaussian (alpha under 1/255, its
  transmittance spent, or, walking back, past where it stopped) gets alpha 0, which leaves every sum and
  its transmittance exactly as they were. Where a pixel stops is written after the row, only on rows
  where one did.
* **One buffer a tile.** Every per-pixel quantity is a plane of one flat buffer (the transmittance, the
  falloff lanes, the features' sums; walking back also the opacity gradient, where each pixel stopped and
  the upstream gradients), and a row's loop indexes one slice of it at constant offsets. Held in separate
  or 2D arrays, the vectoriser could not prove that the rows do not overlap (numba's arrays carry their
  strides at run time) and left the loops scalar. Python's division check is off
  (``error_model="numpy"``: 1 - alpha >= 0.01 by the clamp), and the backward's sums over a row are
  vectorised reductions (``fastmath`` reassociation: the same sums in another order).
* **Narrow boxes walk fewer lanes.** A Gaussian whose box spans at most ``NARROW`` (4) columns of the
  tile walks only those 4 lanes, forward and back; any other the whole row of 16. On the bench's fitted
  finger the boxes are 4 columns wide at the median. (A tier of 8 lanes came out slower forward, and
  walking back 2 % faster for 6 s more compiling.)
* **Compiled once.** The two feature counts are two closures whose only free variable is the count (a
  constant to numba); the helpers are module functions called with constant lane counts. A closure that
  captured the helpers themselves was compiled again by every process: numba keys its disk cache on the
  closure's cells, and a dispatcher pickles differently in every process.

Measured in ``tools/bench_rasterizer.py``'s main case (200k Gaussians at 640x512, 2 threads, AMD EPYC
Zen 5), the kernels alone: forward 23 -> 17 ms, backward 35 -> 24 ms against the scalar kernels
compiled for the same feature count (measurements.md, Rasterizer). The general kernels stay for other
feature counts, and ``tests/test_cpu_raster.py`` checks these against them.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from .cpu_tile_math import TILE, conic_terms, falloff_exact, falloff_start, load_pair, quadratic_at, tile_rect
from .project import ALPHA_MAX, ALPHA_MIN

__all__ = ["LANE_KERNELS", "NARROW"]

NARROW = 4
"""Lanes walked for a Gaussian whose box spans at most this many of the tile's columns (half the tile pairs of a
fitted finger); any other box walks the whole row of ``TILE``."""
PLANE = (TILE + 1) * TILE
"""One per-pixel quantity of a tile, row after row, and one row more (the falloff lanes of the row below the last)."""
TRANS, FALL, STEP, OPACITY_UP, STOPPED = (k * PLANE for k in range(5))
"""Planes of a tile's buffer: the transmittance, the falloff and its factor to the row below (carried down the
rows), and for the backward the opacity gradient and where each pixel stopped. The features' planes follow: the
colour sums (forward), or the colour behind and the upstream gradients (backward)."""
FORWARD_PLANES, BACKWARD_PLANES = 3, 5


@njit(cache=True, inline="always")
def _lanes_start(buf, mx, my, a, b, c, ea, eb, bx0, by0, bx1, tx0, ty0):
    """The falloff lanes at the box's first row: exp(-q/2) and its factor to the row below at the box's
    columns, 0 at the others."""
    falloff, ratio_x, ratio_y = falloff_start(mx, my, a, b, c, bx0, by0)
    row = (by0 - ty0) * TILE
    buf[FALL + row:FALL + row + TILE] = 0.0
    buf[STEP + row:STEP + row + TILE] = 0.0
    for x in range(bx0 - tx0, bx1 - tx0 + 1):
        buf[FALL + row + x] = falloff
        buf[STEP + row + x] = ratio_y
        falloff *= ratio_x
        ratio_x *= ea
        ratio_y *= eb


@njit(cache=True, inline="always")
def _lanes_exact(buf, mx, my, a, b, c, bx0, bx1, y, tx0, ty0):
    """The falloff lanes of row ``y`` by one exp per pixel (a Gaussian outside the incremental range)."""
    row = (y - ty0) * TILE
    buf[FALL + row:FALL + row + TILE] = 0.0
    buf[STEP + row:STEP + row + TILE] = 1.0
    for x in range(bx0, bx1 + 1):
        buf[FALL + row + x - tx0] = falloff_exact(mx, my, a, b, c, x, y)


@njit(cache=True, inline="always")
def _first_lane(bx0: int, bx1: int, tx0: int, lanes: int) -> int:
    """The first of ``lanes`` consecutive lanes of the tile row that cover the box's columns; -1 where none do."""
    low = min(bx0 - tx0, TILE - lanes)
    return low if bx1 - tx0 < low + lanes else -1


@njit(cache=True, inline="always", error_model="numpy")
def _row_forward(buf, start, f0, f1, f2, f3, o, ec, min_transmittance, lanes, four):
    """One Gaussian composited into ``lanes`` pixels of a tile row, from index ``start`` (row * TILE + first lane)
    of each plane of ``buf``; returns how many pixels it stopped. ``lanes`` and ``four`` (four feature columns, else
    two) are constants at every call: inlined, the loop has a length LLVM knows."""
    w = buf[start:]  # every plane at a constant offset from one pointer: no overlap to check at run time
    acc = FORWARD_PLANES * PLANE
    stopped = 0
    for i in range(lanes):
        falloff = w[FALL + i]
        raw = o * falloff
        before = w[TRANS + i]
        live = (raw >= ALPHA_MIN) & (before >= min_transmittance)
        alpha = min(raw, ALPHA_MAX) if live else 0.0
        weight = alpha * before
        w[acc + i] += weight * f0
        w[acc + PLANE + i] += weight * f1
        if four:
            w[acc + 2 * PLANE + i] += weight * f2
            w[acc + 3 * PLANE + i] += weight * f3
        after = before * (1.0 - alpha)
        w[TRANS + i] = after
        stopped += live & (after < min_transmittance)
        step = w[STEP + i]
        w[FALL + TILE + i] = falloff * step
        w[STEP + TILE + i] = step * ec
    return stopped


@njit(cache=True, inline="always", error_model="numpy", fastmath={"contract", "reassoc"})
def _row_backward(buf, start, f0, f1, f2, f3, k, o, ec, mx, my, a, b, c, x0, dy, lanes, four):
    """One Gaussian's gradients over ``lanes`` pixels of a tile row (from index ``start`` of each plane, the first
    pixel's column ``x0``), walking back: ``(mx, my, a, b, c, o, features 0-3)``."""
    w = buf[start:]
    behind = BACKWARD_PLANES * PLANE
    upstream = (BACKWARD_PLANES + (4 if four else 2)) * PLANE
    g_mx = g_my = g_a = g_b = g_c = g_o = l0 = l1 = l2 = l3 = 0.0
    for i in range(lanes):
        dx = (x0 + i) - mx
        falloff = w[FALL + i]
        raw = o * falloff
        live = (k < w[STOPPED + i]) & (raw >= ALPHA_MIN)
        alpha = min(raw, ALPHA_MAX) if live else 0.0
        inverse = 1.0 / (1.0 - alpha)
        before = w[TRANS + i] * inverse  # T_k, the transmittance in front of Gaussian k
        w[TRANS + i] = before
        weight = alpha * before
        u0, u1 = w[upstream + i], w[upstream + PLANE + i]
        b0, b1 = w[behind + i], w[behind + PLANE + i]
        l0 += weight * u0
        l1 += weight * u1
        grad_alpha = (w[OPACITY_UP + i] * inverse + (f0 * before - b0 * inverse) * u0
                      + (f1 * before - b1 * inverse) * u1)
        w[behind + i] = b0 + f0 * weight
        w[behind + PLANE + i] = b1 + f1 * weight
        if four:
            u2, u3 = w[upstream + 2 * PLANE + i], w[upstream + 3 * PLANE + i]
            b2, b3 = w[behind + 2 * PLANE + i], w[behind + 3 * PLANE + i]
            l2 += weight * u2
            l3 += weight * u3
            grad_alpha += (f2 * before - b2 * inverse) * u2 + (f3 * before - b3 * inverse) * u3
            w[behind + 2 * PLANE + i] = b2 + f2 * weight
            w[behind + 3 * PLANE + i] = b3 + f3 * weight
        grad_alpha = grad_alpha if live & (raw < ALPHA_MAX) else 0.0  # clamped: alpha is constant
        g_o += grad_alpha * falloff
        q = quadratic_at(a, b, c, dx, dy)
        grad_q = -0.5 * grad_alpha * raw if q > 0.0 else 0.0  # q clamped at 0 (rounding only)
        t_mx, t_my, t_a, t_b, t_c = conic_terms(grad_q, a, b, c, dx, dy)
        g_mx += t_mx
        g_my += t_my
        g_a += t_a
        g_b += t_b
        g_c += t_c
        step = w[STEP + i]
        w[FALL + TILE + i] = falloff * step
        w[STEP + TILE + i] = step * ec
    return g_mx, g_my, g_a, g_b, g_c, g_o, l0, l1, l2, l3


@njit(cache=True, inline="always", error_model="numpy")
def _pair_forward(buf, used, rank, whole, feat, mx, my, a, b, c, o, ea, ec, bx0, by0, bx1, by1, tx0, ty0, low,
                  min_transmittance, lanes, four):
    """One Gaussian composited into a tile, ``lanes`` pixels of each of its rows from lane ``low``; returns how many
    pixels it stopped (``used`` records where: entry ``rank`` of the tile's list, for pixels still at ``whole``)."""
    stopped = 0
    for y in range(by0, by1 + 1):
        if ea == 0.0:  # outside the incremental range: one exp per pixel
            _lanes_exact(buf, mx, my, a, b, c, bx0, bx1, y, tx0, ty0)
        py = y - ty0
        now = _row_forward(buf, py * TILE + low, feat[0], feat[1], feat[2], feat[3], o, ec, min_transmittance, lanes,
                           four)
        if now > 0:  # where each stopped: the entry that took it under the threshold
            for px in range(TILE):
                if buf[TRANS + py * TILE + px] < min_transmittance and used[py, px] == whole:
                    used[py, px] = rank
            stopped += now
    return stopped


@njit(cache=True, inline="always", error_model="numpy", fastmath={"contract", "reassoc"})
def _pair_backward(buf, sums, k, feat, mx, my, a, b, c, o, ea, ec, bx0, by0, bx1, by1, tx0, ty0, low, lanes, four):
    """One Gaussian's gradients over a tile (``lanes`` pixels of each of its rows from lane ``low``) into ``sums``."""
    sums[:] = 0.0
    for y in range(by0, by1 + 1):
        if ea == 0.0:
            _lanes_exact(buf, mx, my, a, b, c, bx0, bx1, y, tx0, ty0)
        row = _row_backward(buf, (y - ty0) * TILE + low, feat[0], feat[1], feat[2], feat[3], k, o, ec, mx, my, a, b,
                            c, tx0 + low, y - my, lanes, four)
        for i in range(10):
            sums[i] += row[i]


def _lane_kernels(features: int):
    """``(forward, backward)`` for ``features`` (2 or 4) feature columns, with the signatures of
    :mod:`.cpu_composite`'s general kernels (the pairs carry ``features`` feature columns). The count is the
    closures' one free variable, so numba compiles it in as a constant (and caches each count's kernels apart);
    the helpers are module globals, given their lane counts as constants."""
    four = features == 4

    @njit(cache=True, parallel=True, error_model="numpy")
    def forward(starts, pairs, width, height, tiles_x, min_transmittance, chunks):
        acc = FORWARD_PLANES * PLANE
        image = np.zeros((height, width, features))
        final = np.ones((height, width))
        consumed = np.zeros((height, width), np.int32)
        num_tiles = starts.shape[0] - 1
        for chunk in prange(chunks):
            buf = np.zeros((FORWARD_PLANES + features) * PLANE)
            used = np.empty((TILE, TILE), np.int32)
            feat = np.zeros(4)
            for t in range(chunk, num_tiles, chunks):
                first, end = starts[t], starts[t + 1]
                if first == end:
                    continue
                tx0, ty0, tx1, ty1 = tile_rect(t, tiles_x, width, height)
                buf[TRANS:TRANS + PLANE] = 1.0  # pixels past the image's edge too: finite, and never composited
                buf[acc:] = 0.0
                used[:] = end - first  # a pixel that never stops walks the whole list
                alive = (tx1 - tx0 + 1) * (ty1 - ty0 + 1)
                for j in range(first, end):
                    mx, my, a, b, c, o, ea, eb, ec, bx0, by0, bx1, by1 = load_pair(pairs[j], feat[:features], tx0, ty0,
                                                                                   tx1, ty1)
                    if ea != 0.0:
                        _lanes_start(buf, mx, my, a, b, c, ea, eb, bx0, by0, bx1, tx0, ty0)
                    low = _first_lane(bx0, bx1, tx0, NARROW)
                    if low >= 0:
                        alive -= _pair_forward(buf, used, j - first + 1, end - first, feat, mx, my, a, b, c, o, ea, ec,
                                               bx0, by0, bx1, by1, tx0, ty0, low, min_transmittance, NARROW, four)
                    else:
                        alive -= _pair_forward(buf, used, j - first + 1, end - first, feat, mx, my, a, b, c, o, ea, ec,
                                               bx0, by0, bx1, by1, tx0, ty0, 0, min_transmittance, TILE, four)
                    if alive == 0:
                        break
                for y in range(ty0, ty1 + 1):
                    for x in range(tx0, tx1 + 1):
                        pixel = (y - ty0) * TILE + x - tx0
                        final[y, x] = buf[TRANS + pixel]
                        consumed[y, x] = used[y - ty0, x - tx0]
                        for f in range(features):
                            image[y, x, f] = buf[acc + f * PLANE + pixel]
        return image, final, consumed

    @njit(cache=True, parallel=True, error_model="numpy", fastmath={"contract", "reassoc"})
    def backward(starts, pairs, width, height, tiles_x, final, consumed, grad_image, grad_alpha_image, chunks):
        upstream = (BACKWARD_PLANES + features) * PLANE
        pair_grads = np.zeros((pairs.shape[0], 6 + features))
        num_tiles = starts.shape[0] - 1
        for chunk in prange(chunks):
            buf = np.zeros((BACKWARD_PLANES + 2 * features) * PLANE)
            feat = np.zeros(4)
            sums = np.empty(10)
            for t in range(chunk, num_tiles, chunks):
                first, end = starts[t], starts[t + 1]
                if first == end:
                    continue
                tx0, ty0, tx1, ty1 = tile_rect(t, tiles_x, width, height)
                buf[TRANS:TRANS + PLANE] = 1.0  # pixels past the image's edge: finite, stopped before entry 0
                buf[OPACITY_UP:] = 0.0
                deepest = 0
                for y in range(ty0, ty1 + 1):
                    for x in range(tx0, tx1 + 1):
                        pixel = (y - ty0) * TILE + x - tx0
                        buf[TRANS + pixel] = final[y, x]
                        buf[OPACITY_UP + pixel] = grad_alpha_image[y, x] * final[y, x]
                        buf[STOPPED + pixel] = consumed[y, x]
                        deepest = max(deepest, consumed[y, x])
                        for f in range(features):
                            buf[upstream + f * PLANE + pixel] = grad_image[y, x, f]
                for k in range(deepest - 1, -1, -1):
                    mx, my, a, b, c, o, ea, eb, ec, bx0, by0, bx1, by1 = load_pair(pairs[first + k], feat[:features],
                                                                                   tx0, ty0, tx1, ty1)
                    if ea != 0.0:
                        _lanes_start(buf, mx, my, a, b, c, ea, eb, bx0, by0, bx1, tx0, ty0)
                    low = _first_lane(bx0, bx1, tx0, NARROW)
                    if low >= 0:
                        _pair_backward(buf, sums, k, feat, mx, my, a, b, c, o, ea, ec, bx0, by0, bx1, by1, tx0, ty0,
                                       low, NARROW, four)
                    else:
                        _pair_backward(buf, sums, k, feat, mx, my, a, b, c, o, ea, ec, bx0, by0, bx1, by1, tx0, ty0, 0,
                                       TILE, four)
                    local = pair_grads[first + k]
                    for i in range(6 + features):
                        local[i] = sums[i]
        return pair_grads

    return forward, backward


LANE_KERNELS = {features: _lane_kernels(features) for features in (2, 4)}
"""``(forward, backward)`` by feature count."""
