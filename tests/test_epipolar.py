"""The guarded fundamental matrix: data that admit no model are a failed estimate, never an exception."""
import numpy as np
import pytest

from fingersplat3d.align.correspond.epipolar import fundamental_inliers, sampson_distance


@pytest.mark.parametrize("uv_a, uv_b", [
    (np.zeros((0, 2)), np.zeros((0, 2))),  # nothing
    (np.ones((5, 2)), np.ones((5, 2))),  # too few
    (np.ones((40, 2)), np.ones((40, 2)) * 3),  # all points identical
    (np.stack([np.arange(40.0), np.arange(40.0)], 1), np.stack([np.arange(40.0), 2 * np.arange(40.0)], 1)),  # collinear
    (np.full((20, 2), np.nan), np.ones((20, 2))),  # not finite
])
def test_degenerate_correspondences_fail_quietly(uv_a, uv_b):
    F, inliers = fundamental_inliers(uv_a, uv_b, 1.0)
    assert F is None or np.isfinite(F).all()
    assert inliers.shape == (len(uv_a),) and inliers.dtype == bool


def test_a_true_two_view_geometry_is_found_and_outliers_rejected():
    rng = np.random.default_rng(0)
    points = rng.uniform([-1, -1, 4], [1, 1, 6], (200, 3))
    angle = np.radians(30)
    rotation = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    moved = points @ rotation.T + [1.0, 0.0, 0.5]
    uv_a, uv_b = 500 * points[:, :2] / points[:, 2:] + 320, 500 * moved[:, :2] / moved[:, 2:] + 240
    uv_b[:20] += rng.uniform(20, 40, (20, 2))
    F, inliers = fundamental_inliers(uv_a, uv_b, 1.0)
    assert F is not None and not inliers[:20].any() and inliers[20:].mean() > 0.95
    assert np.median(sampson_distance(F, uv_a[20:], uv_b[20:])) < 0.1
