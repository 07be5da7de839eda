"""Guided matching: ridge-texture correspondences on a grid, searched around a prediction.

A *predictor* maps pixels of view a to where view b should see them (through cylinder charts in
the first round, through the current 3D model afterwards) and says whether b sees them. For each
grid point of a, the patch of b around the prediction is resampled into a's frame with the
predictor's local quadratic map (its Jacobian and its bend over the patch), which undoes the
foreshortening between the views, and a's patch is slid over it (normalised cross-correlation);
the peak, refined to sub-pixel by a parabola, is the match. So the search only has to cover the
predictor's error, not the whole image, and a repeating ridge pattern is not confused with its
neighbour when that error is below half a ridge period. The bend matters on a finger: the
foreshortening grows across a patch towards the silhouette, and an affine map alone set side
views' matches 0.8-1.6 px off across the finger, all the same way (a bias the global alignment
cannot average away; with the bend 0.0-0.2 px; docs/measurements.md, stop 73).

Ridge texture is nearly one-dimensional over a few periods: a patch pins the position *across*
the ridges to a fraction of a pixel and *along* them hardly at all (measured on synthetic
captures: median error 0.4-0.8 px across, 1.3-3.4 px along). Each match therefore carries an
information matrix, the structure tensor of a's patch normalised to 1 across the ridges and
mapped into b's pixels through the Jacobian: a residual ``r`` costs ``r^T I r``, so the global
alignment uses each match for what it measures.

Pure numpy/OpenCV.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from ...device import cpu_threads, per_item
from ...segment.morphology import eroded
from ...structure_tensor import structure_products

__all__ = ["GuidedMatches", "Predictor", "RidgeMaps", "predict_with_curvature", "predict_with_jacobian", "match_guided",
           "structure_information"]

Predictor = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``uv_a [N, 2] -> (uv_b [N, 2], seen_in_b [N] bool)``."""

PATCH_PERIODS = 2.5
"""Patch half-size in ridge periods: enough curvature of the ridges to pin a position. Smaller ones (1.75) measured on
every registration figure at stops 71-72 (docs/measurements.md), with the affine patch warp of then: the warp check and
the held-out finger better, the rig's side cameras worse, because the smaller patches' smaller warp bias no longer
offset the contour targets' one-pixel inset (both gone at stop 73); chance peaks more frequent."""
MIN_SCORE = 0.4
"""Correlation a match must reach."""
MIN_UNIQUENESS = 0.03
"""How far the peak must stand above the best correlation at least 0.6 periods away."""
_FLOOR = 1e-3  # information along the ridges never drops below this share of the information across


@dataclass(frozen=True, eq=False)
class GuidedMatches:
    """Correspondences ``uv_a <-> uv_b`` with their correlation and information matrices."""

    uv_a: np.ndarray  # [N, 2]
    uv_b: np.ndarray  # [N, 2]
    score: np.ndarray  # [N] normalised cross-correlation at the peak
    information_a: np.ndarray  # [N, 2, 2] in a's pixels (1 across the ridges)
    information_b: np.ndarray  # [N, 2, 2] in b's pixels
    tried: int = 0
    """Points of a's grid that were searched (their prediction on b's finger): the matches are a share of them."""

    def __len__(self) -> int:
        return len(self.uv_a)

    def subset(self, keep: np.ndarray) -> "GuidedMatches":
        return GuidedMatches(self.uv_a[keep], self.uv_b[keep], self.score[keep], self.information_a[keep],
                             self.information_b[keep], self.tried)

    def swapped(self) -> "GuidedMatches":
        """The same correspondences read from b to a."""
        return GuidedMatches(self.uv_b, self.uv_a, self.score, self.information_b, self.information_a, self.tried)

    def joined(self, other: "GuidedMatches") -> "GuidedMatches":
        """These correspondences and ``other``'s (of the same two views, the same way round); their points searched
        added up."""
        return GuidedMatches(np.concatenate([self.uv_a, other.uv_a]), np.concatenate([self.uv_b, other.uv_b]),
                             np.concatenate([self.score, other.score]),
                             np.concatenate([self.information_a, other.information_a]),
                             np.concatenate([self.information_b, other.information_b]), self.tried + other.tried)

    @classmethod
    def empty(cls) -> "GuidedMatches":
        return cls(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2, 2)), np.zeros((0, 2, 2)))


