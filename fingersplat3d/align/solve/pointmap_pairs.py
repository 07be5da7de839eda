"""Pairwise relations from learned pairwise pointmaps (DUSt3R), for the global alignment.

A pairwise backend gives, for the pair ``(a, b)``, ``X^{a,a}`` and ``X^{b,a}`` (both views' points
in a's camera frame, in the pair's own scale) and, symmetrised, ``X^{b,b}`` and ``X^{a,b}``. The
global alignment works on each view's own-frame pointmap ``P_v`` (the backend's
``predict_views``) and needs, per pair, a similarity ``b_to_a`` between those own frames and
pixel correspondences. Both come from the pair's points:

1. frame of pair ``(a, b)`` -> own frame of a: the similarity ``S_a`` taking ``X^{a,a}`` onto
   ``P_a`` pixel by pixel (weighted Umeyama: same camera, so mostly a scale);
   ``Y_b = S_a(X^{b,a})`` are b's pixels in a's own frame. Likewise ``S_b`` and
   ``Y_a = S_b(X^{a,b})``, a's pixels in b's own frame.
2. ``b_to_a``: one weighted Umeyama over both directions' pixels,
   ``P_b(p) -> Y_b(p)`` and ``Y_a(q) -> P_a(q)``, refit once without residuals above
   ``trim`` times their weighted median.
3. correspondences: ``Y_b(p)`` projected with a's focal (principal point at the centre) gives the
   pixel of a that sees b's pixel ``p``; ``Y_a(q)`` projected into b likewise. A projection is kept
   when it lands inside the other image (and its mask, when given), in front of the camera, among
   the step-2 inliers, and not hidden: its depth agrees with the other view's own depth there
   within ``occlusion_tolerance`` (a fraction of the median depth). At most
   ``max_correspondences`` per direction are kept (uniform random subset).
4. the pair fails when too few correspondences remain or the step-2 residual is above ``max_residual``.

Weights are ``t(c_pair) * t(c_own)``, with ``t = log`` for DUSt3R's confidences (>= 1; upstream's
``conf_trf='log'``) or the identity. A pair that cannot be registered is not an error: the result
has ``ok=False`` and a ``reason``.

Pure numpy: no Open3D, no files.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...pointmaps.base import PairPointmaps, Pointmap
from .global_opt import PairCorrespondences, weighted_median
from .procrustes import Similarity, umeyama

__all__ = ["PointmapPairConfig", "PointmapPairRegistration", "register_pointmap_pair", "frame_similarity"]

_FRAME_SAMPLES = 20_000  # pixels used to fit S_a, S_b (plenty for 7 parameters)


@dataclass(frozen=True)
class PointmapPairConfig:
    """Settings of :func:`register_pointmap_pair`."""

    max_correspondences: int = 1500
    """Correspondences kept per direction (a->b and b->a), a uniform random subset."""
    log_confidence: bool = True
    """Weight by ``log(confidence)`` (DUSt3R confidences are >= 1), else by the confidence itself."""
    trim: float = 3.0
    """Residuals above ``trim`` x their weighted median are outliers of the ``b_to_a`` fit."""
    occlusion_tolerance: float = 0.02
    """A projected point is hidden when its depth exceeds the other view's own depth at that pixel by
    more than this fraction of the median depth."""
    min_correspondences: int = 8
    """Fewer kept correspondences make the pair fail."""
    max_residual: float = 0.25
    """A relative residual (see :attr:`PointmapPairRegistration.residual`) above this makes the pair
    fail: the pair's points and the own-frame pointmaps do not describe one rigid scene (exact
    pointmaps give ~1e-7, unrelated ones ~1). A guard, not a tuned value."""


@dataclass(frozen=True, eq=False)
class PointmapPairRegistration:
    """The relation of views a and b from their pairwise pointmaps."""

    a: int
    b: int
    b_to_a: Similarity
    """Takes b's own-frame points into a's own frame (identity when not ``ok``)."""
    correspondences: PairCorrespondences | None
    """What the global alignment uses (None when not ``ok``)."""
    residual: float
    """Weighted RMS 3D distance of the inliers after ``b_to_a``, over the RMS radius of their
    points in a's frame (unit-free; NaN when not ``ok``)."""
    n_correspondences: int
    ok: bool
    reason: str = ""


