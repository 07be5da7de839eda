"""Pairwise registration: the similarity taking view b's own-frame pointmap into view a's frame.

The paper's pose initialisation (eq. 2) aligns two pointmaps by confidence-weighted Procrustes.
Own-frame pointmaps (``X^{a,a}``, ``X^{b,b}``) share no pixels, so the pairing of their points
comes from image correspondences (:func:`fingersplat3d.align.features.match_views`):

1. look both pointmaps up at the matched pixels (bilinear where the 4 neighbours are valid,
   nearest valid pixel otherwise, dropped when neither), with confidences likewise;
2. weight each pair by ``conf_a * conf_b * score``;
3. RANSAC over 3-point samples (:func:`~fingersplat3d.align.procrustes.ransac_similarity`) with an
   inlier distance relative to the size of the matched point set (pointmaps are in arbitrary
   units; a tight distance first, a looser one when the tight one keeps less than half of the
   matches), then a weighted Umeyama refit on the inliers.

A merely bad pair (too few matches, too few inliers, degenerate geometry) is not an error: the
result has ``ok=False`` and a ``reason``, and the caller decides. Bad *input* (wrong types or
shapes) raises :class:`~fingersplat3d.errors.InputError`.

Pure numpy: no Open3D, no files.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ...errors import InputError
from ...pointmaps.base import Pointmap
from ..correspond.features import Matches
from .procrustes import NoConsensusError, Similarity, ransac_similarity, umeyama

__all__ = ["PairRegistration", "register_pair", "sample_pointmap", "DEFAULT_THRESHOLDS"]

DEFAULT_THRESHOLDS = (0.02, 0.05)
"""RANSAC inlier distances to try, as fractions of the RMS radius of the matched points of view a:
the first that keeps at least half of the matches (and ``min_inliers``) wins. Tight first, since an
exact pointmap then rejects every wrong match; looser next, since a pointmap with a smooth shape
error (a wrong cross-section) spreads the residuals of right matches too."""


@dataclass(frozen=True, eq=False)
class PairRegistration:
    """The relative similarity of two views and the correspondences that support it."""

    a: int
    """Index of view a (``pointmap_a.view``)."""
    b: int
    """Index of view b (``pointmap_b.view``)."""
    b_to_a: Similarity
    """Takes view b's own-frame points into view a's camera frame (identity when not ``ok``)."""
    uv_a: np.ndarray  # [M, 2] inlier pixels in view a
    uv_b: np.ndarray  # [M, 2] inlier pixels in view b
    weight: np.ndarray  # [M] conf_a * conf_b * score of each inlier
    residual: float
    """Weighted RMS 3D distance of the inliers after alignment, divided by the RMS radius of the
    inlier points of a (so it is unit-free; NaN when not ``ok``)."""
    n_inliers: int
    n_matches: int
    """Correspondences with a valid 3D point in both pointmaps (the RANSAC input)."""
    ok: bool
    reason: str = ""
    """Why the pair failed (empty when ``ok``)."""

    @property
    def matrix(self) -> np.ndarray:
        """``[4, 4]`` ``b_to_a`` as a homogeneous matrix."""
        return self.b_to_a.as_matrix()


def sample_pointmap(pointmap: Pointmap, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points ``[N, 3]`` and confidences ``[N]`` of ``pointmap`` at pixels ``uv [N, 2]``.

    Bilinear where the four surrounding pixels are all valid, the nearest pixel where it alone is
    valid, NaN points and 0 confidence otherwise (also outside the image).
    """
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    points = np.asarray(pointmap.points, np.float64)
    confidence = np.asarray(pointmap.confidence, np.float64)
    valid = pointmap.valid
    height, width = valid.shape
    out_points = np.full((len(uv), 3), np.nan)
    out_conf = np.zeros(len(uv))
    finite = np.all(np.isfinite(uv), axis=1)
    u, v = np.where(finite, uv[:, 0], -1.0), np.where(finite, uv[:, 1], -1.0)
    inside = finite & (u >= -0.5) & (u <= width - 0.5) & (v >= -0.5) & (v <= height - 0.5)
    # Bilinear: the 4 neighbours must exist and be valid.
    u0 = np.clip(np.floor(u).astype(int), 0, max(width - 2, 0))
    v0 = np.clip(np.floor(v).astype(int), 0, max(height - 2, 0))
    fu, fv = np.clip(u - u0, 0, 1)[:, None], np.clip(v - v0, 0, 1)[:, None]
    u1, v1 = np.minimum(u0 + 1, width - 1), np.minimum(v0 + 1, height - 1)
    four = inside & valid[v0, u0] & valid[v0, u1] & valid[v1, u0] & valid[v1, u1]
    if four.any():
        i = np.flatnonzero(four)
        a, b, c, d = (w[i] for w in ((1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv))
        out_points[i] = (a * points[v0[i], u0[i]] + b * points[v0[i], u1[i]]
                         + c * points[v1[i], u0[i]] + d * points[v1[i], u1[i]])
        out_conf[i] = (a[:, 0] * confidence[v0[i], u0[i]] + b[:, 0] * confidence[v0[i], u1[i]]
                       + c[:, 0] * confidence[v1[i], u0[i]] + d[:, 0] * confidence[v1[i], u1[i]])
    nearest = inside & ~four
    if nearest.any():
        i = np.flatnonzero(nearest)
        un = np.clip(np.round(u[i]).astype(int), 0, width - 1)
        vn = np.clip(np.round(v[i]).astype(int), 0, height - 1)
        good = valid[vn, un]
        out_points[i[good]] = points[vn[good], un[good]]
        out_conf[i[good]] = confidence[vn[good], un[good]]
    return out_points, out_conf


def _failed(pointmap_a: Pointmap, pointmap_b: Pointmap, n_matches: int, reason: str) -> PairRegistration:
    empty = np.zeros((0, 2))
    return PairRegistration(pointmap_a.view, pointmap_b.view, Similarity.identity(), empty, empty.copy(),
                            np.zeros(0), float("nan"), 0, n_matches, False, reason)


def register_pair(pointmap_a: Pointmap, pointmap_b: Pointmap, matches: Matches, *,
                  rng: np.random.Generator | int | None = None,
                  thresholds: Sequence[float] = DEFAULT_THRESHOLDS, min_inliers: int = 8,
                  iterations: int = 2000) -> PairRegistration:
    """Similarity ``b_to_a`` from matched pixels of two own-frame pointmaps (see the module).

    ``matches.uv_a`` are pixels of ``pointmap_a``'s view, ``matches.uv_b`` of ``pointmap_b``'s.
    ``thresholds``: RANSAC inlier distances relative to the RMS radius of the matched points of a,
    tried in order (see :data:`DEFAULT_THRESHOLDS`).
    ``min_inliers``: fewer inliers than this make the pair ``ok=False``. ``rng``: a Generator or a
    seed (None: seed 0, reproducible).
    """
    if not isinstance(pointmap_a, Pointmap) or not isinstance(pointmap_b, Pointmap):
        raise InputError("register_pair needs two Pointmap objects")
    if not isinstance(matches, Matches):
        raise InputError("register_pair needs a Matches object (from match_views)")
    thresholds = [float(value) for value in np.atleast_1d(np.asarray(thresholds, np.float64))]
    if not thresholds or not all(np.isfinite(value) and value > 0 for value in thresholds):
        raise InputError(f"registration thresholds must be positive fractions, got {thresholds}")
    points_a, conf_a = sample_pointmap(pointmap_a, matches.uv_a)
    points_b, conf_b = sample_pointmap(pointmap_b, matches.uv_b)
    score = np.where(np.isfinite(matches.score), np.clip(matches.score, 0.0, None), 0.0)
    weight = conf_a * conf_b * score
    usable = np.isfinite(points_a).all(1) & np.isfinite(points_b).all(1) & (weight > 0)
    n_matches = int(usable.sum())
    needed = max(3, int(min_inliers))
    if n_matches < needed:
        return _failed(pointmap_a, pointmap_b, n_matches,
                       f"only {n_matches} matches have a 3D point in both pointmaps (of {len(matches)}); "
                       f"at least {needed} are needed")
    src, dst, w = points_b[usable], points_a[usable], weight[usable]
    centre = np.average(dst, axis=0, weights=w)
    radius = float(np.sqrt(np.average(((dst - centre) ** 2).sum(1), weights=w)))
    if not radius > 0:
        return _failed(pointmap_a, pointmap_b, n_matches, "the matched points of view a all coincide")
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(0 if rng is None else rng)
    best, failure = None, ""
    for threshold in thresholds:
        try:
            model, inliers = ransac_similarity(src, dst, w, threshold=threshold * radius, iterations=iterations,
                                               rng=rng, min_inliers=needed)
            model = umeyama(src[inliers], dst[inliers], w[inliers])
        except NoConsensusError as error:
            failure = f"no consistent similarity: {error}"
            continue
        except InputError as error:  # degenerate inlier geometry (collinear...)
            failure = f"degenerate correspondences: {error}"
            continue
        best = (model, inliers)
        if inliers.sum() >= 0.5 * n_matches:
            break
    if best is None:
        return _failed(pointmap_a, pointmap_b, n_matches, failure)
    model, inliers = best
    inlier_dst, inlier_w = dst[inliers], w[inliers]
    inlier_centre = np.average(inlier_dst, axis=0, weights=inlier_w)
    inlier_radius = float(np.sqrt(np.average(((inlier_dst - inlier_centre) ** 2).sum(1), weights=inlier_w)))
    distance_sq = ((model.apply(src[inliers]) - inlier_dst) ** 2).sum(1)
    residual = float(np.sqrt(np.average(distance_sq, weights=inlier_w)) / max(inlier_radius, 1e-300))
    index = np.flatnonzero(usable)[inliers]
    return PairRegistration(pointmap_a.view, pointmap_b.view, model, matches.uv_a[index].copy(),
                            matches.uv_b[index].copy(), weight[index].copy(), residual,
                            int(inliers.sum()), n_matches, True, "")
