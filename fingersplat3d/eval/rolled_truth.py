"""A rolled-equivalent print scored against the finger's true rolled print (``fs3d synth``'s ``rolled_print``).

* **Minutiae located**: the true minutiae are carried into the print by a similarity (scale, turn,
  shift; no reflection: both prints are tip up with a photo's handedness) fitted to the minutiae
  mindtct finds on the print. Start: the shift at which the middle of the true print correlates best
  with the print (:func:`template_shift`; the charts' origins when the print is too small), refined by
  a search over shifts of up to :data:`SEARCH_PX` for the most minutiae paired within 12 px and 45
  degrees, then trimmed least squares (Umeyama) on pairs within a shrinking radius. (Started from
  the origins alone, a print with 150 minutiae found a wrong shift with more chance pairs: 17 % located
  against 55 % from the correlation's start.) A true minutia *inside* the print (on its mask, :data:`EDGE_PX` from its border)
  is *located* when a found one lies within :data:`LOCATED_PX` (8 px at 500 ppi: ~0.4 mm, under a
  ridge period) after the fit.
* **bozorth3**: the print's score against its own true print (genuine) and against other fingers'
  (impostor), :func:`fingersplat3d.eval.fingerprint.match_score`.

Pure numpy/scipy (NIST's tools through :mod:`fingersplat3d.eval.fingerprint`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

__all__ = ["TruthScore", "fit_minutiae_similarity", "located_minutiae", "template_shift", "LOCATED_PX", "SEARCH_PX", "EDGE_PX"]

LOCATED_PX = 8.0
SEARCH_PX = 60.0
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


def template_shift(printed: np.ndarray, truth: np.ndarray) -> np.ndarray | None:
    """``(dx, dy)`` taking true-print pixels to the print's where the middle half of ``truth`` (uint8, 255 outside)
    correlates best with ``printed`` (normalised cross-correlation); None when the print is smaller than that patch."""
    import cv2

    height, width = truth.shape
    top, left = height // 4, width // 4
    patch = truth[top:top + height // 2, left:left + width // 2].astype(np.float32)
    image = np.asarray(printed, np.float32)
    if patch.shape[0] > image.shape[0] or patch.shape[1] > image.shape[1] or patch.size == 0:
        return None
    centred = lambda values: np.where(values < 255, values - 128.0, 0.0).astype(np.float32)  # noqa: E731
    scores = cv2.matchTemplate(centred(image), centred(patch), cv2.TM_CCORR_NORMED)
    row, col = np.unravel_index(int(np.argmax(scores)), scores.shape)
    return np.array([col - left, row - top], np.float64)


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
    """The :class:`TruthScore` of a print (``found_*`` from mindtct, ``mask`` its skin) against the true minutiae."""
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