def _weights(pair_confidence: np.ndarray, own_confidence: np.ndarray, log: bool) -> np.ndarray:
    if log:
        pair_confidence = np.log(np.maximum(pair_confidence, 1.0))
        own_confidence = np.log(np.maximum(own_confidence, 1.0))
    return np.where(np.isfinite(pair_confidence * own_confidence), pair_confidence * own_confidence, 0.0)


def _subset(index: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    return index if len(index) <= count else np.sort(rng.choice(index, size=count, replace=False))


def frame_similarity(pair_points: np.ndarray, pair_confidence: np.ndarray, own: Pointmap, *, log_confidence: bool = True,
                     mask: np.ndarray | None = None, rng: np.random.Generator | None = None) -> Similarity:
    """``S``: the similarity taking a pair's ``X^{v,v} [H, W, 3]`` onto the own-frame pointmap ``own`` of v.

    Raises :class:`InputError` when the two share too few valid pixels or are degenerate.
    """
    if pair_points.shape != own.points.shape:
        raise InputError(f"view {own.view}: pair pointmap is {pair_points.shape[:2]}, own pointmap "
                         f"{own.points.shape[:2]}")
    rng = rng if rng is not None else np.random.default_rng(0)
    weight = _weights(pair_confidence, own.confidence, log_confidence)
    valid = own.valid & np.isfinite(pair_points).all(-1) & (weight > 0)
    if mask is not None and (valid & mask).sum() >= 100:
        valid &= mask
    index = _subset(np.flatnonzero(valid), _FRAME_SAMPLES, rng)
    src = pair_points.reshape(-1, 3)[index]
    dst = own.points.reshape(-1, 3)[index]
    return umeyama(src, dst, weight.reshape(-1)[index])


def _project(points: np.ndarray, focal: float, size: tuple[int, int]) -> np.ndarray:
    """Camera-frame ``[N, 3]`` -> pixels ``[N, 2]`` (principal point at the image centre)."""
    width, height = size
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([focal * points[:, 0] / points[:, 2] + (width - 1) / 2.0,
                         focal * points[:, 1] / points[:, 2] + (height - 1) / 2.0], axis=1)


def _visible(points: np.ndarray, uv: np.ndarray, target: Pointmap, mask: np.ndarray | None, tolerance: float) -> np.ndarray:
    """Projections inside the target image (and mask), in front, and not behind the target's own surface."""
    height, width = target.depth.shape
    finite = np.isfinite(uv).all(1) & (points[:, 2] > 0)
    u = np.where(finite, np.round(uv[:, 0]), -1).astype(np.int64)
    v = np.where(finite, np.round(uv[:, 1]), -1).astype(np.int64)
    inside = finite & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    keep = np.zeros(len(points), bool)
    i = np.flatnonzero(inside)
    own_depth = target.depth[v[i], u[i]]
    valid_target = target.valid[v[i], u[i]] & (mask[v[i], u[i]] if mask is not None else True)
    median = float(np.nanmedian(target.depth[target.valid])) if target.valid.any() else np.nan
    keep[i] = valid_target & (points[i, 2] <= own_depth + tolerance * abs(median))
    return keep


def register_pointmap_pair(pointmap_a: Pointmap, pointmap_b: Pointmap, pair_ab: PairPointmaps,
                           pair_ba: PairPointmaps | None = None, *, mask_a: np.ndarray | None = None,
                           mask_b: np.ndarray | None = None, rng: np.random.Generator | int | None = None,
                           config: PointmapPairConfig = PointmapPairConfig()) -> PointmapPairRegistration:
    """Relative similarity and correspondences of views a and b (see the module docstring).

    ``pointmap_a``, ``pointmap_b``: own-frame pointmaps (what the global alignment aligns);
    ``pair_ab``: the pair ``(a, b)``; ``pair_ba``: the reverse pair (optional: one direction only
    without it). Masks restrict the correspondences to the finger.
    """
    a, b = pointmap_a.view, pointmap_b.view
    if (pair_ab.i, pair_ab.j) != (a, b) or (pair_ba is not None and (pair_ba.i, pair_ba.j) != (b, a)):
        raise InputError(f"pair pointmaps ({pair_ab.i}, {pair_ab.j}) do not belong to views ({a}, {b})")
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(0 if rng is None else rng)

    def failed(reason: str) -> PointmapPairRegistration:
        return PointmapPairRegistration(a, b, Similarity.identity(), None, float("nan"), 0, False, reason)

    # (own-frame pointmap, the other view's, the pair seen from own, own mask, other mask, own is a?)
    directions = [(pointmap_a, pointmap_b, pair_ab, mask_a, mask_b, True)]
    if pair_ba is not None:
        directions.append((pointmap_b, pointmap_a, pair_ba, mask_b, mask_a, False))
    src, dst, weight, pixels_other, projected = [], [], [], [], []
    for own, other, pair, own_mask, other_mask, forward in directions:
        try:
            to_own = frame_similarity(pair.points_i, pair.confidence_i, own, log_confidence=config.log_confidence,
                                      mask=own_mask, rng=rng)
        except InputError as error:
            return failed(f"pair ({pair.i}, {pair.j}): view {own.view}'s two pointmaps do not align: {error}")
        w = _weights(pair.confidence_j, other.confidence, config.log_confidence)
        valid = other.valid & np.isfinite(pair.points_j).all(-1) & (w > 0)
        if other_mask is not None:
            valid &= other_mask
        index = _subset(np.flatnonzero(valid), 4 * config.max_correspondences, rng)
        in_own = to_own.apply(pair.points_j.reshape(-1, 3)[index])  # other's pixels, in own's frame
        other_points = np.asarray(other.points, np.float64).reshape(-1, 3)[index]
        rows, cols = np.divmod(index, other.depth.shape[1])
        # b_to_a maps b's frame to a's: forward (own = a): P_b -> Y_b; reverse (own = b): Y_a -> P_a.
        src.append(other_points if forward else in_own)
        dst.append(in_own if forward else other_points)
        weight.append(w.reshape(-1)[index])
        pixels_other.append(np.stack([cols, rows], axis=1).astype(np.float64))
        projected.append((in_own, own, own_mask, forward))
    src_all, dst_all, w_all = np.concatenate(src), np.concatenate(dst), np.concatenate(weight)
    if np.count_nonzero(w_all) < config.min_correspondences:
        return failed(f"only {np.count_nonzero(w_all)} pixels have a point in both pointmaps")
    try:
        model = umeyama(src_all, dst_all, w_all)
        residual = np.linalg.norm(model.apply(src_all) - dst_all, axis=1)
        inlier = residual <= config.trim * max(weighted_median(residual, w_all), 1e-300)
        model = umeyama(src_all[inlier], dst_all[inlier], w_all[inlier])
    except InputError as error:
        return failed(f"degenerate pointmaps: {error}")
    residual = np.linalg.norm(model.apply(src_all) - dst_all, axis=1)
    inlier = residual <= config.trim * max(weighted_median(residual, w_all), 1e-300)
    uv_a, uv_b, kept_weight = [], [], []
    start = 0
    for (in_own, own, own_mask, forward), pixels, w in zip(projected, pixels_other, weight):
        stop = start + len(w)
        uv_own = _project(in_own, own.focal, own.depth.shape[::-1])
        keep = inlier[start:stop] & _visible(in_own, uv_own, own, own_mask, config.occlusion_tolerance)
        chosen = _subset(np.flatnonzero(keep), config.max_correspondences, rng)
        if forward:  # own is a: the other pixels are b's
            uv_a.append(uv_own[chosen])
            uv_b.append(pixels[chosen])
        else:
            uv_a.append(pixels[chosen])
            uv_b.append(uv_own[chosen])
        kept_weight.append(w[chosen])
        start = stop
    uv_a, uv_b, kept_weight = np.concatenate(uv_a), np.concatenate(uv_b), np.concatenate(kept_weight)
    if len(kept_weight) < config.min_correspondences:
        return failed(f"only {len(kept_weight)} pixels project visibly into the other view (at least "
                      f"{config.min_correspondences} are needed)")
    centre = np.average(dst_all[inlier], axis=0, weights=w_all[inlier])
    radius = float(np.sqrt(np.average(((dst_all[inlier] - centre) ** 2).sum(1), weights=w_all[inlier])))
    rms = float(np.sqrt(np.average(residual[inlier] ** 2, weights=w_all[inlier])))
    relative_residual = rms / max(radius, 1e-300)
    if not relative_residual <= config.max_residual:
        return failed(f"the pointmaps disagree: relative residual {relative_residual:.2f} after alignment "
                      f"(at most {config.max_residual:g} accepted)")
    correspondences = PairCorrespondences(a, b, uv_a, uv_b, kept_weight, model.as_matrix())
    return PointmapPairRegistration(a, b, model, correspondences, relative_residual, len(kept_weight), True)

