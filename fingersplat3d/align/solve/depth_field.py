"""A smooth correction field over an image: uniform cubic B-splines on a coarse grid of knots.

The global alignment corrects each view's pointmap depth with such a field
(:mod:`fingersplat3d.align.global_opt`): the pointmap's shape only initialises the surface, and the
correspondences reshape it wherever views overlap; the field's bending penalty (second differences
of the coefficients) lets the pointmap fill in where no view constrains it.

A field over the box ``(u0, v0, u1, v1)`` with knot ``spacing`` has ``(gy, gx)`` coefficients; a
point's value is a weighted sum of 4x4 of them, so the basis is stored sparse: 16 coefficient
indices and weights per point (:class:`FieldBasis`). Numpy (the finger's width for the knots: OpenCV's distance
transform, :func:`~fingersplat3d.segment.silhouette.widest_disc`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...segment.silhouette import widest_disc

__all__ = ["FieldGrid", "FieldBasis", "CROP_WIDER"]

CROP_WIDER = 1.1
"""How much wider than its box's short side the widest disc inside a mask must be to set the knots instead: on whole
fingers the two agree within a pixel or two (the box's side is kept, so their fields are as before); a real capture
cropped about its centre to 240-440 pixels along the finger, the frame cutting the tip off, reads 1.3-2.4."""


@dataclass(frozen=True)
class FieldGrid:
    """The knot grid of one field: its box (pixels), knot spacing and coefficient grid shape."""

    u0: float
    v0: float
    spacing: float
    shape: tuple[int, int]  # (gy, gx)

    @classmethod
    def covering(cls, mask: np.ndarray, knots_across: float) -> "FieldGrid":
        """A grid over the bounding box of ``mask`` with about ``knots_across`` knot intervals across the finger: its
        box's short side, or the widest disc inside it where that is :data:`CROP_WIDER` times wider (a crop shorter
        along the finger than across it, cut by the frame at both ends, whose box's short side is its length)."""
        rows, cols = np.nonzero(mask)
        if rows.size == 0:
            rows, cols = np.array([0, mask.shape[0] - 1]), np.array([0, mask.shape[1] - 1])
        u0, u1, v0, v1 = float(cols.min()), float(cols.max()), float(rows.min()), float(rows.max())
        across, disc = min(u1 - u0, v1 - v0), widest_disc(mask)
        if disc > CROP_WIDER * across:
            across = disc
        spacing = max(1.0, across / max(knots_across, 1e-9))
        shape = (int(np.ceil((v1 - v0) / spacing)) + 3, int(np.ceil((u1 - u0) / spacing)) + 3)
        return cls(u0, v0, spacing, shape)

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]

    def basis(self, uv: np.ndarray) -> "FieldBasis":
        """The 16 coefficients and cubic B-spline weights of each point ``uv [N, 2]`` (clamped to the grid)."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        gy, gx = self.shape
        x = (uv[:, 0] - self.u0) / self.spacing + 1.0
        y = (uv[:, 1] - self.v0) / self.spacing + 1.0
        ix = np.clip(np.floor(x).astype(np.int64), 1, gx - 3)
        iy = np.clip(np.floor(y).astype(np.int64), 1, gy - 3)
        wx, wy = _cubic_weights(np.clip(x - ix, 0.0, 1.0)), _cubic_weights(np.clip(y - iy, 0.0, 1.0))
        offsets = np.arange(4) - 1
        index = (iy[:, None, None] + offsets[None, :, None]) * gx + (ix[:, None, None] + offsets[None, None, :])
        weight = wy[:, :, None] * wx[:, None, :]
        return FieldBasis(index.reshape(len(uv), 16), weight.reshape(len(uv), 16))

    def dense(self, coefficients: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """The field on every pixel of an image of ``shape`` (rows, cols), as a separable product."""
        rows, cols = shape
        gy, gx = self.shape
        return self._axis_weights(np.arange(rows), self.v0, gy) @ np.asarray(coefficients).reshape(gy, gx) \
            @ self._axis_weights(np.arange(cols), self.u0, gx).T

    def _axis_weights(self, positions: np.ndarray, origin: float, count: int) -> np.ndarray:
        """``[len(positions), count]`` 1D cubic B-spline weights along one axis (clamped as in :meth:`basis`)."""
        x = (positions - origin) / self.spacing + 1.0
        index = np.clip(np.floor(x).astype(np.int64), 1, count - 3)
        weights = _cubic_weights(np.clip(x - index, 0.0, 1.0))
        matrix = np.zeros((len(positions), count))
        for k in range(4):
            matrix[np.arange(len(positions)), index - 1 + k] = weights[:, k]
        return matrix

    def bending(self) -> tuple[np.ndarray, np.ndarray]:
        """Second differences of the coefficients along rows and columns: index triples ``[K, 3]`` and their weights (1, -2, 1)."""
        gy, gx = self.shape
        grid = np.arange(gy * gx).reshape(gy, gx)
        rows = np.stack([grid[:, :-2].ravel(), grid[:, 1:-1].ravel(), grid[:, 2:].ravel()], 1)
        cols = np.stack([grid[:-2, :].ravel(), grid[1:-1, :].ravel(), grid[2:, :].ravel()], 1)
        triples = np.concatenate([rows, cols]) if rows.size or cols.size else np.zeros((0, 3), np.int64)
        return triples, np.array([1.0, -2.0, 1.0])


@dataclass(frozen=True, eq=False)
class FieldBasis:
    """Sparse basis rows: ``value[n] = sum_k weight[n, k] * coefficients[index[n, k]]``."""

    index: np.ndarray  # [N, 16] int64
    weight: np.ndarray  # [N, 16] float64, each row sums to 1

    def evaluate(self, coefficients: np.ndarray) -> np.ndarray:
        return (np.asarray(coefficients)[self.index] * self.weight).sum(-1)


def _cubic_weights(t: np.ndarray) -> np.ndarray:
    """Uniform cubic B-spline weights ``[N, 4]`` of the four knots around fractional position ``t``."""
    return np.stack([(1 - t) ** 3 / 6.0, (3 * t ** 3 - 6 * t ** 2 + 4) / 6.0,
                     (-3 * t ** 3 + 3 * t ** 2 + 3 * t + 1) / 6.0, t ** 3 / 6.0], axis=1)
