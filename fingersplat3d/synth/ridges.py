"""Procedural fingerprint ridge patterns with exact ground-truth minutiae.

Pattern space
    A flat 2-D chart of the finger skin in millimetres. ``a`` runs along the finger from the
    fingertip (``a = 0``) toward the base (``a = length_mm``); ``b`` runs across it, around the
    circumference, ``b = 0`` on the centre line of the pad. Grid row ``i`` is ``a = i * spacing``,
    column ``j`` is ``b = -half_width + j * spacing``.

Ridge field
    ``ridges`` is +1 on ridge centre lines and -1 in valley centres, near-sinusoidal across the
    ridges. A pixel is "on a ridge" where ``ridges > 0``.

Minutiae
    Rows ``(a_mm, b_mm, angle_rad, kind)``, ``kind`` 0 = ridge ending, 1 = bifurcation. They are
    found on the skeleton of ``ridges > 0`` (``cv2.ximgproc.thinning``, crossing number), so
    re-skeletonising the exported field finds each of them again at the same place.
    ``angle = atan2(db, da)`` of the unit vector pointing *away from the stem*: for a ridge
    ending, from the ridge body out through the free end; for a bifurcation, from the stem into
    the fork between the two branches. Directions come from tracing the skeleton about one ridge
    period along each branch.

Generation (after SFinGe, Cappelli et al.)
    1. An orientation field from :mod:`fingersplat3d.synth.orientation` (zero-pole model).
    2. Sparse random seeds grown into ridges by iterated oriented Gabor filtering: a bank of
       filters at ``N_BINS`` orientations applied by FFT, each pixel interpolating between the
       responses of its two nearest orientation bins, then gain and clipping to [-1, 1]. Where
       fronts grown from different seeds meet out of phase, minutiae appear, as in real skin.
    3. A last pass with quadrature (complex) Gabor filters gives the local phase; the exported
       field is ``cos(phase)``, softened where the amplitude vanishes (at minutiae).
    4. Minutiae come from the skeleton of ``ridges > 0`` once islands and holes smaller than
       ``period**2`` (dots, pores: left in the field, as in real skin, but not minutiae) are
       removed. Artefacts are dropped: minutiae within a period of the grid border, within 1.5
       periods of a core or delta, and pairs closer than half a period (skeleton spurs, bridges).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np
import scipy.fft as sfft
from scipy.spatial import cKDTree

from ..errors import InputError
from .orientation import PATTERN_CLASSES, orientation_field, random_orientation_model

__all__ = ["PATTERN_CLASSES", "ENDING", "BIFURCATION", "RidgePattern", "make_ridge_pattern"]

N_BINS = 12  # orientation bins of the Gabor bank
GROW_ITERATIONS = 20  # Gabor growth iterations (the grid fills after ~12; the rest settle it)
SEEDS_PER_MM2 = 0.3  # density of the random seeds the ridges grow from
GAIN = 4.0  # per-iteration gain before clipping; > 1 makes the ridge fronts advance
SIGMA_ACROSS = 0.6  # Gabor envelope across the ridges, in periods
SIGMA_ALONG = 0.6  # Gabor envelope along the ridges, in periods
AMPLITUDE_FLOOR = 0.15  # cos(phase) fades to 0 where the amplitude drops below this x median

ENDING, BIFURCATION = 0, 1  # minutia kinds (column 3 of RidgePattern.minutiae)


@dataclass(frozen=True, eq=False)
class RidgePattern:
    """A ridge field on a regular pattern-space grid, with its ground-truth singular points."""

    ridges: np.ndarray  # [H, W] float32 in [-1, 1]; +1 on ridge centre lines
    spacing_mm: float  # grid spacing in mm (both axes)
    period_mm: float  # nominal ridge period
    pattern_class: str  # "arch" | "loop" | "whorl"
    minutiae: np.ndarray  # [M, 4] float64 (a_mm, b_mm, angle_rad, kind)
    cores: np.ndarray  # [C, 2] float64 (a_mm, b_mm)
    deltas: np.ndarray  # [D, 2] float64 (a_mm, b_mm)
    half_width_mm: float | None = None  # b of column 0 is -half_width_mm; None: (W - 1) * spacing / 2

    def __post_init__(self) -> None:
        if self.half_width_mm is None:
            object.__setattr__(self, "half_width_mm", (self.ridges.shape[1] - 1) * self.spacing_mm / 2)

    @property
    def length_mm(self) -> float:
        """``a`` of the last grid row."""
        return (self.ridges.shape[0] - 1) * self.spacing_mm

    def sample(self, a_mm: np.ndarray, b_mm: np.ndarray, field: np.ndarray | None = None) -> np.ndarray:
        """Bilinear lookup of ``ridges`` (or of another ``field`` on the same grid, e.g. its gradient)
        at points ``(a_mm, b_mm)`` (broadcast, any shape).

        Points outside the grid take the value of the nearest edge. Returns float32.
        """
        a, b = np.broadcast_arrays(np.asarray(a_mm, dtype=np.float64), np.asarray(b_mm, dtype=np.float64))
        grid = self.ridges if field is None else field
        return _bilinear(grid, a / self.spacing_mm, (b + self.half_width_mm) / self.spacing_mm)


def _bilinear(image: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Bilinear lookup of ``image`` ([H, W]) at fractional pixels, clamped to the edges."""
    height, width = image.shape
    row = np.clip(row, 0.0, height - 1)
    col = np.clip(col, 0.0, width - 1)
    row0 = np.minimum(np.floor(row).astype(np.intp), max(height - 2, 0))
    col0 = np.minimum(np.floor(col).astype(np.intp), max(width - 2, 0))
    row1 = np.minimum(row0 + 1, height - 1)
    col1 = np.minimum(col0 + 1, width - 1)
    fr = (row - row0).astype(image.dtype)
    fc = (col - col0).astype(image.dtype)
    top = image[row0, col0] * (1 - fc) + image[row0, col1] * fc
    bottom = image[row1, col0] * (1 - fc) + image[row1, col1] * fc
    return top * (1 - fr) + bottom * fr


