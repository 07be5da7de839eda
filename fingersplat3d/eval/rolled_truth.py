"""A rolled-equivalent print scored against the finger's true rolled print (``fs3d synth``'s ``rolled_print``).

* **Minutiae located**: the true minutiae are carried into the print by a similarity (scale, turn,
  shift; no reflection: both prints are tip up with a photo's handedness) fitted to the minutiae
  mindtct finds on the print. Starts: the :data:`START_PEAKS` shifts at which the middle of the true print
  correlates best with the print (:func:`template_shift`; the charts' origins when the print is too small), each
  refined by a search over shifts of up to :data:`SEARCH_PX` for the most minutiae paired within 12 px and 45
  degrees, then trimmed least squares (Umeyama) on pairs within a shrinking radius; the fit that locates most
  counts. (Started from the origins alone, a print with 150 minutiae found a wrong shift with more chance pairs:
  17 % located against 55 % from the correlation's start. From the best peak alone, a print whose pad's centre sits
  a ridge or two along the finger from its sides correlated best 80-120 px off: 8 % located against 44 %.) A true
  minutia *inside* the print (on its mask, :data:`EDGE_PX` from its border) is *located* when a found one lies
  within :data:`LOCATED_PX` (8 px at 500 ppi: ~0.4 mm, under a ridge period) after the fit.
* **Minutiae placed** (the print's geometry alone, no mindtct): each true minutia's 3D point, in the model's frame,
  is carried to the print pixel whose model point is nearest (within ``max_gap``); one similarity, fitted in least
  squares to all of them and refitted once to those within twice :data:`LOCATED_PX`, takes the true print's
  positions onto those pixels. *Placed*: within :data:`LOCATED_PX` after it. Where *located* also asks that the
  print's texture show the minutia, *placed* asks only that the chart put its skin in the right place.
* **bozorth3**: the print's score against its own true print (genuine) and against other fingers'
  (impostor), :func:`fingersplat3d.eval.fingerprint.match_score`.

Pure numpy/scipy (NIST's tools through :mod:`fingersplat3d.eval.fingerprint`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

__all__ = ["TruthScore", "fit_minutiae_similarity", "located_minutiae", "placed_minutiae", "template_shift",
           "START_PEAKS", "LOCATED_PX", "SEARCH_PX", "EDGE_PX"]

LOCATED_PX = 8.0
SEARCH_PX = 60.0
START_PEAKS = 5
EDGE_PX = 8
_PAIR_PX, _PAIR_DEG = 12.0, 45.0


@dataclass(frozen=True)
class TruthScore:
    """How well a print's minutiae sit where the true ones are."""

    inside: int  # true minutiae inside the print
    located: int  # of those, with a found minutia within LOCATED_PX
    scale: float  # the fitted similarity's scale (print px per true-print px)
    turn_deg: float
    residual_px: float  # median distance of the located ones

    @property
    def located_share(self) -> float:
        return self.located / self.inside if self.inside else float("nan")