def predict_with_jacobian(predictor: Predictor, uv: np.ndarray, step: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predictions ``[N, 2]``, their Jacobians ``d uv_b / d uv_a`` ``[N, 2, 2]`` (central differences) and visibility."""
    uv = np.asarray(uv, np.float64)
    centre, seen = predictor(uv)
    columns = []
    for axis in range(2):
        offset = np.zeros(2)
        offset[axis] = step
        forward, _ = predictor(uv + offset)
        backward, _ = predictor(uv - offset)
        columns.append((forward - backward) / (2.0 * step))
    jacobian = np.stack(columns, axis=-1)
    finite = np.isfinite(centre).all(1) & np.isfinite(jacobian).all((1, 2))
    return centre, jacobian, seen & finite


def _structure_products(texture: np.ndarray, half: int) -> np.ndarray:
    """``[H, W, 3]`` the structure tensor of ``texture`` (float32) over a Gaussian of ``half / 2``."""
    return structure_products(np.asarray(texture, np.float32), max(1.0, half / 2.0))


def _sampled_information(products: np.ndarray, uv: np.ndarray) -> np.ndarray:
    u = np.clip(np.round(uv[:, 0]).astype(int), 0, products.shape[1] - 1)
    v = np.clip(np.round(uv[:, 1]).astype(int), 0, products.shape[0] - 1)
    xx, xy, yy = products[v, u].astype(np.float64).T
    tensor = np.stack([np.stack([xx, xy], -1), np.stack([xy, yy], -1)], -2)
    largest = np.linalg.eigvalsh(tensor)[:, 1]
    return tensor / np.maximum(largest, 1e-30)[:, None, None] + _FLOOR * np.eye(2)


def structure_information(texture: np.ndarray, uv: np.ndarray, half: int) -> np.ndarray:
    """``[N, 2, 2]`` structure tensors of ``texture`` at ``uv`` (Gaussian window of ``half / 2``), 1 across the ridges."""
    return _sampled_information(_structure_products(texture, half), uv)


class RidgeMaps:
    """One view as guided matching reads it: its ridge texture (float32) and finger mask, with the maps derived from
    them (eroded masks, blurred structure products) made once per size and kept: every pair and round of a
    registration reads the same few (they were a third of the matching's time when remade per call)."""

    def __init__(self, texture: np.ndarray, mask: np.ndarray) -> None:
        self.texture = np.asarray(texture, np.float32)
        self.mask = np.asarray(mask, bool)
        self._derived: dict = {}

    def inner(self, size: int) -> np.ndarray:
        """The mask eroded by a disc ``size`` (odd) pixels across."""
        key = ("inner", size)
        if key not in self._derived:
            self._derived[key] = eroded(self.mask, size // 2)
        return self._derived[key]

    def information(self, uv: np.ndarray, half: int) -> np.ndarray:
        """:func:`structure_information` of the texture at ``uv``."""
        key = ("structure", half)
        if key not in self._derived:
            self._derived[key] = _structure_products(self.texture, half)
        return _sampled_information(self._derived[key], uv)


def _grid(maps: RidgeMaps, half: int, stride: float) -> np.ndarray:
    inner = maps.inner(2 * half + 1)
    rows, cols = np.mgrid[half:inner.shape[0] - half:stride, half:inner.shape[1] - half:stride]
    grid = np.stack([cols.ravel(), rows.ravel()], 1).astype(np.float64)
    return grid[inner[grid[:, 1].astype(int), grid[:, 0].astype(int)]]


def _on_points(grid: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``[N]`` whether each grid point lies within a hundredth of a pixel of one of ``points``."""
    points = points[np.isfinite(points).all(1) & (points >= 0.0).all(1)]
    if len(points) == 0:
        return np.zeros(len(grid), bool)
    keys = [np.round(np.asarray(xy) * 100.0).astype(np.int64) for xy in (grid, points)]
    width = int(max(keys[0][:, 0].max(), keys[1][:, 0].max())) + 1
    return np.isin(keys[0][:, 1] * width + keys[0][:, 0], keys[1][:, 1] * width + keys[1][:, 0])


def _parabola(left, centre, right) -> float:
    """Sub-pixel offset of a peak from its two neighbours (float32 scores), within half a pixel. Python's min and max,
    not ``np.clip``: the same value, a tenth of the cost, and it runs twice for every point searched."""
    denominator = left - 2.0 * centre + right
    return float(min(max(0.5 * (left - right) / denominator, -0.5), 0.5)) if denominator < 0 else 0.0


def _match_one(texture_a, texture_b, point, coefficients, basis, half, search, exclusion):
    """``(offset_u, offset_v, score, uniqueness)`` of one grid point: the peak's offset from the prediction in a's frame
    (NaN when the correlation surface is empty); b's region is resampled in a's frame through the predictor's local
    quadratic map (:func:`_region`)."""
    size = 2 * half + 1
    template = cv2.getRectSubPix(texture_a, (size, size), (float(point[0]), float(point[1])))
    region = _region(texture_b, coefficients, basis)
    score = cv2.matchTemplate(region, template, cv2.TM_CCOEFF_NORMED)
    _, best, _, (px, py) = cv2.minMaxLoc(score)
    if not math.isfinite(best):
        return math.nan, math.nan, 0.0, 0.0
    others = score.copy()
    cv2.circle(others, (px, py), exclusion, -1.0, -1)
    dx = _parabola(score[py, px - 1], score[py, px], score[py, px + 1]) if 0 < px < score.shape[1] - 1 else 0.0
    dy = _parabola(score[py - 1, px], score[py, px], score[py + 1, px]) if 0 < py < score.shape[0] - 1 else 0.0
    return px + dx - search, py + dy - search, float(best), float(best - others.max())


def _monomials(d: np.ndarray) -> np.ndarray:
    """``[..., 6]`` the terms ``1, du, dv, du^2 / 2, du dv, dv^2 / 2`` of offsets ``d [..., 2]``: a local quadratic map is
    these times its :func:`_coefficients`."""
    du, dv = d[..., 0], d[..., 1]
    return np.stack([np.ones_like(du), du, dv, 0.5 * du * du, du * dv, 0.5 * dv * dv], -1)


def _coefficients(prediction: np.ndarray, jacobian: np.ndarray, hessian: np.ndarray) -> np.ndarray:
    """``[N, 6, 2]`` the maps ``prediction + J d + d^T H d / 2`` (``hessian [N, 2, 2, 2]``, one symmetric matrix per
    coordinate of b) as coefficients of :func:`_monomials`."""
    return np.stack([prediction, jacobian[:, :, 0], jacobian[:, :, 1], hessian[:, :, 0, 0], hessian[:, :, 0, 1],
                     hessian[:, :, 1, 1]], 1)


def _region(texture_b: np.ndarray, coefficients: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """b's texture resampled through a point's local map (``coefficients [6, 2]``) at the region's offsets (``basis
    [R, R, 6]``, their :func:`_monomials` in float32): the region around the prediction seen in a's frame. One small
    product and a remap: 0.16 ms a point (an affine warp 0.10 ms; the map as one einsum cost 2 ms)."""
    where = basis @ coefficients.astype(np.float32)
    return cv2.remap(texture_b, where[..., 0], where[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def predict_with_curvature(predictor: Predictor, uv: np.ndarray, reach: float,
                           centre: np.ndarray | None = None) -> np.ndarray:
    """``[N, 2, 2, 2]`` second derivatives of the predictor at ``uv`` (per coordinate of b), from its values ``reach``
    pixels around each point (a patch's scale: the bend the patch sees, not the local one); zero where any of those is
    not finite (near the edge of a's surface), which leaves the affine map. ``centre``: the predictions at ``uv``
    themselves, when the caller holds them."""
    uv = np.asarray(uv, np.float64)
    value = {}
    for du in (-1, 0, 1):
        for dv in (-1, 0, 1):
            if (du, dv) == (0, 0) and centre is not None:
                value[du, dv] = np.asarray(centre, np.float64)
            else:
                value[du, dv] = predictor(uv + reach * np.array([du, dv], np.float64))[0]
    uu = (value[1, 0] - 2.0 * value[0, 0] + value[-1, 0]) / reach**2
    vv = (value[0, 1] - 2.0 * value[0, 0] + value[0, -1]) / reach**2
    uv_ = (value[1, 1] - value[1, -1] - value[-1, 1] + value[-1, -1]) / (4.0 * reach**2)
    hessian = np.stack([np.stack([uu, uv_], -1), np.stack([uv_, vv], -1)], -1)  # [N, 2(k), 2, 2]
    finite = np.isfinite(hessian).all((1, 2, 3))
    hessian[~finite] = 0.0
    return hessian


def match_guided(maps_a: RidgeMaps, maps_b: RidgeMaps, predictor: Predictor, period: float, search: float, *, stride: float | None = None,
                 min_score: float = MIN_SCORE, min_uniqueness: float = MIN_UNIQUENESS,
                 patch_periods: float = PATCH_PERIODS, curvature: bool = True,
                 skip: np.ndarray | None = None) -> GuidedMatches:
    """Matches of a grid of ``a`` (every ``stride`` pixels, default one period) searched ``search`` px around the predictions,
    with patches of half-size ``patch_periods`` ridge periods.

    ``maps_*`` hold the ridge textures (:func:`fingersplat3d.align.texture.ridge_texture`) and the
    finger masks; a point is tried when its patch lies on the finger in a and its
    prediction, seen by b, lies on the finger in b with a non-degenerate local map. ``curvature=False`` resamples b
    through the predictor's affine map alone (before stop 73; kept for tools/bench_guided_bias.py). ``skip``: pixels
    ``[K, 2]`` of a whose grid points are left out (matched already; within a hundredth of a pixel).
    """
    half = max(3, int(round(patch_periods * period)))
    search = max(1, int(round(search)))
    grid = _grid(maps_a, half, stride or period)
    if skip is not None and len(skip) and len(grid):
        grid = grid[~_on_points(grid, np.asarray(skip, np.float64))]
    if len(grid) == 0:
        return GuidedMatches.empty()
    prediction, jacobian, seen = predict_with_jacobian(predictor, grid)
    inner_b = maps_b.inner(half | 1)
    height, width = inner_b.shape
    inside = seen & (prediction[:, 0] >= 0) & (prediction[:, 1] >= 0) & (prediction[:, 0] <= width - 1) & (prediction[:, 1] <= height - 1)
    inside[inside] &= inner_b[np.round(prediction[inside, 1]).astype(int), np.round(prediction[inside, 0]).astype(int)]
    determinant = np.linalg.det(np.where(np.isfinite(jacobian), jacobian, 0.0))
    inside &= (determinant > 0.05) & (determinant < 20.0)
    index = np.flatnonzero(inside)
    exclusion = max(2, int(round(0.6 * period)))
    texture_a, texture_b = maps_a.texture, maps_b.texture
    # Patches in parallel on the process's threads (OpenCV releases the GIL), OpenCV itself on one each.
    # A few chunks per thread, not a task per point: a task's hand-off cost as much as a small patch's search.
    threads = cpu_threads()
    chunks = np.array_split(index, min(len(index), 4 * threads)) if len(index) else []

    hessian = np.zeros((len(grid), 2, 2, 2))
    if curvature and len(index):
        hessian[index] = predict_with_curvature(predictor, grid[index], 0.5 * half, prediction[index])
    coefficients = _coefficients(prediction, jacobian, hessian)
    steps = np.arange(-(half + search), half + search + 1, dtype=np.float64)
    basis = _monomials(np.stack(np.meshgrid(steps, steps), -1)).astype(np.float32)  # [R, R, 6], (u, v) from the point

    def chunk(points: np.ndarray) -> list:
        return [_match_one(texture_a, texture_b, grid[i], coefficients[i], basis, half, search, exclusion) for i in points]

    results = np.array([r for part in per_item(chunk, chunks) for r in part], np.float64).reshape(-1, 4)
    # Each peak carried from a's frame into b's by the point's own local map.
    uv_b = (_monomials(results[:, :2])[:, None, :] @ coefficients[index])[:, 0]
    score, uniqueness = results[:, 2], results[:, 3]
    keep = np.isfinite(uv_b).all(1) & (score >= min_score) & (uniqueness >= min_uniqueness)
    uv_a, uv_b, score, J = grid[index][keep], uv_b[keep], score[keep], jacobian[index][keep]
    information_a = maps_a.information(uv_a, half)
    J_inv = np.linalg.inv(J)
    information_b = np.einsum("nji,njk,nkl->nil", J_inv, information_a, J_inv)
    return GuidedMatches(uv_a, uv_b, score, information_a, information_b, len(index))