def make_ridge_pattern(
    rng: np.random.Generator,
    length_mm: float,
    half_width_mm: float,
    *,
    period_mm: float = 0.45,
    pattern_class: str = "loop",
    core_a_mm: float | None = None,
    spacing_mm: float = 0.05,
) -> RidgePattern:
    """Grow a fingerprint ridge pattern of ``pattern_class`` and extract its minutiae.

    The grid spans ``a`` in ``[0, length_mm]`` and ``b`` in ``[-half_width_mm, half_width_mm]``
    at ``spacing_mm``. ``core_a_mm`` places the core (default ``0.4 * length_mm``, jittered).
    The result is a deterministic function of the state of ``rng``.
    """
    _validate(rng, length_mm, half_width_mm, period_mm, pattern_class, core_a_mm, spacing_mm)
    n_rows = int(math.floor(length_mm / spacing_mm + 1e-6)) + 1
    n_cols = int(math.floor(2 * half_width_mm / spacing_mm + 1e-6)) + 1
    period_px = period_mm / spacing_mm

    model = random_orientation_model(rng, length_mm, half_width_mm, pattern_class, core_a_mm)
    # Grow on a padded, FFT-friendly grid so the circular wrap of the FFT stays off the grid.
    margin = int(math.ceil(3 * period_px))
    padded = (sfft.next_fast_len(n_rows + 2 * margin), sfft.next_fast_len(n_cols + 2 * margin, real=True))
    a = (np.arange(padded[0]) - margin) * spacing_mm
    b = (np.arange(padded[1]) - margin) * spacing_mm - half_width_mm
    theta = orientation_field(model, a[:, None], b[None, :])  # [Hp, Wp]

    bins = _OrientationBins(theta)
    grown = _grow(bins, period_px, rng, seeds=int(rng.poisson(SEEDS_PER_MM2 * length_mm * 2 * half_width_mm)))
    field = _quadrature_cosine(grown, bins, period_px)
    field = field[margin : margin + n_rows, margin : margin + n_cols]

    singular = np.concatenate([model.cores, model.deltas]) / spacing_mm + np.array([0.0, half_width_mm / spacing_mm])
    minutiae_px = _extract_minutiae(field, period_px, singular)  # [M, 4] (row, col, angle, kind)
    minutiae = minutiae_px.copy()
    minutiae[:, 0] = minutiae_px[:, 0] * spacing_mm
    minutiae[:, 1] = minutiae_px[:, 1] * spacing_mm - half_width_mm
    inside = _inside(length_mm, half_width_mm)
    return RidgePattern(
        ridges=field.astype(np.float32),
        spacing_mm=float(spacing_mm),
        period_mm=float(period_mm),
        pattern_class=pattern_class,
        minutiae=minutiae,
        cores=model.cores[inside(model.cores)].astype(np.float64).reshape(-1, 2),
        deltas=model.deltas[inside(model.deltas)].astype(np.float64).reshape(-1, 2),
        half_width_mm=float(half_width_mm),
    )


