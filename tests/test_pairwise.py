"""Pair registration from matched pixels of two own-frame pointmaps, against the synthetic ground truth.

Measured with a matcher benchmark (uwa 640x512; the script is in git history): on pointmaps from the exact depth the
relative rotation comes out within 0.1..0.3 degrees; with the relief scaled 1.3x (a wrong
cross-section) it degrades to 10..11 degrees.
"""
import numpy as np
import pytest

from fingersplat3d.align.correspond.features import Matches, match_views
from fingersplat3d.align.solve.pairwise import PairRegistration, register_pair, sample_pointmap
from fingersplat3d.errors import InputError
from fingersplat3d.pointmaps.base import Pointmap
from fingersplat3d.synth import Appearance, SynthConfig, synthesize

# The classic matchers need crisp, high-contrast ridges: the generator's earlier look. On its
# real-looking default (faint ridges, soft optics, glints), as on real photos, ``minutiae`` finds
# next to nothing; the default ``surface`` registration is tested in test_register.py.
CRISP = Appearance(ridge_contrast=0.35, relief_mm=0.02, blur_px=0.6, noise=0.012, glints=0.0, wrinkles=0.0)


def gt_pointmap(view, index, relief=1.0):
    """Own-frame points ``depth * K^-1 [u, v, 1]`` from the exact depth (relief scaled about the mean)."""
    depth = view.depth.astype(np.float64)
    if relief != 1.0:
        mean = np.nanmean(depth[view.mask])
        depth = mean + relief * (depth - mean)
    u, v = np.meshgrid(np.arange(view.width, dtype=np.float64), np.arange(view.height, dtype=np.float64))
    rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(view.camera.K).T
    points = (rays * depth[..., None]).astype(np.float32)
    confidence = np.isfinite(depth).astype(np.float32)
    return Pointmap(index, points, confidence, float(view.camera.K[0, 0]))


def relative_rotation(view_a, view_b):
    return view_a.camera.rotation @ view_b.camera.rotation.T


def angle_deg(rotation):
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1))))


@pytest.fixture(scope="module")
def pair():
    capture = synthesize(0, SynthConfig(size=(640, 512), appearance=CRISP)).capture
    left, center = capture["left"], capture["center"]
    matches = match_views(left.image, left.mask, center.image, center.mask)
    return left, center, matches


def test_exact_pointmaps_recover_the_relative_pose(pair):
    left, center, matches = pair
    result = register_pair(gt_pointmap(left, 0), gt_pointmap(center, 1), matches)
    assert isinstance(result, PairRegistration) and result.ok and result.reason == ""
    assert (result.a, result.b) == (0, 1)
    truth = relative_rotation(left, center)
    assert angle_deg(result.b_to_a.rotation @ truth.T) < 0.5
    assert result.b_to_a.scale == pytest.approx(1.0, abs=0.01)  # both maps are in mm
    translation = left.camera.translation - truth @ center.camera.translation
    assert np.linalg.norm(result.b_to_a.translation - translation) < 0.01 * np.linalg.norm(translation)
    assert result.n_inliers == len(result.uv_a) == len(result.uv_b) == len(result.weight) >= 12
    assert np.all(result.weight > 0) and 0 <= result.residual < 0.02
    assert result.matrix.shape == (4, 4)


def test_wrong_relief_degrades_rotation_gracefully(pair):
    left, center, matches = pair
    result = register_pair(gt_pointmap(left, 0, 1.3), gt_pointmap(center, 1, 1.3), matches)
    assert result.ok
    assert angle_deg(result.b_to_a.rotation @ relative_rotation(left, center).T) < 15.0


def test_too_few_or_unusable_matches_fail_without_raising(pair):
    left, center, matches = pair
    pointmap_a, pointmap_b = gt_pointmap(left, 0), gt_pointmap(center, 1)
    few = Matches(matches.uv_a[:4], matches.uv_b[:4], matches.score[:4], "minutiae")
    result = register_pair(pointmap_a, pointmap_b, few)
    assert not result.ok and "at least" in result.reason and result.n_inliers == 0
    assert np.isnan(result.residual) and result.uv_a.shape == (0, 2)
    off_finger = Matches(np.zeros((30, 2)), np.zeros((30, 2)), np.ones(30), "minutiae")  # background corner
    assert not register_pair(pointmap_a, pointmap_b, off_finger).ok


def test_random_matches_are_rejected(pair):
    left, center, _ = pair
    rng = np.random.default_rng(0)
    pick = lambda view: np.argwhere(view.mask)[rng.integers(0, view.mask.sum(), 40)][:, ::-1].astype(float)  # noqa: E731
    garbage = Matches(pick(left), pick(center), np.ones(40), "minutiae")
    result = register_pair(gt_pointmap(left, 0), gt_pointmap(center, 1), garbage)
    assert not result.ok and result.reason


def test_sample_pointmap_bilinear_nearest_and_outside():
    height, width = 6, 8
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    points = np.stack([u, 2 * v, u + v + 10], axis=-1).astype(np.float32)  # linear in (u, v)
    confidence = np.ones((height, width), np.float32)
    points[0, 0] = np.nan
    confidence[0, 0] = 0
    pointmap = Pointmap(0, points, confidence, 10.0)
    uv = np.array([[2.25, 3.5], [0.6, 0.6], [0.0, 0.0], [-3.0, 1.0], [np.nan, 1.0]])
    sampled, conf = sample_pointmap(pointmap, uv)
    np.testing.assert_allclose(sampled[0], [2.25, 7.0, 15.75], atol=1e-5)
    np.testing.assert_allclose(sampled[1], [1.0, 2.0, 12.0])  # a NaN neighbour: nearest valid pixel
    assert np.all(np.isnan(sampled[2:])) and np.all(conf[2:] == 0)


def test_bad_input_types_raise(pair):
    left, center, matches = pair
    with pytest.raises(InputError):
        register_pair(gt_pointmap(left, 0), "not a pointmap", matches)
    with pytest.raises(InputError):
        register_pair(gt_pointmap(left, 0), gt_pointmap(center, 1), matches, thresholds=(-1.0,))