def template_shift(printed: np.ndarray, truth: np.ndarray, count: int = 1) -> np.ndarray | None:
    """``(dx, dy)`` taking true-print pixels to the print's where the middle half of ``truth`` (uint8, 255 outside)
    correlates best with ``printed`` (normalised cross-correlation); None when the print is smaller than that patch.
    ``count > 1``: the ``[count, 2]`` best peaks (or fewer), best first, each :data:`SEARCH_PX` or more from those
    before it."""
    import cv2

    height, width = truth.shape
    top, left = height // 4, width // 4
    patch = truth[top:top + height // 2, left:left + width // 2].astype(np.float32)
    image = np.asarray(printed, np.float32)
    if patch.shape[0] > image.shape[0] or patch.shape[1] > image.shape[1] or patch.size == 0:
        return None
    centred = lambda values: np.where(values < 255, values - 128.0, 0.0).astype(np.float32)  # noqa: E731
    scores = cv2.matchTemplate(centred(image), centred(patch), cv2.TM_CCORR_NORMED)
    peaks = []
    for _ in range(max(1, count)):
        row, col = np.unravel_index(int(np.argmax(scores)), scores.shape)
        if not np.isfinite(scores[row, col]):
            break
        peaks.append([col - left, row - top])
        if len(peaks) == count:
            break
        rows, cols = np.ogrid[:scores.shape[0], :scores.shape[1]]
        scores[np.hypot(rows - row, cols - col) < SEARCH_PX] = -np.inf
    if not peaks:  # no correlation anywhere (a blank print)
        return None
    return np.array(peaks[0] if count == 1 else peaks, np.float64)


def _angle_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs((np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0)


def _umeyama(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``[2, 3]`` similarity (no reflection) taking ``source`` points to ``target`` in least squares. Written here in 2D:
    :func:`fingersplat3d.align.solve.procrustes.umeyama` is 3D, and on points in a plane its proper 3D rotation can be
    a mirror of that plane turned over."""
    mu_s, mu_t = source.mean(0), target.mean(0)
    s, t = source - mu_s, target - mu_t
    u, sigma, vt = np.linalg.svd(t.T @ s / len(source))
    d = np.diag([1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    rotation = u @ d @ vt
    scale = float(np.trace(np.diag(sigma) @ d) / max((s ** 2).sum() / len(source), 1e-12))
    return np.hstack([scale * rotation, (mu_t - scale * rotation @ mu_s)[:, None]])


def _apply(transform: np.ndarray, xy: np.ndarray) -> np.ndarray:
    return xy @ transform[:, :2].T + transform[:, 2]


def _pairs(transform: np.ndarray, true_xy, true_deg, found_xy, found_deg, radius: float):
    mapped = _apply(transform, true_xy)
    turn = np.degrees(np.arctan2(transform[1, 0], transform[0, 0]))
    distance, nearest = cKDTree(found_xy).query(mapped, distance_upper_bound=radius)
    ok = np.isfinite(distance)
    ok[ok] &= _angle_gap(true_deg[ok] + turn, found_deg[nearest[ok]]) <= _PAIR_DEG
    return np.flatnonzero(ok), nearest[ok], distance[ok]


def fit_minutiae_similarity(true_xy: np.ndarray, true_deg: np.ndarray, found_xy: np.ndarray, found_deg: np.ndarray,
                            shift: np.ndarray) -> np.ndarray:
    """``[2, 3]`` similarity taking true-print pixels to the print's (module docstring), from the initial ``shift``."""
    true_xy, found_xy = np.asarray(true_xy, np.float64).reshape(-1, 2), np.asarray(found_xy, np.float64).reshape(-1, 2)
    true_deg, found_deg = np.asarray(true_deg, np.float64), np.asarray(found_deg, np.float64)
    transform = np.array([[1.0, 0.0, shift[0]], [0.0, 1.0, shift[1]]])
    if len(true_xy) < 3 or len(found_xy) < 3:
        return transform
    best, best_count = transform, -1
    for dx in np.arange(-SEARCH_PX, SEARCH_PX + 1, 6.0):
        for dy in np.arange(-SEARCH_PX, SEARCH_PX + 1, 6.0):
            trial = transform + np.array([[0, 0, dx], [0, 0, dy]])
            count = len(_pairs(trial, true_xy, true_deg, found_xy, found_deg, _PAIR_PX)[0])
            if count > best_count:
                best, best_count = trial, count
    transform = best
    for radius in (_PAIR_PX, 10.0, LOCATED_PX, LOCATED_PX):
        index, nearest, _ = _pairs(transform, true_xy, true_deg, found_xy, found_deg, radius)
        if len(index) < 3:
            break
        transform = _umeyama(true_xy[index], found_xy[nearest])
    return transform


def located_minutiae(true_xy: np.ndarray, true_deg: np.ndarray, found_xy: np.ndarray, found_deg: np.ndarray,
                     mask: np.ndarray, shift: np.ndarray) -> TruthScore:
    """The :class:`TruthScore` of a print (``found_*`` from mindtct, ``mask`` its skin) against the true minutiae;
    ``shift``: one start ``[2]`` for the similarity fit, or several ``[K, 2]``: the fit locating most counts."""
    starts = np.asarray(shift, np.float64).reshape(-1, 2)
    scores = [_located(true_xy, true_deg, found_xy, found_deg, mask, start) for start in starts]
    return max(scores, key=lambda score: score.located)


def _located(true_xy, true_deg, found_xy, found_deg, mask, shift) -> TruthScore:
    true_xy = np.asarray(true_xy, np.float64).reshape(-1, 2)
    transform = fit_minutiae_similarity(true_xy, true_deg, found_xy, found_deg, shift)
    mapped = _apply(transform, true_xy)
    inner = ndimage.binary_erosion(np.asarray(mask, bool), iterations=EDGE_PX)
    col, row = np.rint(mapped[:, 0]).astype(int), np.rint(mapped[:, 1]).astype(int)
    inside = (col >= 0) & (row >= 0) & (col < inner.shape[1]) & (row < inner.shape[0])
    inside[inside] = inner[row[inside], col[inside]]
    located = np.zeros(len(true_xy), bool)
    distance = np.full(len(true_xy), np.inf)
    if len(found_xy):
        distance, _ = cKDTree(np.asarray(found_xy, np.float64).reshape(-1, 2)).query(mapped)
        located = distance <= LOCATED_PX
    scale = float(np.hypot(transform[0, 0], transform[1, 0]))
    hits = distance[inside & located]
    return TruthScore(int(inside.sum()), int((inside & located).sum()), scale,
                      float(np.degrees(np.arctan2(transform[1, 0], transform[0, 0]))),
                      float(np.median(hits)) if hits.size else float("nan"))


def placed_minutiae(print_points: np.ndarray, mask: np.ndarray, true_model_xyz: np.ndarray, true_xy: np.ndarray,
                    max_gap: float) -> TruthScore:
    """The :class:`TruthScore` of a print's geometry (module docstring, *placed*): ``print_points [H, W, 3]`` its
    model points (NaN off the skin), ``mask`` its skin, ``true_model_xyz [N, 3]`` the true minutiae in the model's
    frame, ``true_xy [N, 2]`` their true print pixels, ``max_gap`` the farthest a minutia may lie from the print's
    surface (model units)."""
    true_xy = np.asarray(true_xy, np.float64).reshape(-1, 2)
    inner = ndimage.binary_erosion(np.asarray(mask, bool), iterations=EDGE_PX)
    rows, cols = np.nonzero(inner & np.isfinite(print_points).all(-1))
    empty = TruthScore(0, 0, float("nan"), float("nan"), float("nan"))
    if len(rows) < 3 or len(true_xy) < 3:
        return empty
    gap, nearest = cKDTree(print_points[rows, cols].astype(np.float64)).query(np.asarray(true_model_xyz, np.float64))
    inside = gap <= max_gap
    if inside.sum() < 3:
        return empty
    source, target = true_xy[inside], np.stack([cols, rows], 1)[nearest[inside]].astype(np.float64)
    transform = _umeyama(source, target)
    close = np.linalg.norm(_apply(transform, source) - target, axis=1) <= 2 * LOCATED_PX
    if close.sum() >= 3:
        transform = _umeyama(source[close], target[close])
    distance = np.linalg.norm(_apply(transform, source) - target, axis=1)
    placed = distance <= LOCATED_PX
    return TruthScore(int(inside.sum()), int(placed.sum()), float(np.hypot(transform[0, 0], transform[1, 0])),
                      float(np.degrees(np.arctan2(transform[1, 0], transform[0, 0]))),
                      float(np.median(distance[placed])) if placed.any() else float("nan"))