def _validate(rng, length_mm, half_width_mm, period_mm, pattern_class, core_a_mm, spacing_mm) -> None:
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    if pattern_class not in PATTERN_CLASSES:
        raise InputError(f"pattern_class must be one of {PATTERN_CLASSES}, got {pattern_class!r}")
    for name, value in (("length_mm", length_mm), ("half_width_mm", half_width_mm),
                        ("period_mm", period_mm), ("spacing_mm", spacing_mm)):
        if not (isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive finite number, got {value!r}")
    if period_mm < 3 * spacing_mm * (1 - 1e-9):
        raise InputError(f"period_mm ({period_mm:g}) must span at least 3 grid cells (3 * spacing_mm = {3 * spacing_mm:g})")
    if length_mm < 10 * period_mm or 2 * half_width_mm < 10 * period_mm:
        raise InputError(f"the pattern must span at least 10 ridge periods each way, got length_mm={length_mm}, "
                         f"half_width_mm={half_width_mm} for period_mm={period_mm}")
    cells = (length_mm / spacing_mm + 1) * (2 * half_width_mm / spacing_mm + 1)
    if cells > 2e7:
        raise InputError(f"the grid would have {cells:.3g} cells (more than 2e7); use a larger spacing_mm")
    if core_a_mm is not None and not (isinstance(core_a_mm, (int, float, np.integer, np.floating))
                                      and math.isfinite(core_a_mm) and 0 <= core_a_mm <= length_mm):
        raise InputError(f"core_a_mm must lie in [0, length_mm={length_mm}], got {core_a_mm!r}")


def _inside(length_mm: float, half_width_mm: float):
    def test(points: np.ndarray) -> np.ndarray:  # [N, 2] -> [N] bool
        return (points[:, 0] >= 0) & (points[:, 0] <= length_mm) & (np.abs(points[:, 1]) <= half_width_mm)
    return test


class _OrientationBins:
    """Per-pixel interpolation weights between the two orientation bins nearest ``theta``."""

    def __init__(self, theta: np.ndarray) -> None:  # theta: [H, W] in [0, pi)
        position = theta * (N_BINS / np.pi)
        lower = np.floor(position)
        frac = (position - lower).astype(np.float32)
        lower = lower.astype(np.intp) % N_BINS
        upper = (lower + 1) % N_BINS
        self.shape = theta.shape
        self.weights = [((lower == k) * (1 - frac) + (upper == k) * frac).astype(np.float32) for k in range(N_BINS)]

    def angles(self) -> np.ndarray:  # [N_BINS]
        return np.arange(N_BINS) * (np.pi / N_BINS)


def _gabor_spectra(shape: tuple[int, int], period_px: float, angles: np.ndarray, *, one_sided: bool) -> list[np.ndarray]:
    """Frequency responses of oriented Gabor filters with ridge tangent angle ``angles`` (rad).

    ``one_sided=False``: even (cosine) filters on the ``rfft2`` grid, real. ``True``: analytic
    (complex) filters on the full ``fft2`` grid, passing only the frequency on one side.
    """
    f_row = sfft.fftfreq(shape[0])[:, None]
    f_col = (sfft.fftfreq(shape[1]) if one_sided else sfft.rfftfreq(shape[1]))[None, :]
    s_across, s_along = SIGMA_ACROSS * period_px, SIGMA_ALONG * period_px
    spectra = []
    for angle in angles:
        tangent = (math.cos(angle), math.sin(angle))  # (row, col)
        normal = (-tangent[1], tangent[0])
        response = 0.0
        for sign in ((1.0,) if one_sided else (1.0, -1.0)):
            d_row = f_row - sign * normal[0] / period_px
            d_col = f_col - sign * normal[1] / period_px
            across = d_row * normal[0] + d_col * normal[1]
            along = d_row * tangent[0] + d_col * tangent[1]
            response = response + np.exp(-2 * np.pi**2 * ((s_across * across) ** 2 + (s_along * along) ** 2))
        spectra.append(np.asarray(response, dtype=np.float32))
    return spectra


def _grow(bins: _OrientationBins, period_px: float, rng: np.random.Generator, seeds: int) -> np.ndarray:
    """Grow ridges from ``seeds`` random spikes by iterated oriented Gabor filtering. [H, W]."""
    shape = bins.shape
    spectra = _gabor_spectra(shape, period_px, bins.angles(), one_sided=False)
    image = np.zeros(shape, np.float32)
    rows = rng.integers(0, shape[0], max(seeds, 1))
    cols = rng.integers(0, shape[1], max(seeds, 1))
    image[rows, cols] = rng.choice(np.array([-1.0, 1.0], np.float32), rows.size)
    for _ in range(GROW_ITERATIONS):
        spectrum = sfft.rfft2(image, workers=-1)
        response = np.zeros(shape, np.float32)
        for weight, gabor in zip(bins.weights, spectra):
            response += weight * sfft.irfft2(spectrum * gabor, s=shape, workers=-1)
        image = np.clip(response * (GAIN / max(float(np.abs(response).max()), 1e-12)), -1.0, 1.0)
    return image


def _quadrature_cosine(image: np.ndarray, bins: _OrientationBins, period_px: float) -> np.ndarray:
    """``cos`` of the local ridge phase of ``image``: a clean near-sinusoid in [-1, 1]. [H, W]."""
    spectrum = sfft.fft2(image, workers=-1)
    real = np.zeros(image.shape, np.float32)
    amplitude = np.zeros(image.shape, np.float32)
    for weight, gabor in zip(bins.weights, _gabor_spectra(image.shape, period_px, bins.angles(), one_sided=True)):
        analytic = sfft.ifft2(spectrum * gabor, workers=-1)
        real += weight * analytic.real
        amplitude += weight * np.abs(analytic)
    # Soften cos(phase) where the amplitude vanishes (the phase is singular at minutiae).
    floor = AMPLITUDE_FLOOR * float(np.median(amplitude))
    return np.clip(real / np.sqrt(amplitude**2 + floor**2), -1.0, 1.0)


def _remove_specks(binary: np.ndarray, min_area: float) -> np.ndarray:
    """``binary`` ([H, W] bool) without ridge islands and valley holes smaller than ``min_area``.

    Specks cut by the grid border are kept (they are parts of larger ridges or valleys).
    """
    binary = binary.copy()
    for value in (True, False):  # islands (8-connected ridges), then holes (4-connected valleys)
        mask = (binary == value).astype(np.uint8)
        _, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8 if value else 4)
        left, top = stats[1:, cv2.CC_STAT_LEFT], stats[1:, cv2.CC_STAT_TOP]
        right, bottom = left + stats[1:, cv2.CC_STAT_WIDTH], top + stats[1:, cv2.CC_STAT_HEIGHT]
        interior = (left > 0) & (top > 0) & (right < binary.shape[1]) & (bottom < binary.shape[0])
        small = np.flatnonzero((stats[1:, cv2.CC_STAT_AREA] < min_area) & interior) + 1
        if small.size:
            binary[np.isin(labels, small)] = not value
    return binary


