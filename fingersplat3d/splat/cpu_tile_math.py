"""What every compositing kernel computes per tile and per (tile, Gaussian) pair (numba): the tile's
pixel rectangle, a pair's record and its falloff by products.

Shared by the general kernels (:mod:`.cpu_composite`) and the vectorised ones (:mod:`.cpu_lanes`).
"""
from __future__ import annotations

import math

from numba import njit

__all__ = ["TILE", "FEATS", "EXPONENT_RANGE", "conic_terms", "falloff_exact", "falloff_start", "load_pair", "quadratic",
           "quadratic_at", "tile_rect"]

TILE = 16
"""Tile side in pixels: 256 pixels per tile keep a tile's state in L1 and amortise the list walk."""

# Columns of a Gaussian's record (one row per drawn Gaussian, front to back, then one per tile pair).
MX, MY, A, B, C, O, QMAX, EA, EB, EC, X0, Y0, X1, Y1 = range(14)
FEATS = 14
EXPONENT_RANGE = 600.0
"""The incremental falloff (:func:`falloff_start`) is used when every exponent it involves stays
within this of zero over the Gaussian's box, so that no factor under- or overflows float64."""


@njit(cache=True, inline="always")
def load_pair(rec, feat, tx0, ty0, tx1, ty1):
    """A tile pair's record: ``(mx, my, a, b, c, o, exp(-a), exp(-b), exp(-c), x0, y0, x1, y1)`` with
    the Gaussian's pixel box clipped to the tile ``[tx0, tx1] x [ty0, ty1]``; its features into ``feat``."""
    for f in range(feat.shape[0]):
        feat[f] = rec[FEATS + f]
    return (float(rec[MX]), float(rec[MY]), float(rec[A]), float(rec[B]), float(rec[C]), float(rec[O]),
            float(rec[EA]), float(rec[EB]), float(rec[EC]), max(tx0, int(rec[X0])), max(ty0, int(rec[Y0])),
            min(tx1, int(rec[X1])), min(ty1, int(rec[Y1])))


@njit(cache=True, inline="always")
def quadratic_at(a: float, b: float, c: float, dx: float, dy: float) -> float:
    """q = d^T conic d for the offset d = (dx, dy) from the mean."""
    return dx * (a * dx + 2.0 * b * dy) + c * dy * dy


@njit(cache=True, inline="always")
def quadratic(mx: float, my: float, a: float, b: float, c: float, x: int, y: int) -> float:
    """q = d^T conic d at pixel (x, y), d = pixel - mean."""
    return quadratic_at(a, b, c, x - mx, y - my)


@njit(cache=True, inline="always")
def falloff_exact(mx: float, my: float, a: float, b: float, c: float, x: int, y: int) -> float:
    """exp(-q / 2) at pixel (x, y) by its own exp (q clamped at 0: rounding only), where the products of
    :func:`falloff_start` are not used."""
    return math.exp(-0.5 * max(quadratic(mx, my, a, b, c, x, y), 0.0))


@njit(cache=True, inline="always")
def falloff_start(mx: float, my: float, a: float, b: float, c: float, x: int, y: int):
    """At pixel (x, y): ``(falloff, ratio_x, ratio_y)`` = exp(-q / 2), exp(-(q(x + 1, y) - q) / 2),
    exp(-(q(x, y + 1) - q) / 2). From there the falloff of every pixel of a block follows by
    products: along a row falloff *= ratio_x, ratio_x *= exp(-a); down a column falloff *= ratio_y,
    ratio_y *= exp(-c), and the row's first ratio_x *= exp(-b): three exps per (tile, Gaussian)
    pair instead of one per pixel, exact up to float64 rounding over a tile's 16 + 16 steps."""
    dx, dy = x - mx, y - my
    return (falloff_exact(mx, my, a, b, c, x, y),
            math.exp(-0.5 * (a * (2.0 * dx + 1.0) + 2.0 * b * dy)),
            math.exp(-0.5 * (c * (2.0 * dy + 1.0) + 2.0 * b * dx)))


@njit(cache=True, inline="always")
def tile_rect(t, tiles_x, width, height):
    """Tile ``t``'s inclusive pixel rectangle ``(x0, y0, x1, y1)``, cut at the image's edge."""
    x0, y0 = (t % tiles_x) * TILE, (t // tiles_x) * TILE
    return x0, y0, min(x0 + TILE, width) - 1, min(y0 + TILE, height) - 1


@njit(cache=True, inline="always")
def conic_terms(grad_q: float, a: float, b: float, c: float, dx: float, dy: float):
    """A pixel's share of the gradients of (mx, my, a, b, c) given dL/dq there, q = d^T conic d, d = (dx, dy)."""
    return (-2.0 * grad_q * (a * dx + b * dy), -2.0 * grad_q * (b * dx + c * dy), grad_q * dx * dx,
            2.0 * grad_q * dx * dy, grad_q * dy * dy)
