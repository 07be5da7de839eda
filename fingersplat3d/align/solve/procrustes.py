"""Similarity transforms and the confidence-weighted Procrustes fit of the paper's eq. 2.

``umeyama(src, dst, weights)`` returns the similarity ``x -> s R x + t`` minimising
``sum_i w_i || s R src_i + t - dst_i ||^2`` (Umeyama 1991, weighted), with ``R`` a proper rotation
(det +1, also for coplanar data). ``ransac_similarity`` wraps it in RANSAC over minimal 3-point
samples (vectorised: a batch of hypotheses is one batched SVD), scores hypotheses by the weighted
truncated squared residual (MSAC), and refits on the inliers until they stop changing.

Numerics: both point sets are centred on their weighted centroid and divided by their RMS radius
before the 3x3 cross-covariance is formed, so coordinates from 1e-6 to 1e6 (and any offset) give
the same relative accuracy. Degenerate data is refused with an :class:`~fingersplat3d.errors.InputError`
saying why: fewer than 3 points, NaN/Inf, negative or all-zero weights, all points coincident, or
collinear points (the rotation about their common line is undetermined; coplanar data is fine).

Pure numpy: no Open3D, no files.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import FS3DError, InputError

__all__ = ["Similarity", "umeyama", "ransac_similarity", "NoConsensusError"]

# Second singular value of the normalised cross-covariance below this fraction of the first:
# the data is collinear to double precision (exactly collinear data gives ~1e-16).
_COLLINEAR_TOLERANCE = 1e-9
# Minimal samples whose triangle is thinner than this (area / longest edge^2) are skipped.
_THIN_SAMPLE = 1e-3


class NoConsensusError(FS3DError, ValueError):
    """RANSAC found no model supported by enough inliers."""


@dataclass(frozen=True, eq=False)
class Similarity:
    """``x -> scale * rotation @ x + translation``: a rotation, a positive scale and a translation."""

    scale: float
    rotation: np.ndarray  # [3, 3] proper rotation
    translation: np.ndarray  # [3]

    def __post_init__(self) -> None:
        rotation = np.asarray(self.rotation, np.float64)
        translation = np.asarray(self.translation, np.float64).reshape(-1)
        scale = float(self.scale)
        if rotation.shape != (3, 3) or translation.shape != (3,):
            raise ValueError(f"similarity needs a 3x3 rotation and a 3-vector translation, got "
                             f"{rotation.shape} and {translation.shape}")
        if not (np.isfinite(scale) and scale > 0 and np.all(np.isfinite(rotation)) and np.all(np.isfinite(translation))):
            raise ValueError("similarity needs a finite positive scale and finite rotation/translation")
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation", translation)

    @classmethod
    def identity(cls) -> "Similarity":
        return cls(1.0, np.eye(3), np.zeros(3))

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> "Similarity":
        """From a 4x4 ``[[s R, t], [0, 1]]`` (``s`` is the cube root of the determinant)."""
        matrix = np.asarray(matrix, np.float64)
        if matrix.shape != (4, 4):
            raise ValueError(f"similarity matrix must be 4x4, got {matrix.shape}")
        determinant = np.linalg.det(matrix[:3, :3])
        if not determinant > 0:
            raise ValueError("similarity matrix must have a positive-determinant 3x3 block")
        scale = float(np.cbrt(determinant))
        return cls(scale, matrix[:3, :3] / scale, matrix[:3, 3])

    def apply(self, points: np.ndarray) -> np.ndarray:
        """``[..., 3]`` points to ``[..., 3]`` transformed points."""
        return self.scale * (np.asarray(points, np.float64) @ self.rotation.T) + self.translation

    def inverse(self) -> "Similarity":
        rotation_t = self.rotation.T
        return Similarity(1.0 / self.scale, rotation_t, -(rotation_t @ self.translation) / self.scale)

    def as_matrix(self) -> np.ndarray:
        """``[4, 4]`` homogeneous matrix ``[[s R, t], [0, 1]]``."""
        matrix = np.eye(4)
        matrix[:3, :3] = self.scale * self.rotation
        matrix[:3, 3] = self.translation
        return matrix

    def __matmul__(self, other: "Similarity") -> "Similarity":
        """``(self @ other).apply(x) == self.apply(other.apply(x))``."""
        return Similarity(self.scale * other.scale, self.rotation @ other.rotation,
                          self.scale * (self.rotation @ other.translation) + self.translation)


def _fit_batch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray, with_scale: bool):
    """Weighted Umeyama over a batch: ``src, dst [B, n, 3]``, ``weights [B, n]`` (each row sums > 0).

    Returns ``scale [B]``, ``rotation [B, 3, 3]``, ``translation [B, 3]`` and ``flatness [B]``: the
    ratio of the 2nd to the 1st singular value of the normalised cross-covariance (0 = collinear).
    Rows whose points all coincide get flatness 0 (and an identity-like, meaningless fit).
    """
    total = weights.sum(axis=1, keepdims=True)  # [B, 1]
    w = weights / total  # [B, n], sums to 1
    mean_src = np.einsum("bn,bnk->bk", w, src)  # [B, 3]
    mean_dst = np.einsum("bn,bnk->bk", w, dst)
    centred_src = src - mean_src[:, None]
    centred_dst = dst - mean_dst[:, None]
    radius_src = np.sqrt(np.einsum("bn,bnk,bnk->b", w, centred_src, centred_src))  # RMS radius [B]
    radius_dst = np.sqrt(np.einsum("bn,bnk,bnk->b", w, centred_dst, centred_dst))
    spread = (radius_src > 0) & (radius_dst > 0)
    safe_src = np.where(spread, radius_src, 1.0)
    safe_dst = np.where(spread, radius_dst, 1.0)
    unit_src = centred_src / safe_src[:, None, None]
    unit_dst = centred_dst / safe_dst[:, None, None]
    covariance = np.einsum("bn,bni,bnj->bij", w, unit_dst, unit_src)  # [B, 3, 3] = sum w y x^T
    u, singular, vt = np.linalg.svd(covariance)
    sign = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    sign = np.where(sign == 0, 1.0, sign)
    correction = np.ones((len(src), 3))
    correction[:, 2] = sign
    rotation = np.einsum("bij,bj,bjk->bik", u, correction, vt)
    if with_scale:
        # Normalised source has unit variance, so s' = trace(S D); undo the normalisation.
        scale = (singular * correction).sum(axis=1) * safe_dst / safe_src
    else:
        scale = np.ones(len(src))
    translation = mean_dst - scale[:, None] * np.einsum("bij,bj->bi", rotation, mean_src)
    with np.errstate(invalid="ignore", divide="ignore"):
        flatness = np.where(spread & (singular[:, 0] > 0), singular[:, 1] / singular[:, 0], 0.0)
    return scale, rotation, translation, flatness


def _validate(src, dst, weights, minimum: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    src = np.asarray(src, np.float64)
    dst = np.asarray(dst, np.float64)
    if src.ndim != 2 or src.shape[1] != 3 or dst.shape != src.shape:
        raise InputError(f"Procrustes needs two [N, 3] point arrays of the same shape, got {src.shape} and {dst.shape}")
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise InputError("Procrustes input points contain NaN or Inf")
    if weights is None:
        weights = np.ones(len(src))
    weights = np.asarray(weights, np.float64)
    if weights.shape != (len(src),):
        raise InputError(f"Procrustes weights must have shape ({len(src)},), got {weights.shape}")
    if not np.all(np.isfinite(weights)) or np.any(weights < 0):
        raise InputError("Procrustes weights must be finite and non-negative")
    count = int(np.count_nonzero(weights))
    if count == 0:
        raise InputError("Procrustes weights are all zero: there is nothing to align")
    if count < minimum:
        raise InputError(f"a 3D similarity needs at least {minimum} points with positive weight, got {count}")
    return src, dst, weights


def umeyama(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None,
            with_scale: bool = True) -> Similarity:
    """The similarity (rigid if ``with_scale=False``) best taking ``src [N, 3]`` onto ``dst [N, 3]``.

    Minimises ``sum_i w_i || s R src_i + t - dst_i ||^2`` over ``s > 0``, ``R`` in SO(3), ``t``;
    ``weights [N] >= 0`` default to 1. Raises :class:`InputError` for degenerate input (see module).
    """
    src, dst, weights = _validate(src, dst, weights)
    scale, rotation, translation, flatness = _fit_batch(src[None], dst[None], weights[None], with_scale)
    if flatness[0] <= _COLLINEAR_TOLERANCE:
        if flatness[0] == 0 and (np.ptp(src[weights > 0], axis=0).max() == 0 or np.ptp(dst[weights > 0], axis=0).max() == 0):
            raise InputError("Procrustes points all coincide: rotation and scale are undetermined")
        raise InputError("Procrustes points are collinear: the rotation about their common line is undetermined")
    if not scale[0] > 0:
        raise InputError("Procrustes fit has a non-positive scale: the two point sets do not correspond")
    return Similarity(float(scale[0]), rotation[0], translation[0])


def _thin(points: np.ndarray) -> np.ndarray:
    """``[B, 3, 3]`` triangles -> ``[B]`` bool: (near-)degenerate (area / longest edge^2 tiny)."""
    edge1 = points[:, 1] - points[:, 0]
    edge2 = points[:, 2] - points[:, 0]
    edge3 = points[:, 2] - points[:, 1]
    area2 = np.linalg.norm(np.cross(edge1, edge2), axis=1)
    longest = np.max(np.stack([(e * e).sum(1) for e in (edge1, edge2, edge3)]), axis=0)
    return ~(area2 > _THIN_SAMPLE * longest)


def ransac_similarity(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None, *,
                      threshold: float, iterations: int = 1000, confidence: float = 0.999,
                      with_scale: bool = True, rng: np.random.Generator | int | None = None,
                      min_inliers: int = 3, batch: int = 128) -> tuple[Similarity, np.ndarray]:
    """Robust :func:`umeyama`: ``(similarity, inliers [N] bool)``.

    ``threshold`` is the inlier distance ``|| s R src + t - dst ||`` in ``dst`` units. Hypotheses
    come from uniform 3-point samples of the positive-weight points (thin triangles skipped), at
    most ``iterations`` of them, fewer when the best inlier ratio so far makes ``confidence``
    certain (adaptive stopping). The best is scored by the weighted truncated squared residual,
    then refit by weighted Umeyama on its inliers (repeated until the inlier set is stable).
    ``rng`` is a Generator or a seed; ``None`` means seed 0, so results are reproducible.
    Raises :class:`InputError` for bad input and :class:`NoConsensusError` when the best model
    has fewer than ``max(3, min_inliers)`` inliers.
    """
    src, dst, weights = _validate(src, dst, weights)
    if not (np.isfinite(threshold) and threshold > 0):
        raise InputError(f"RANSAC threshold must be a positive distance, got {threshold}")
    if iterations < 1:
        raise InputError(f"RANSAC needs at least one iteration, got {iterations}")
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(0 if rng is None else rng)
    min_inliers = max(3, int(min_inliers))
    candidates = np.flatnonzero(weights > 0)
    threshold_sq = float(threshold) ** 2

    best_cost, best_model, needed, done = np.inf, None, iterations, 0
    while done < min(iterations, needed):
        count = min(batch, iterations - done)
        done += count
        # Three distinct indices per sample: draw without replacement per row via argsort of noise.
        picks = candidates[np.argsort(rng.random((count, len(candidates))), axis=1)[:, :3]] \
            if len(candidates) <= 64 else _three_distinct(rng, candidates, count)
        sample_src, sample_dst = src[picks], dst[picks]  # [B, 3, 3]
        usable = ~(_thin(sample_src) | _thin(sample_dst))
        if not usable.any():
            continue
        scale, rotation, translation, flatness = _fit_batch(sample_src[usable], sample_dst[usable],
                                                            weights[picks[usable]], with_scale)
        good = (flatness > _COLLINEAR_TOLERANCE) & (scale > 0) & np.isfinite(scale)
        if not good.any():
            continue
        scale, rotation, translation = scale[good], rotation[good], translation[good]
        moved = scale[:, None, None] * np.einsum("bij,nj->bni", rotation, src) + translation[:, None]
        residual_sq = ((moved - dst) ** 2).sum(-1)  # [B, N]
        cost = (np.minimum(residual_sq, threshold_sq) * weights).sum(1)
        index = int(np.argmin(cost))
        if cost[index] < best_cost:
            best_cost = cost[index]
            best_model = (scale[index], rotation[index], translation[index])
            ratio = np.count_nonzero(residual_sq[index] <= threshold_sq) / len(candidates)
            needed = _needed_iterations(ratio, confidence, iterations)
    if best_model is None:
        raise NoConsensusError("RANSAC found no non-degenerate 3-point sample: the points are (nearly) collinear")

    model = Similarity(*best_model)
    inliers, cost = _score(model, src, dst, weights, threshold_sq)
    for _ in range(10):  # refit on the inliers while that lowers the robust cost
        if np.count_nonzero(inliers) < 3:
            break
        try:
            refit = umeyama(src[inliers], dst[inliers], weights[inliers], with_scale=with_scale)
        except InputError:
            break
        refit_inliers, refit_cost = _score(refit, src, dst, weights, threshold_sq)
        if refit_cost > cost:
            break
        changed = not np.array_equal(refit_inliers, inliers)
        model, inliers, cost = refit, refit_inliers, refit_cost
        if not changed:
            break
    found = int(np.count_nonzero(inliers))
    if found < min_inliers:
        raise NoConsensusError(f"RANSAC found {found} inliers within {threshold:g}, fewer than the {min_inliers} required")
    return model, inliers


def _three_distinct(rng: np.random.Generator, candidates: np.ndarray, count: int) -> np.ndarray:
    """``[count, 3]`` rows of three distinct entries of ``candidates`` (rejection of the rare repeats)."""
    n = len(candidates)
    picks = rng.integers(0, n, size=(count, 3))
    while True:
        bad = (picks[:, 0] == picks[:, 1]) | (picks[:, 0] == picks[:, 2]) | (picks[:, 1] == picks[:, 2])
        if not bad.any():
            return candidates[picks]
        picks[bad] = rng.integers(0, n, size=(int(bad.sum()), 3))


def _score(model: Similarity, src, dst, weights, threshold_sq: float) -> tuple[np.ndarray, float]:
    """Inliers ``[N]`` and the weighted truncated squared residual (MSAC cost) of one model."""
    residual_sq = ((model.apply(src) - dst) ** 2).sum(-1)
    cost = float((np.minimum(residual_sq, threshold_sq) * weights).sum())
    return (residual_sq <= threshold_sq) & (weights > 0), cost


def _needed_iterations(inlier_ratio: float, confidence: float, cap: int) -> int:
    """Samples needed to draw one all-inlier triple with probability ``confidence``."""
    good = inlier_ratio ** 3
    if good >= 1.0:
        return 1
    if good <= 0.0:
        return cap
    return int(min(cap, np.ceil(np.log(1.0 - confidence) / np.log(1.0 - good))))
