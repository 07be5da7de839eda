"""Image correspondences between two photos of one finger taken from different angles.

``match_views(image_a, mask_a, image_b, mask_b, method=...)`` returns :class:`Matches`: pixel pairs
``uv_a <-> uv_b`` (OpenCV convention, pixel centres at integers) that passed a ratio test, a
mutual-nearest-neighbour check and epipolar verification (``cv2.findFundamentalMat`` with
USAC_MAGSAC), so a pair without overlap (90 degrees apart) returns few or no matches, not garbage.
No camera parameters are needed.

Methods (measured against synthetic ground truth on an earlier generator; the benchmark script is in git history):

These are the classic matchers, kept as ``--matcher`` options; the default first guess of
``fs3d fuse`` is the ``surface`` registration of :mod:`fingersplat3d.align.register`, since on
real photos (faint ridges, 45 degrees apart) ``minutiae`` finds no match and SIFT verifies at
chance level. Their figures below are from the generator's earlier, crisp-ridged images.

* ``minutiae``: keypoints are ridge endings and bifurcations (band-pass at the measured
  ridge period, binarise, thin, crossing number), described by RootSIFT over ~3 ridge periods,
  matched (ratio 0.95 + mutual), verified (MAGSAC fundamental matrix), then every match is refined
  to sub-pixel by aligning a 4-period patch of the band-passed texture with an affine ECC warp and
  kept only if that patch correlates >= ``min_correlation`` and a 6-period patch under the same
  warp >= ``MIN_WIDE_CORRELATION`` (ridges repeat, minutiae configurations do not, so this is
  what rejects a match one ridge off along its epipolar line); a guided round then ECC-refines
  every other minutia of a from the position its verified neighbours predict, and a
  leave-one-out local-affine consistency test drops the last outliers. The ECC correlation is the
  match ``score``. ``densify=True`` adds grid points grown the same way (3-4x the matches, median
  error 0.9-1.4 px instead of 0.7: plain texture is ambiguous along the ridges).

  Why it was the default before (numbers from the bench, uwa 640x512, seeds 0-2): the ridge texture is
  periodic, so generic detectors are not repeatable across 45 degrees of foreshortening (SIFT
  keypoints coincide within 2 px about as often as random points would) and their verified
  matches are mostly wrong along the epipolar lines: sift 25-48 % within 2 px, median 2.1 px
  (left-center) and 56 px (center-right); akaze 5-53 %; and all three return 13-18 wrong matches
  on the 90-degree pair, which no threshold on their count separates from a real pair. minutiae
  gives 16-29 matches per 45-degree pair, 76-91 % within 2 px, median 0.7 px, and returns
  nothing on every 90-degree pair; at 0.2 s per pair. Its weakness is recall: about 1 in 7
  45-degree pairs yields fewer than ``min_matches`` and comes back empty (3 of 20 over seeds 0-9).
* ``sift``: OpenCV SIFT on a CLAHE-equalised image (the textbook baseline).
* ``rootsift``: the same keypoints with RootSIFT descriptors (Hellinger kernel).
* ``akaze``: AKAZE (binary MLDB descriptors, Hamming distance).

Detection runs at a reduced scale where the ridge period is about ``TARGET_PERIOD_PX`` pixels
(1280x1024 uwa: 0.45 s per pair instead of 1.2 s at full resolution, same match count, median
error 1.3-1.5 px instead of 1.1-1.3 px, i.e. ~0.08 ridge periods either way); coordinates are
always returned in the input's pixels and the ``minutiae`` refinement runs at full resolution.

Pure numpy/OpenCV: no Open3D, no files.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np

from ...errors import InputError
from ...segment.morphology import eroded
from .epipolar import fundamental_inliers, sampson_distance
from .texture import as_gray, estimate_ridge_period, ridge_texture

__all__ = ["Matches", "match_views", "METHODS", "DEFAULT_METHOD"]

METHODS = ("minutiae", "sift", "rootsift", "akaze")
DEFAULT_METHOD = "minutiae"
TARGET_PERIOD_PX = 8.0
"""Ridge period (pixels) the images are resized down to before detection."""
ECC_HALF_PERIODS = 2.0
"""Half-size of the ECC refinement patch, in ridge periods."""
VERIFY_HALF_PERIODS = 3.0
"""Half-size of the wider verification patch, in ridge periods."""
MIN_WIDE_CORRELATION = 0.7
"""Correlation the wider patch must reach under the refined affine map (ridges repeat, minutiae do not)."""


@dataclass(frozen=True, eq=False)
class Matches:
    """Verified correspondences between view a and view b."""

    uv_a: np.ndarray  # [N, 2] float64 pixels in image a
    uv_b: np.ndarray  # [N, 2] float64 pixels in image b
    score: np.ndarray  # [N] float64 in (0, 1]: confidence of each match
    method: str
    n_putative: int = 0
    """Matches that passed the ratio and mutual checks, before geometric verification."""
    seconds: float = 0.0
    """Wall time of the call."""

    def __post_init__(self) -> None:
        uv_a = np.asarray(self.uv_a, np.float64).reshape(-1, 2)
        uv_b = np.asarray(self.uv_b, np.float64).reshape(-1, 2)
        score = np.asarray(self.score, np.float64).reshape(-1)
        if not (len(uv_a) == len(uv_b) == len(score)):
            raise ValueError(f"matches need equal counts, got {len(uv_a)}, {len(uv_b)} and {len(score)}")
        object.__setattr__(self, "uv_a", uv_a)
        object.__setattr__(self, "uv_b", uv_b)
        object.__setattr__(self, "score", score)

    def __len__(self) -> int:
        return len(self.uv_a)

    @classmethod
    def empty(cls, method: str, n_putative: int = 0, seconds: float = 0.0) -> "Matches":
        return cls(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), method, n_putative, seconds)

    def swapped(self) -> "Matches":
        """The same matches seen from view b (a and b exchanged)."""
        return Matches(self.uv_b, self.uv_a, self.score, self.method, self.n_putative, self.seconds)


# ------------------------------------------------------------------------------------------------
# Preprocessing
# ------------------------------------------------------------------------------------------------

def _validate(image, mask, name: str) -> tuple[np.ndarray, np.ndarray]:
    gray = as_gray(image, f"image {name}")
    if mask is None:
        mask = np.ones(gray.shape, bool)
    mask = np.asarray(mask)
    if mask.shape != gray.shape:
        raise InputError(f"mask {name} is {mask.shape[1]}x{mask.shape[0]}, image {name} is {gray.shape[1]}x{gray.shape[0]}")
    mask = mask.astype(bool)
    if not mask.any():
        raise InputError(f"mask {name} is empty")
    return gray, mask


def _erode(mask: np.ndarray, radius: float) -> np.ndarray:
    return eroded(mask, max(1, int(round(radius))))


def _to_uint8(gray: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Contrast-limited histogram equalisation of the finger, for the generic detectors."""
    image = np.clip(gray * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return cv2.createCLAHE(clipLimit=2.0, tileGridSize=(8, 8)).apply(image)


# ------------------------------------------------------------------------------------------------
# Keypoints and descriptors
# ------------------------------------------------------------------------------------------------

def _minutiae(band: np.ndarray, mask: np.ndarray, period: float) -> np.ndarray:
    """Ridge endings and bifurcations ``[K, 2]`` (u, v) inside ``mask``, spurious clusters removed."""
    ridges = ((band > 0) & mask).astype(np.uint8) * 255
    skeleton = cv2.ximgproc.thinning(ridges, thinningType=cv2.ximgproc.THINNING_GUOHALL) > 0
    padded = np.pad(skeleton, 1).astype(np.int8)
    ring = [padded[0:-2, 1:-1], padded[0:-2, 2:], padded[1:-1, 2:], padded[2:, 2:],
            padded[2:, 1:-1], padded[2:, 0:-2], padded[1:-1, 0:-2], padded[0:-2, 0:-2]]
    crossing = sum(np.abs(ring[i] - ring[(i + 1) % 8]) for i in range(8)) // 2
    inner = _erode(mask, period)  # away from the mask edge, where ridges end artificially
    rows, cols = np.nonzero(skeleton & ((crossing == 1) | (crossing == 3)) & inner)
    points = np.stack([cols, rows], axis=1).astype(np.float64)
    if len(points) < 2:
        return points
    # Broken ridges and bridges make close pairs of false minutiae: drop every point in such a pair.
    from scipy.spatial import cKDTree

    close = cKDTree(points).query_pairs(0.8 * period, output_type="ndarray")
    keep = np.ones(len(points), bool)
    keep[close.ravel()] = False
    return points[keep]


def _rootsift(descriptors: np.ndarray) -> np.ndarray:
    descriptors = descriptors / (np.abs(descriptors).sum(axis=1, keepdims=True) + 1e-7)
    return np.sqrt(descriptors).astype(np.float32)


def _detect_describe(method: str, gray: np.ndarray, mask: np.ndarray, period: float,
                     band: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """Keypoints ``[K, 2]`` and descriptors ``[K, D]`` (None when there are none)."""
    image = _to_uint8(gray, mask)
    detect_mask = _erode(mask, max(3.0, 0.02 * min(mask.shape))).astype(np.uint8)
    if method == "minutiae":
        points = _minutiae(band, detect_mask > 0, period)
        if len(points) == 0:
            return points, None
        # SIFT window radius is ~5.3 x size: 0.6 periods gives a window of ~3 ridge periods.
        keypoints = [cv2.KeyPoint(float(u), float(v), 0.6 * period, 0.0) for u, v in points]
        keypoints, descriptors = cv2.SIFT_create().compute(image, keypoints)
        if descriptors is None:
            return np.zeros((0, 2)), None
        return np.array([k.pt for k in keypoints], np.float64), _rootsift(descriptors)
    if method in ("sift", "rootsift"):
        detector = cv2.SIFT_create(nfeatures=4000, contrastThreshold=0.02)
    elif method == "akaze":
        detector = cv2.xfeatures2d.AKAZE_create(threshold=1e-4)
    else:  # pragma: no cover - validated by the caller
        raise InputError(f"unknown matching method {method!r}")
    keypoints, descriptors = detector.detectAndCompute(image, detect_mask)
    if descriptors is None or len(keypoints) == 0:
        return np.zeros((0, 2)), None
    if method == "rootsift":
        descriptors = _rootsift(descriptors)
    return np.array([k.pt for k in keypoints], np.float64), descriptors


def _mutual_ratio_match(desc_a: np.ndarray, desc_b: np.ndarray, ratio: float,
                        binary: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices ``ia [M]``, ``ib [M]`` and Lowe ratios ``[M]`` of mutual nearest neighbours passing the ratio test."""
    if len(desc_a) < 2 or len(desc_b) < 2:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING if binary else cv2.NORM_L2)
    forward = matcher.knnMatch(desc_a, desc_b, k=2)
    backward = np.full(len(desc_b), -1)
    for match in matcher.match(desc_b, desc_a):
        backward[match.queryIdx] = match.trainIdx
    ia, ib, ratios = [], [], []
    for pair in forward:
        if len(pair) < 2:
            continue
        best, second = pair
        value = best.distance / max(second.distance, 1e-9)
        if value < ratio and backward[best.trainIdx] == best.queryIdx:
            ia.append(best.queryIdx)
            ib.append(best.trainIdx)
            ratios.append(value)
    return np.array(ia, int), np.array(ib, int), np.array(ratios, np.float64)


# ------------------------------------------------------------------------------------------------
# Geometric verification and refinement
# ------------------------------------------------------------------------------------------------

def _ecc_refine(band_a: np.ndarray, band_b: np.ndarray, uv_a: np.ndarray, guess_b: np.ndarray,
                linear: np.ndarray, half: int, verify_half: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Align a ``(2 half + 1)``-pixel patch of ``band_a`` around each ``uv_a`` into ``band_b``.

    The affine warp starts at ``guess_b`` with the 2x2 ``linear [N, 2, 2]`` part. Returns the refined
    ``uv_b [N, 2]`` (NaN where ECC failed or drifted more than half a patch) and the correlation
    coefficient ``[N]`` (0 where it failed).
    """
    size = 2 * half + 1
    search = 2 * size + 1  # the crop of b the warp may reach into
    refined = np.full((len(uv_a), 2), np.nan)
    correlation = np.zeros(len(uv_a))
    wide = np.zeros(len(uv_a))
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    height, width = band_b.shape
    for index in range(len(uv_a)):
        template = cv2.getRectSubPix(band_a, (size, size), (float(uv_a[index, 0]), float(uv_a[index, 1])))
        if np.count_nonzero(template) < 0.7 * size * size:  # mostly off the finger
            continue
        guess = np.asarray(guess_b[index], np.float64)
        if not (np.all(np.isfinite(guess)) and 0 <= guess[0] <= width - 1 and 0 <= guess[1] <= height - 1):
            continue
        origin = np.round(guess) - search // 2  # crop corner in b (integer: no resampling)
        crop = cv2.getRectSubPix(band_b, (search, search), (float(origin[0] + search // 2), float(origin[1] + search // 2)))
        # Warp maps template pixel (x, y) into the crop; the template centre (half, half) goes to guess.
        A = np.asarray(linear[index], np.float64)
        offset = guess - origin - A @ np.array([half, half], np.float64)
        warp = np.concatenate([A, offset[:, None]], axis=1).astype(np.float32)
        try:
            value, warp = cv2.findTransformECC(template, crop, warp, cv2.MOTION_AFFINE, criteria, None, 1)
        except cv2.error:  # did not converge
            continue
        centre = warp[:, :2].astype(np.float64) @ np.array([half, half], np.float64) + warp[:, 2] + origin
        if (not np.all(np.isfinite(centre)) or np.linalg.norm(centre - guess) > 0.5 * half
                or not (0 <= centre[0] <= width - 1 and 0 <= centre[1] <= height - 1)):
            continue
        singular = np.linalg.svd(warp[:, :2], compute_uv=False)
        if singular[1] < 0.4 or singular[0] > 2.5:  # collapsed or exploded patch: not a real fit
            continue
        refined[index] = centre
        correlation[index] = value
        if verify_half:
            # Correlation over a wider patch under the same affine map: ridges repeat, minutiae do not.
            big = 2 * verify_half + 1
            linear_part = warp[:, :2].astype(np.float64)
            absolute = np.concatenate([linear_part, (centre - linear_part @ np.array([verify_half, verify_half], np.float64))[:, None]], axis=1)
            wide_a = cv2.getRectSubPix(band_a, (big, big), (float(uv_a[index, 0]), float(uv_a[index, 1])))
            wide_b = cv2.warpAffine(band_b, absolute, (big, big), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
            both = (wide_a != 0) & (wide_b != 0)
            if both.sum() >= 0.5 * big * big:
                x, y = wide_a[both] - wide_a[both].mean(), wide_b[both] - wide_b[both].mean()
                wide[index] = float(np.dot(x, y) / np.sqrt(np.dot(x, x) * np.dot(y, y) + 1e-12))
    return refined, correlation, wide


def _local_linear(uv_a: np.ndarray, uv_b: np.ndarray, queries: np.ndarray, neighbours: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Predict ``queries [Q, 2]`` in b from the nearest matches by a local affine fit.

    Returns the predicted pixels ``[Q, 2]`` and the 2x2 linear parts ``[Q, 2, 2]`` (identity when
    there are too few neighbours for a fit).
    """
    from scipy.spatial import cKDTree

    k = min(neighbours, len(uv_a))
    _, index = cKDTree(uv_a).query(queries, k=k)
    index = index.reshape(len(queries), k)
    predicted = np.zeros((len(queries), 2))
    linear = np.tile(np.eye(2), (len(queries), 1, 1))
    for q in range(len(queries)):
        src, dst = uv_a[index[q]], uv_b[index[q]]
        if k >= 3:
            design = np.concatenate([src - queries[q], np.ones((k, 1))], axis=1)
            solution, *_ = np.linalg.lstsq(design, dst, rcond=None)
            linear[q] = solution[:2].T
            predicted[q] = solution[2]
        else:
            predicted[q] = queries[q] + np.mean(dst - src, axis=0)
    return predicted, linear


# ------------------------------------------------------------------------------------------------
# Public entry point
# ------------------------------------------------------------------------------------------------

def match_views(image_a: np.ndarray, mask_a: np.ndarray | None, image_b: np.ndarray,
                mask_b: np.ndarray | None, *, method: str = DEFAULT_METHOD, max_matches: int = 2000,
                ratio: float | None = None, epipolar_px: float | None = None, min_matches: int = 12,
                min_correlation: float = 0.8, densify: bool = False,
                period_px: float | None = None, target_period_px: float | None = TARGET_PERIOD_PX) -> Matches:
    """Verified correspondences between two photos of one finger (see the module docstring).

    ``image_*``: ``[H, W]`` or ``[H, W, 3]`` in [0, 1] (uint8/uint16 accepted); ``mask_*``: ``[H, W]``
    bool finger masks (None: whole image). ``ratio``: Lowe's ratio bound (default 0.95 for
    ``minutiae``, whose candidates are few and sparse, 0.8 otherwise). ``epipolar_px``: MAGSAC
    threshold at full resolution (default: ``max(1, period / 4)``). Fewer than ``min_matches``
    verified matches means no reliable overlap: an empty :class:`Matches` is returned.
    ``min_correlation``: ECC correlation below which a refined ``minutiae`` match is dropped.
    ``densify``: add guided grid matches (``minutiae`` only). ``period_px``: the ridge period
    in pixels of image a (measured when None). ``target_period_px``: detection runs on images
    shrunk until the ridge period is about this many pixels (None: at full resolution; images are
    never enlarged). At most ``max_matches`` are returned, best first.
    """
    start = time.perf_counter()
    if method not in METHODS:
        raise InputError(f"unknown matching method {method!r}; choose one of {', '.join(METHODS)}")
    if max_matches < 1:
        raise InputError(f"max_matches must be positive, got {max_matches}")
    gray_a, mask_a = _validate(image_a, mask_a, "a")
    gray_b, mask_b = _validate(image_b, mask_b, "b")
    period = float(period_px) if period_px else estimate_ridge_period(gray_a, mask_a)
    scale = 1.0 if target_period_px is None else min(1.0, float(target_period_px) / period)
    small = [_resize(gray, mask, scale) for gray, mask in ((gray_a, mask_a), (gray_b, mask_b))]
    small_period = period * scale
    bands = [ridge_texture(g, m, small_period) if method == "minutiae" else None for g, m in small]
    (points_a, desc_a), (points_b, desc_b) = (
        _detect_describe(method, g, m, small_period, band) for (g, m), band in zip(small, bands))
    if desc_a is None or desc_b is None:
        return Matches.empty(method, 0, time.perf_counter() - start)
    ratio = (0.95 if method == "minutiae" else 0.8) if ratio is None else float(ratio)
    ia, ib, ratios = _mutual_ratio_match(desc_a, desc_b, ratio, binary=method == "akaze")
    n_putative = len(ia)
    uv_a = (points_a[ia] + 0.5) / scale - 0.5
    uv_b = (points_b[ib] + 0.5) / scale - 0.5
    threshold = max(1.0, period / 4.0) if epipolar_px is None else float(epipolar_px)
    F, inliers = fundamental_inliers(uv_a, uv_b, threshold)
    if F is None or inliers.sum() < min_matches:
        return Matches.empty(method, n_putative, time.perf_counter() - start)
    uv_a, uv_b, ratios = uv_a[inliers], uv_b[inliers], ratios[inliers]

    if method != "minutiae":
        score = np.clip(1.0 - ratios ** 2, 1e-3, 1.0)
    else:
        all_a = (points_a + 0.5) / scale - 0.5
        uv_a, uv_b, score = _refine_minutiae(gray_a, mask_a, gray_b, mask_b, uv_a, uv_b, all_a, period,
                                             threshold, min_correlation, densify, max_matches)
    order = np.argsort(-score, kind="stable")[:max_matches]
    if len(order) < min_matches:
        return Matches.empty(method, n_putative, time.perf_counter() - start)
    return Matches(uv_a[order], uv_b[order], score[order], method, n_putative, time.perf_counter() - start)


def _refine_minutiae(gray_a, mask_a, gray_b, mask_b, uv_a, uv_b, all_a, period, threshold,
                     min_correlation, densify, max_matches):
    """ECC-refine verified minutia matches, add guided ones, drop locally inconsistent ones."""
    band_a = ridge_texture(gray_a, mask_a, period)
    band_b = ridge_texture(gray_b, mask_b, period)
    half = int(round(ECC_HALF_PERIODS * period))
    verify_half = int(round(VERIFY_HALF_PERIODS * period))
    # Identity start: a local fit from the putative neighbours is worse (they still hold outliers).
    linear = np.tile(np.eye(2), (len(uv_a), 1, 1))
    refined, correlation, wide = _ecc_refine(band_a, band_b, uv_a, uv_b, linear, half, verify_half)
    keep = np.isfinite(refined).all(axis=1) & (correlation >= min_correlation) & (wide >= MIN_WIDE_CORRELATION)
    uv_a, uv_b, score = uv_a[keep], refined[keep], correlation[keep]
    F, inliers = fundamental_inliers(uv_a, uv_b, min(threshold, 1.0))
    if F is None or inliers.sum() < 8:
        return uv_a[:0], uv_b[:0], score[:0]
    uv_a, uv_b, score = uv_a[inliers], uv_b[inliers], score[inliers]
    # Guided round: every other minutia of a, predicted in b from its verified neighbours.
    from scipy.spatial import cKDTree

    distance, _ = cKDTree(uv_a).query(all_a)
    candidates = all_a[distance > 0.5 * period]
    if len(candidates):
        predicted, linear = _local_linear(uv_a, uv_b, candidates)
        refined, correlation, wide = _ecc_refine(band_a, band_b, candidates, predicted, linear, half, verify_half)
        ok = np.isfinite(refined).all(axis=1) & (correlation >= min_correlation) & (wide >= MIN_WIDE_CORRELATION)
        ok[ok] &= sampson_distance(F, candidates[ok], refined[ok]) < min(threshold, 1.0)
        ok[ok] &= np.linalg.norm(refined[ok] - predicted[ok], axis=1) < 0.5 * period
        uv_a = np.concatenate([uv_a, candidates[ok]])
        uv_b = np.concatenate([uv_b, refined[ok]])
        score = np.concatenate([score, correlation[ok]])
    if densify and len(uv_a) < max_matches:
        extra = _densify(band_a, band_b, mask_a, uv_a, uv_b, F, period, half, verify_half,
                         min_correlation, max_matches - len(uv_a))
        uv_a = np.concatenate([uv_a, extra[0]])
        uv_b = np.concatenate([uv_b, extra[1]])
        score = np.concatenate([score, extra[2]])
    keep = _locally_consistent(uv_a, uv_b, 0.5 * period)
    return uv_a[keep], uv_b[keep], score[keep]


def _locally_consistent(uv_a: np.ndarray, uv_b: np.ndarray, tolerance: float, neighbours: int = 8,
                        rounds: int = 3, spread: float = 0.1) -> np.ndarray:
    """``[N]`` bool: matches that their neighbours' local affine map predicts well.

    Leave-one-out: each match is predicted from its ``neighbours`` nearest others (in a) and must
    land within ``max(tolerance, spread * distance to the farthest of them)`` pixels (an affine map
    is only locally right on a curved finger, so sparse neighbourhoods are judged more loosely).
    The worst offenders are removed first and the test is repeated, so one gross outlier does not
    condemn its neighbours.
    """
    from scipy.spatial import cKDTree

    keep = np.ones(len(uv_a), bool)
    for _ in range(rounds):
        index = np.flatnonzero(keep)
        if len(index) < 5:
            return keep
        src, dst = uv_a[index], uv_b[index]
        k = min(neighbours + 1, len(index))
        reach, near = cKDTree(src).query(src, k=k)
        allowed = np.maximum(tolerance, spread * reach[:, -1])
        error = np.zeros(len(index))
        for i in range(len(index)):
            others = near[i][near[i] != i]
            design = np.concatenate([src[others] - src[i], np.ones((len(others), 1))], axis=1)
            solution, *_ = np.linalg.lstsq(design, dst[others], rcond=None)
            error[i] = np.linalg.norm(solution[2] - dst[i])
        bad = error > allowed
        if not bad.any():
            return keep
        # Remove the worse half of the offenders (at least one) and test again.
        worst = index[bad][np.argsort(-error[bad])][: max(1, int(np.ceil(bad.sum() / 2)))]
        keep[worst] = False
    return keep


def _densify(band_a, band_b, mask_a, uv_a, uv_b, F, period, half, verify_half, min_correlation, budget,
             rounds: int = 3):
    """Grow matches on a grid around the verified ones: predict, ECC-refine, check epipolar residual."""
    step = 2.0 * period
    inner = _erode(mask_a, 1.5 * half)
    rows, cols = np.mgrid[half:band_a.shape[0] - half:step, half:band_a.shape[1] - half:step]
    grid = np.stack([cols.ravel(), rows.ravel()], axis=1).astype(np.float64)
    grid = grid[inner[grid[:, 1].astype(int), grid[:, 0].astype(int)]]
    known_a, known_b = uv_a.copy(), uv_b.copy()
    new_a, new_b, new_score = [], [], []
    from scipy.spatial import cKDTree

    for _ in range(rounds):
        if len(grid) == 0 or budget <= 0:
            break
        distance, _ = cKDTree(known_a).query(grid)
        near = (distance > 0.75 * step) & (distance < 4.0 * step)
        candidates = grid[near][:budget]
        if len(candidates) == 0:
            break
        predicted, linear = _local_linear(known_a, known_b, candidates)
        refined, correlation, wide = _ecc_refine(band_a, band_b, candidates, predicted, linear, half, verify_half)
        ok = np.isfinite(refined).all(axis=1) & (correlation >= min_correlation) & (wide >= MIN_WIDE_CORRELATION)
        ok[ok] &= sampson_distance(F, candidates[ok], refined[ok]) < 1.0
        ok[ok] &= np.linalg.norm(refined[ok] - predicted[ok], axis=1) < 0.5 * period
        new_a.append(candidates[ok])
        new_b.append(refined[ok])
        new_score.append(correlation[ok])
        known_a = np.concatenate([known_a, candidates[ok]])
        known_b = np.concatenate([known_b, refined[ok]])
        budget -= int(ok.sum())
        grid = grid[~near]
    if not new_a:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    return np.concatenate(new_a), np.concatenate(new_b), np.concatenate(new_score)


def _resize(gray: np.ndarray, mask: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    if scale >= 1.0:
        return gray, mask
    small = cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    small_mask = cv2.resize(mask.astype(np.uint8), (small.shape[1], small.shape[0]),
                            interpolation=cv2.INTER_NEAREST) > 0
    return small, small_mask