# Neighbour offsets in cyclic order around a pixel (row, col).
_RING = np.array([(-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1)])


def _crossing_number(skeleton: np.ndarray) -> np.ndarray:
    """Crossing number of every skeleton pixel (0 elsewhere). skeleton: [H, W] bool -> [H, W] int."""
    padded = np.pad(skeleton.astype(np.int8), 1)
    height, width = skeleton.shape
    ring = [padded[1 + dr : 1 + dr + height, 1 + dc : 1 + dc + width] for dr, dc in _RING]
    transitions = sum(np.abs(ring[k] - ring[(k + 1) % 8]) for k in range(8)) // 2
    return np.where(skeleton, transitions, 0)


def _skeleton(binary: np.ndarray) -> np.ndarray:
    """One-pixel skeleton of ``binary`` ([H, W] bool) by Zhang-Suen thinning."""
    return cv2.ximgproc.thinning(binary.astype(np.uint8) * 255, thinningType=cv2.ximgproc.THINNING_ZHANGSUEN) > 0


def _branch_directions(skeleton: np.ndarray, row: int, col: int, reach: float) -> list[np.ndarray]:
    """Unit vectors (row, col) from a skeleton pixel toward each of its branches, ~``reach`` away.

    The branches are the runs of skeleton pixels in the 8-ring; a breadth-first walk along the
    skeleton labels pixels by the branch that reaches them first, and each branch's direction is
    the mean offset of its pixels between ``reach / 2`` and ``reach`` steps out.
    """
    height, width = skeleton.shape
    ring = [(row + dr, col + dc) for dr, dc in _RING]
    on = [0 <= r < height and 0 <= c < width and bool(skeleton[r, c]) for r, c in ring]
    label_of: dict[tuple[int, int], int] = {(row, col): -1}
    queue: deque[tuple[int, int, int]] = deque()
    n_branches = 0
    start = next((k for k in range(8) if not on[k]), None)
    if start is None:
        return []
    for step in range(1, 9):  # walk the ring from an empty cell so runs are contiguous
        k = (start + step) % 8
        if on[k]:
            if not on[(k - 1) % 8]:
                n_branches += 1
            label_of[ring[k]] = n_branches - 1
            queue.append((ring[k][0], ring[k][1], 1))
    sums = np.zeros((n_branches, 2))
    counts = np.zeros(n_branches)
    fallback = np.zeros((n_branches, 2))
    limit = max(int(round(reach)), 2)
    while queue:
        r, c, depth = queue.popleft()
        branch = label_of[(r, c)]
        offset = np.array([r - row, c - col], dtype=np.float64)
        fallback[branch] = offset  # the farthest pixel reached so far
        if depth >= limit / 2:
            sums[branch] += offset
            counts[branch] += 1
        if depth >= limit:
            continue
        for dr, dc in _RING:
            nr, nc = r + dr, c + dc
            if 0 <= nr < height and 0 <= nc < width and skeleton[nr, nc] and (nr, nc) not in label_of:
                label_of[(nr, nc)] = branch
                queue.append((nr, nc, depth + 1))
    directions = []
    for branch in range(n_branches):
        vector = sums[branch] / counts[branch] if counts[branch] else fallback[branch]
        directions.append(vector / max(np.linalg.norm(vector), 1e-12))
    return directions


