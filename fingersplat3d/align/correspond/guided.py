"""Guided matching: ridge-texture correspondences on a grid, searched around a prediction.

A *predictor* maps pixels of view a to where view b should see them (through cylinder charts in
the first round, through the current 3D model afterwards) and says whether b sees them. For each
grid point of a, the patch of b around the prediction is resampled into a's frame with the
predictor's local affine map (its Jacobian), which undoes the foreshortening between the views,
and a's patch is slid over it (normalised cross-correlation); the peak, refined to sub-pixel by a
parabola, is the match. So the search only has to cover the predictor's error, not the whole
image, and a repeating ridge pattern is not confused with its neighbour when that error is below
half a ridge period.

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
from .texture import structure_products

__all__ = ["GuidedMatches", "Predictor", "RidgeMaps", "predict_with_jacobian", "match_guided", "structure_information"]

Predictor = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``uv_a [N, 2] -> (uv_b [N, 2], seen_in_b [N] bool)``."""

PATCH_PERIODS = 2.5
"""Patch half-size in ridge periods: enough curvature of the ridges to pin a position. Smaller ones (1.75) measured on
every registration figure (docs/measurements.md, stops 71-72): the warp check and the held-out finger better, but the
side cameras of a rig biased (synthetic rig self-calibration 0.25 -> 0.57 degrees) and chance peaks more frequent."""
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


def _parabola(left, centre, right) -> float:
    """Sub-pixel offset of a peak from its two neighbours (float32 scores), within half a pixel. Python's min and max,
    not ``np.clip``: the same value, a tenth of the cost, and it runs twice for every point searched."""
    denominator = left - 2.0 * centre + right
    return float(min(max(0.5 * (left - right) / denominator, -0.5), 0.5)) if denominator < 0 else 0.0


def _match_one(texture_a, texture_b, point, warp, half, search, exclusion):
    """``(offset_u, offset_v, score, uniqueness)`` of one grid point: the peak's offset from the prediction in a's frame
    (NaN when the correlation surface is empty); ``warp``: the 2x3 map showing b in a's frame (:func:`_region_warps`)."""
    size = 2 * half + 1
    template = cv2.getRectSubPix(texture_a, (size, size), (float(point[0]), float(point[1])))
    reach = 2 * (half + search) + 1
    region = cv2.warpAffine(texture_b, warp, (reach, reach), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    score = cv2.matchTemplate(region, template, cv2.TM_CCOEFF_NORMED)
    _, best, _, (px, py) = cv2.minMaxLoc(score)
    if not math.isfinite(best):
        return math.nan, math.nan, 0.0, 0.0
    others = score.copy()
    cv2.circle(others, (px, py), exclusion, -1.0, -1)
    dx = _parabola(score[py, px - 1], score[py, px], score[py, px + 1]) if 0 < px < score.shape[1] - 1 else 0.0
    dy = _parabola(score[py - 1, px], score[py, px], score[py + 1, px]) if 0 < py < score.shape[0] - 1 else 0.0
    return px + dx - search, py + dy - search, float(best), float(best - others.max())


def _region_warps(prediction: np.ndarray, jacobian: np.ndarray, centre: int) -> np.ndarray:
    """``[N, 2, 3]`` affine maps whose output pixel ``x`` shows b at ``prediction + J (x - centre)`` (b resampled in a's
    frame around each prediction), made for all points at once."""
    return np.concatenate([jacobian, (prediction - jacobian @ np.array([centre, centre], np.float64))[:, :, None]], 2)


def match_guided(maps_a: RidgeMaps, maps_b: RidgeMaps, predictor: Predictor, period: float, search: float, *, stride: float | None = None,
                 min_score: float = MIN_SCORE, min_uniqueness: float = MIN_UNIQUENESS,
                 patch_periods: float = PATCH_PERIODS) -> GuidedMatches:
    """Matches of a grid of ``a`` (every ``stride`` pixels, default one period) searched ``search`` px around the predictions,
    with patches of half-size ``patch_periods`` ridge periods.

    ``maps_*`` hold the ridge textures (:func:`fingersplat3d.align.texture.ridge_texture`) and the
    finger masks; a point is tried when its patch lies on the finger in a and its
    prediction, seen by b, lies on the finger in b with a non-degenerate local map.
    """
    half = max(3, int(round(patch_periods * period)))
    search = max(1, int(round(search)))
    grid = _grid(maps_a, half, stride or period)
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

    warps = np.zeros((len(grid), 2, 3))
    warps[index] = _region_warps(prediction[index], jacobian[index], half + search)

    def chunk(points: np.ndarray) -> list:
        return [_match_one(texture_a, texture_b, grid[i], warps[i], half, search, exclusion) for i in points]

    results = np.array([r for part in per_item(chunk, chunks) for r in part], np.float64).reshape(-1, 4)
    # Each peak carried from a's frame into b's by the point's own local map (its matmul, as one stacked product).
    uv_b = prediction[index] + (jacobian[index] @ results[:, :2, None])[:, :, 0]
    score, uniqueness = results[:, 2], results[:, 3]
    keep = np.isfinite(uv_b).all(1) & (score >= min_score) & (uniqueness >= min_uniqueness)
    uv_a, uv_b, score, J = grid[index][keep], uv_b[keep], score[keep], jacobian[index][keep]
    information_a = maps_a.information(uv_a, half)
    J_inv = np.linalg.inv(J)
    information_b = np.einsum("nji,njk,nkl->nil", J_inv, information_a, J_inv)
    return GuidedMatches(uv_a, uv_b, score, information_a, information_b, len(index))
