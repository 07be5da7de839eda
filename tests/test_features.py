"""Image matching between finger photos, checked against the synthetic ground truth.

Bounds were measured with a matcher benchmark (since folded away; git history) (uwa 640x512, seeds 0..9, default ``minutiae``
method): a 45-degree pair that returns matches returns 12..46 of them, median ground-truth error
0.4..0.9 px; 3 of 20 such pairs return none; every 90-degree pair returns none. Seed 0's
left-center pair gives 35 matches, median 0.7 px.
"""
import numpy as np
import pytest

from fingersplat3d.align.correspond.features import Matches, match_views
from fingersplat3d.align.correspond.texture import estimate_ridge_period
from fingersplat3d.errors import InputError
from fingersplat3d.synth import Appearance, SynthConfig, synthesize

# The classic matchers need crisp, high-contrast ridges: the generator's earlier look. On its
# real-looking default (faint ridges, soft optics, glints), as on real photos, ``minutiae`` finds
# next to nothing; the default ``surface`` registration is tested in test_register.py.
CRISP = Appearance(ridge_contrast=0.35, relief_mm=0.02, blur_px=0.6, noise=0.012, glints=0.0, wrinkles=0.0)


@pytest.fixture(scope="module")
def uwa():
    return synthesize(0, SynthConfig(size=(640, 512), appearance=CRISP)).capture


def gt_errors(view_a, view_b, uv_a, uv_b):
    """Pixel error of each match against the exact depth and cameras (inf when hidden in b)."""
    def bilinear(image, uv):
        u0, v0 = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        fu, fv = uv[:, 0] - u0, uv[:, 1] - v0
        return (image[v0, u0] * (1 - fu) * (1 - fv) + image[v0, u0 + 1] * fu * (1 - fv)
                + image[v0 + 1, u0] * (1 - fu) * fv + image[v0 + 1, u0 + 1] * fu * fv)

    world = view_a.camera.unproject(uv_a, bilinear(view_a.depth.astype(np.float64), uv_a))
    projected, z = view_b.camera.project(world)
    error = np.linalg.norm(projected - uv_b, axis=1)
    inside = np.all((projected >= 0) & (projected < [view_b.width - 1, view_b.height - 1]), axis=1)
    seen = np.full(len(uv_a), np.nan)
    seen[inside] = bilinear(view_b.depth.astype(np.float64), projected[inside])
    error[~(np.abs(seen - z) < 0.01 * z)] = np.inf
    return error


def test_45_degree_pair_gives_accurate_matches(uwa):
    left, center = uwa["left"], uwa["center"]
    matches = match_views(left.image, left.mask, center.image, center.mask)
    assert isinstance(matches, Matches) and matches.method == "minutiae"
    assert len(matches) >= 20
    errors = gt_errors(left, center, matches.uv_a, matches.uv_b)
    assert np.median(errors) < 1.5
    assert np.mean(errors < 2.0) >= 0.7
    assert matches.uv_a.dtype == np.float64 and matches.uv_a.shape == (len(matches), 2)
    assert np.all((matches.score > 0) & (matches.score <= 1))
    assert matches.n_putative >= len(matches) // 3


def test_90_degree_pair_returns_no_garbage(uwa):
    left, right = uwa["left"], uwa["right"]
    matches = match_views(left.image, left.mask, right.image, right.mask)
    if len(matches) > 5:  # anything it does return must be right
        assert np.mean(gt_errors(left, right, matches.uv_a, matches.uv_b) < 2.0) > 0.8


def test_sift_baseline_runs_and_is_well_formed(uwa):
    center, right = uwa["center"], uwa["right"]
    matches = match_views(center.image, center.mask, right.image, right.mask, method="sift", max_matches=10)
    assert len(matches) <= 10
    assert np.all(np.isfinite(matches.uv_a)) and np.all((matches.score > 0) & (matches.score <= 1))
    swapped = matches.swapped()
    np.testing.assert_array_equal(swapped.uv_a, matches.uv_b)


def test_identical_images_match_in_place(uwa):
    view = uwa["center"]
    matches = match_views(view.image, view.mask, view.image, view.mask)
    assert len(matches) >= 20
    assert np.max(np.linalg.norm(matches.uv_a - matches.uv_b, axis=1)) < 0.5


def test_featureless_images_give_no_matches():
    flat = np.full((96, 128), 0.5, np.float32)
    matches = match_views(flat, None, flat, None)
    assert len(matches) == 0 and matches.uv_a.shape == (0, 2)


def test_ridge_period_of_a_sinusoid():
    u, v = np.meshgrid(np.arange(256), np.arange(200))
    image = 0.5 + 0.3 * np.sin(2 * np.pi * (0.8 * u + 0.6 * v) / 7.0)
    assert estimate_ridge_period(image) == pytest.approx(7.0, rel=0.03)


def test_bad_input_is_a_clear_error(uwa):
    view = uwa["center"]
    with pytest.raises(InputError, match="mask a is"):
        match_views(view.image, view.mask[:-1], view.image, view.mask)
    with pytest.raises(InputError, match="mask b is empty"):
        match_views(view.image, view.mask, view.image, np.zeros_like(view.mask))
    with pytest.raises(InputError, match="NaN"):
        match_views(np.full((8, 8), np.nan), None, view.image, view.mask)
    with pytest.raises(InputError, match="unknown matching method"):
        match_views(view.image, view.mask, view.image, view.mask, method="magic")
