"""Procedural ridge patterns: field properties, ground-truth minutiae, singular points, API.

Minutiae are re-found here with an independent crossing-number pass over the skeleton of
``ridges > 0``; periods are measured by zero crossings along the local ridge normal.
"""
from __future__ import annotations

import functools
import subprocess
import sys

import cv2
import numpy as np
import pytest

from fingersplat3d.synth.orientation import orientation_field, random_orientation_model
from fingersplat3d.synth.ridges import BIFURCATION, ENDING, PATTERN_CLASSES, RidgePattern, make_ridge_pattern

LENGTH, HALF_WIDTH, PERIOD, SPACING = 26.0, 15.0, 0.45, 0.05
SEEDS = (0, 1, 2)
CASES = [(pattern_class, seed) for pattern_class in PATTERN_CLASSES for seed in SEEDS]


@functools.lru_cache(maxsize=None)
def pattern(pattern_class: str, seed: int, period_mm: float = PERIOD) -> RidgePattern:
    return make_ridge_pattern(np.random.default_rng(seed), LENGTH, HALF_WIDTH,
                              period_mm=period_mm, pattern_class=pattern_class)


def skeleton_minutiae(ridges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Endings and bifurcations ([N, 2] (row, col)) of the skeleton of ``ridges > 0``."""
    skeleton = cv2.ximgproc.thinning((ridges > 0).astype(np.uint8) * 255) > 0
    padded = np.pad(skeleton, 1).astype(np.int16)
    height, width = skeleton.shape
    ring = [(-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1)]
    neighbours = [padded[1 + dr : 1 + dr + height, 1 + dc : 1 + dc + width] for dr, dc in ring]
    crossing = sum(np.abs(neighbours[k] - neighbours[(k + 1) % 8]) for k in range(8)) // 2
    return np.argwhere(skeleton & (crossing == 1)), np.argwhere(skeleton & (crossing >= 3))


def to_pixels(p: RidgePattern, points_mm: np.ndarray) -> np.ndarray:
    return np.stack([points_mm[:, 0], points_mm[:, 1] + p.half_width_mm], axis=1) / p.spacing_mm


def local_periods(p: RidgePattern, rng: np.random.Generator, count: int = 800, span: float = 5.0) -> np.ndarray:
    """Ridge periods (mm) from zero crossings along the structure-tensor normal at random points."""
    r = p.ridges
    grad_a = cv2.Sobel(r, cv2.CV_32F, 0, 1)
    grad_b = cv2.Sobel(r, cv2.CV_32F, 1, 0)
    sigma = p.period_mm / p.spacing_mm
    jaa = cv2.GaussianBlur(grad_a * grad_a, (0, 0), sigma)
    jbb = cv2.GaussianBlur(grad_b * grad_b, (0, 0), sigma)
    jab = cv2.GaussianBlur(grad_a * grad_b, (0, 0), sigma)
    normal = 0.5 * np.arctan2(2 * jab, jaa - jbb)  # atan2(db, da) of the ridge normal
    length = span * p.period_mm
    a = rng.uniform(length, p.length_mm - length, count)
    b = rng.uniform(-p.half_width_mm + length, p.half_width_mm - length, count)
    angle = normal[np.rint(a / p.spacing_mm).astype(int), np.rint((b + p.half_width_mm) / p.spacing_mm).astype(int)]
    t = np.linspace(-length / 2, length / 2, 801)
    values = p.sample(a[:, None] + t * np.cos(angle)[:, None], b[:, None] + t * np.sin(angle)[:, None])
    periods = []
    for row in values:
        index = np.flatnonzero(np.signbit(row[1:]) != np.signbit(row[:-1]))
        if len(index) >= 3:
            zeros = t[index] + (t[1] - t[0]) * row[index] / (row[index] - row[index + 1])
            periods.append(2 * (zeros[-1] - zeros[0]) / (len(zeros) - 1))
    return np.array(periods)


# --- the field ---------------------------------------------------------------------------------


@pytest.mark.parametrize("pattern_class", PATTERN_CLASSES)
def test_same_seed_same_pattern_other_seed_other_pattern(pattern_class):
    first = pattern(pattern_class, 0)
    again = make_ridge_pattern(np.random.default_rng(0), LENGTH, HALF_WIDTH, pattern_class=pattern_class)
    assert np.array_equal(first.ridges, again.ridges)
    assert np.array_equal(first.minutiae, again.minutiae)
    assert np.array_equal(first.cores, again.cores) and np.array_equal(first.deltas, again.deltas)
    other = pattern(pattern_class, 1)
    assert np.mean(np.sign(first.ridges) != np.sign(other.ridges)) > 0.3


@pytest.mark.parametrize("pattern_class,seed", CASES)
def test_field_is_a_smooth_even_width_sinusoid_in_range(pattern_class, seed):
    p = pattern(pattern_class, seed)
    assert p.ridges.shape == (521, 601) and p.ridges.dtype == np.float32
    assert np.all(np.isfinite(p.ridges))
    assert p.ridges.min() >= -1.0 and p.ridges.max() <= 1.0
    assert 0.45 < np.mean(p.ridges > 0) < 0.55  # ridges and valleys of even width
    rms = float(np.sqrt(np.mean(p.ridges.astype(np.float64) ** 2)))
    assert 0.6 < rms < 0.8  # a unit sinusoid has RMS 0.707; a square wave 1, a washed-out field less
    slope = 2 * np.pi * p.spacing_mm / p.period_mm  # steepest step of a unit sinusoid per cell
    assert np.percentile(np.abs(np.diff(p.ridges, axis=0)), 99.9) < 1.25 * slope
    assert np.percentile(np.abs(np.diff(p.ridges, axis=1)), 99.9) < 1.25 * slope


@pytest.mark.parametrize("pattern_class,seed,period_mm", [("arch", 0, 0.40), ("loop", 1, 0.45), ("whorl", 2, 0.50)])
def test_measured_ridge_period_matches_period_mm(pattern_class, seed, period_mm):
    p = pattern(pattern_class, seed, period_mm)
    periods = local_periods(p, np.random.default_rng(7))
    assert len(periods) > 500
    assert abs(np.median(periods) / period_mm - 1) < 0.10


# --- minutiae ----------------------------------------------------------------------------------


@pytest.mark.parametrize("pattern_class,seed", CASES)
def test_minutiae_density_is_realistic(pattern_class, seed):
    p = pattern(pattern_class, seed)
    margin = p.period_mm
    area = (p.length_mm - 2 * margin) * (2 * p.half_width_mm - 2 * margin)
    density = len(p.minutiae) / area
    assert 0.08 < density < 0.35, density  # real fingers: ~0.1-0.3 per mm^2
    endings = np.mean(p.minutiae[:, 3] == ENDING)
    assert 0.25 < endings < 0.75  # both kinds well represented


@pytest.mark.parametrize("pattern_class,seed", CASES)
def test_minutiae_are_well_formed_and_away_from_border_and_singular_points(pattern_class, seed):
    p = pattern(pattern_class, seed)
    m = p.minutiae
    assert m.dtype == np.float64 and m.ndim == 2 and m.shape[1] == 4
    assert set(np.unique(m[:, 3])) <= {ENDING, BIFURCATION}
    assert np.all(np.abs(m[:, 2]) <= np.pi)
    slack = p.spacing_mm  # the sub-cell crest refinement moves a minutia by at most half a cell
    assert np.all(m[:, 0] >= p.period_mm - slack) and np.all(m[:, 0] <= p.length_mm - p.period_mm + slack)
    assert np.all(np.abs(m[:, 1]) <= p.half_width_mm - p.period_mm + slack)
    singular = np.concatenate([p.cores, p.deltas])
    if len(singular):
        distance = np.linalg.norm(m[:, None, :2] - singular[None], axis=2).min(axis=1)
        assert np.all(distance > 1.5 * p.period_mm - slack)
    pairwise = np.linalg.norm(m[:, None, :2] - m[None, :, :2], axis=2) + np.eye(len(m)) * 1e9
    assert pairwise.min() > 0.5 * p.period_mm - 2 * slack


@pytest.mark.parametrize("pattern_class,seed", CASES)
def test_every_minutia_is_refound_in_the_reskeletonised_field(pattern_class, seed):
    p = pattern(pattern_class, seed)
    endings, bifurcations = skeleton_minutiae(p.ridges)
    tolerance = 0.25 * p.period_mm / p.spacing_mm
    positions = to_pixels(p, p.minutiae[:, :2])
    for position, kind in zip(positions, p.minutiae[:, 3]):
        candidates = endings if kind == ENDING else bifurcations
        assert np.linalg.norm(candidates - position, axis=1).min() <= tolerance


@pytest.mark.parametrize("pattern_class,seed", CASES)
def test_minutia_angles_point_away_from_the_stem(pattern_class, seed):
    p = pattern(pattern_class, seed)
    m, period = p.minutiae, p.period_mm
    along = np.stack([np.cos(m[:, 2]), np.sin(m[:, 2])], axis=1)  # (da, db)
    across = np.stack([-along[:, 1], along[:, 0]], axis=1)

    def at(kind, forward, sideways=0.0, flip=1.0):
        sel = m[:, 3] == kind
        points = m[sel, :2] + flip * forward * period * along[sel] + sideways * period * across[sel]
        return p.sample(points[:, 0], points[:, 1])

    for flip, expect in ((1.0, "right"), (-1.0, "reversed")):
        # An ending: its ridge lies behind it, the valley it ends in lies ahead.
        ending_ok = (at(ENDING, -0.5, flip=flip) > 0) & (at(ENDING, 0.5, flip=flip) < 0)
        # A bifurcation: the stem lies behind; ahead lies the valley between the two branches,
        # with a branch on either side.
        fork_ok = ((at(BIFURCATION, -0.5, flip=flip) > 0) & (at(BIFURCATION, 0.75, flip=flip) < 0)
                   & (at(BIFURCATION, 0.75, 0.35, flip) > 0) & (at(BIFURCATION, 0.75, -0.35, flip) > 0))
        if expect == "right":
            assert ending_ok.mean() > 0.9 and fork_ok.mean() > 0.8, (ending_ok.mean(), fork_ok.mean())
        else:
            assert ending_ok.mean() < 0.1 and fork_ok.mean() < 0.1, (ending_ok.mean(), fork_ok.mean())


# --- singular points and the orientation model ----------------------------------------------------


@pytest.mark.parametrize("pattern_class,seed", CASES)
def test_singular_points_per_class(pattern_class, seed):
    p = pattern(pattern_class, seed)
    expected = {"arch": (0, 0), "loop": (1, 1), "whorl": (2, 2)}[pattern_class]
    assert (len(p.cores), len(p.deltas)) == expected
    assert p.cores.shape == (expected[0], 2) and p.deltas.shape == (expected[1], 2)
    if pattern_class == "arch":
        return
    centre = p.cores.mean(axis=0)
    assert abs(centre[0] / LENGTH - 0.4) < 0.1 and abs(centre[1]) < 0.25 * HALF_WIDTH
    assert np.all(p.deltas[:, 0] > centre[0])  # deltas lie toward the base
    if pattern_class == "whorl":
        assert np.sign(p.deltas[0, 1] - centre[1]) != np.sign(p.deltas[1, 1] - centre[1])


def winding(model, centre, radius=0.3):
    """Total turn of the orientation (rad) once round a small circle about ``centre``."""
    psi = np.linspace(0, 2 * np.pi, 721)
    theta = orientation_field(model, centre[0] + radius * np.cos(psi), centre[1] + radius * np.sin(psi))
    return np.unwrap(2 * theta)[-1] / 2 - theta[0]


@pytest.mark.parametrize("pattern_class", ["loop", "whorl"])
def test_cores_turn_the_orientation_by_plus_pi_and_deltas_by_minus_pi(pattern_class):
    for seed in range(4):
        model = random_orientation_model(np.random.default_rng(seed), LENGTH, HALF_WIDTH, pattern_class)
        for core in model.cores:
            assert winding(model, core) == pytest.approx(np.pi, abs=1e-6)
        for delta in model.deltas:
            assert winding(model, delta) == pytest.approx(-np.pi, abs=1e-6)


def test_loops_open_away_from_their_delta_on_both_sides():
    sides = set()
    for seed in range(12):
        model = random_orientation_model(np.random.default_rng(seed), LENGTH, HALF_WIDTH, "loop")
        core, delta = model.cores[0], model.deltas[0]
        # The loop's legs run where the ridges around the core are radial.
        psi = np.linspace(-np.pi, np.pi, 720, endpoint=False)
        radius = 1.5
        theta = orientation_field(model, core[0] + radius * np.cos(psi), core[1] + radius * np.sin(psi))
        legs = psi[np.argmin(np.abs(np.sin(theta - psi)))]
        delta_side = np.sign(delta[1] - core[1])
        assert np.sign(np.sin(legs)) == -delta_side
        sides.add(delta_side)
    assert sides == {-1.0, 1.0}  # the delta falls on either side at random


@pytest.mark.parametrize("pattern_class", PATTERN_CLASSES)
def test_ridges_run_across_the_finger_at_tip_and_base(pattern_class):
    model = random_orientation_model(np.random.default_rng(3), LENGTH, HALF_WIDTH, pattern_class)
    b = np.linspace(-HALF_WIDTH, HALF_WIDTH, 61)
    for a in (0.0, LENGTH):
        theta = orientation_field(model, np.full_like(b, a), b)
        assert np.all(np.abs(np.cos(theta)) < np.sin(np.deg2rad(30)))  # within 30 deg of along b


def test_core_a_mm_places_the_core():
    p = make_ridge_pattern(np.random.default_rng(5), 18.0, 9.0, pattern_class="loop", core_a_mm=6.0)
    assert p.cores[0, 0] == pytest.approx(6.0)


# --- sampling and the public boundary -------------------------------------------------------------


def test_sample_is_bilinear_and_clamps_outside_the_grid():
    p = make_ridge_pattern(np.random.default_rng(4), 9.0, 3.87, period_mm=0.4, spacing_mm=0.04, pattern_class="arch")
    rows, cols = p.ridges.shape
    assert p.half_width_mm == 3.87 and p.length_mm == pytest.approx((rows - 1) * 0.04)
    i = np.array([0, 5, rows - 1, 17])
    j = np.array([0, cols - 1, 8, 30])
    a, b = i * p.spacing_mm, -p.half_width_mm + j * p.spacing_mm
    np.testing.assert_allclose(p.sample(a, b), p.ridges[i, j], atol=1e-6)
    mid = p.sample(a[3] + 0.5 * p.spacing_mm, b[3] + 0.5 * p.spacing_mm)
    assert mid == pytest.approx(p.ridges[17:19, 30:32].mean(), abs=1e-6)
    np.testing.assert_allclose(p.sample(-5.0, b), p.sample(0.0, b), atol=1e-7)
    np.testing.assert_allclose(p.sample(a, 100.0), p.sample(a, p.half_width_mm), atol=1e-7)
    grid_a, grid_b = np.meshgrid(np.linspace(0, 9, 3), np.linspace(-3, 3, 4), indexing="ij")
    assert p.sample(grid_a, grid_b).shape == (3, 4)
    assert p.sample(grid_a[..., None], 0.5).shape == (3, 4, 1)


BAD_ARGUMENTS = [
    (dict(pattern_class="tented"), "pattern_class"),
    (dict(period_mm=0.0), "period_mm"),
    (dict(period_mm=-0.4), "period_mm"),
    (dict(period_mm=float("nan")), "period_mm"),
    (dict(period_mm=0.12), "3 grid cells"),
    (dict(spacing_mm=0.0), "spacing_mm"),
    (dict(length_mm=2.0), "10 ridge periods"),
    (dict(half_width_mm=1.0), "10 ridge periods"),
    (dict(half_width_mm=-3.0), "half_width_mm"),
    (dict(core_a_mm=40.0), "core_a_mm"),
    (dict(rng=0), "Generator"),
]


@pytest.mark.parametrize("change,message", BAD_ARGUMENTS)
def test_bad_arguments_raise_value_error(change, message):
    kwargs = dict(rng=np.random.default_rng(0), length_mm=LENGTH, half_width_mm=HALF_WIDTH)
    kwargs.update(change)
    with pytest.raises(ValueError, match=message):
        make_ridge_pattern(**kwargs)


def test_importing_the_ridge_generator_loads_neither_open3d_nor_torch():
    code = ("import sys, fingersplat3d.synth.ridges; "
            "bad = [m for m in ('open3d', 'torch') if m in sys.modules]; assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)