def _minutia_angle(directions: list[np.ndarray], kind: int) -> float:
    """Angle ``atan2(db, da)`` pointing away from the stem (see the module docstring)."""
    if kind == ENDING:
        away = -directions[0]
    else:
        first, second, third = directions[:3]
        pairs = [(first @ second, first, second, third), (first @ third, first, third, second),
                 (second @ third, second, third, first)]
        _, fork_1, fork_2, stem = max(pairs, key=lambda p: p[0])  # the fork: the closest pair
        bisector = fork_1 + fork_2
        away = bisector / max(np.linalg.norm(bisector), 1e-12) - stem
    return float(math.atan2(away[1], away[0]))


def _extract_minutiae(field: np.ndarray, period_px: float, singular_px: np.ndarray) -> np.ndarray:
    """Ridge endings and bifurcations of ``field > 0`` (field: [H, W]), in pixels. -> [M, 4].

    Islands and holes smaller than a period squared (dots, pores) are removed before thinning.
    Rows are (row, col, angle, kind). Dropped: minutiae within a period of the border, within
    1.5 periods of a singular point (``singular_px`` [S, 2] (row, col)), and both members of any
    pair closer than half a period (spurs, bridges, tiny gaps). Positions are moved across the
    ridge, by at most half a pixel, to the crest of ``field``.
    """
    skeleton = _skeleton(_remove_specks(field > 0, min_area=period_px**2))
    crossing = _crossing_number(skeleton)
    rows, cols = np.nonzero((crossing == 1) | (crossing == 3))
    kinds = np.where(crossing[rows, cols] == 1, ENDING, BIFURCATION)
    points = np.stack([rows, cols], axis=1).astype(np.float64)  # [K, 2]
    height, width = field.shape
    keep = ((points[:, 0] >= period_px) & (points[:, 0] <= height - 1 - period_px)
            & (points[:, 1] >= period_px) & (points[:, 1] <= width - 1 - period_px))
    # Crossings (CN >= 4) count as neighbours too, so close pairs around them are dropped.
    everything = np.concatenate([points, np.argwhere(crossing >= 4).astype(np.float64)])
    if len(everything) > 1:
        pairs = cKDTree(everything).query_pairs(0.5 * period_px, output_type="ndarray")  # [P, 2]
        crowded = np.zeros(len(everything), bool)
        crowded[pairs.ravel()] = True
        keep &= ~crowded[: len(points)]
    if len(singular_px) and len(points):
        distance = np.linalg.norm(points[:, None, :] - singular_px[None, :, :], axis=2).min(axis=1)
        keep &= distance > 1.5 * period_px
    found = []
    for (row, col), kind in zip(points[keep].astype(int), kinds[keep]):
        directions = _branch_directions(skeleton, int(row), int(col), reach=period_px)
        if len(directions) == (1 if kind == ENDING else 3):
            found.append((row, col, _minutia_angle(directions, int(kind)), kind))
    minutiae = np.array(found, dtype=np.float64).reshape(-1, 4)
    minutiae[:, :2] += _crest_offsets(field, minutiae)
    return minutiae


def _crest_offsets(field: np.ndarray, minutiae: np.ndarray) -> np.ndarray:
    """Sub-pixel shifts ([M, 2] (row, col)) across the ridge to the parabola vertex of ``field``."""
    normal = np.stack([-np.sin(minutiae[:, 2]), np.cos(minutiae[:, 2])], axis=1)  # [M, 2] (row, col)
    rows, cols = minutiae[:, 0], minutiae[:, 1]
    before = _bilinear(field, rows - normal[:, 0], cols - normal[:, 1]).astype(np.float64)
    centre = field[rows.astype(np.intp), cols.astype(np.intp)].astype(np.float64)
    after = _bilinear(field, rows + normal[:, 0], cols + normal[:, 1]).astype(np.float64)
    curvature = before - 2 * centre + after
    shift = np.where(curvature < -1e-6, 0.5 * (before - after) / np.minimum(curvature, -1e-6), 0.0)
    return np.clip(shift, -0.5, 0.5)[:, None] * normal
