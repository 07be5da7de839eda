"""Weighted Umeyama and RANSAC similarity: exact recovery, robustness, weights, degenerate input."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingersplat3d.align.solve.procrustes import NoConsensusError, Similarity, ransac_similarity, umeyama
from fingersplat3d.errors import InputError


def random_similarity(rng: np.random.Generator) -> Similarity:
    scale = float(10 ** rng.uniform(-2, 2))  # 0.01 .. 100
    rotation = Rotation.random(random_state=int(rng.integers(2**31))).as_matrix()
    return Similarity(scale, rotation, rng.normal(size=3) * 10)


def rotation_error_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(a @ b.T) - 1) / 2, -1, 1))))


@pytest.mark.parametrize("seed", range(5))
def test_recovers_random_similarity_exactly(seed):
    rng = np.random.default_rng(seed)
    truth = random_similarity(rng)
    src = rng.normal(size=(20, 3))
    fit = umeyama(src, truth.apply(src))
    assert fit.scale == pytest.approx(truth.scale, rel=1e-10)
    np.testing.assert_allclose(fit.rotation, truth.rotation, atol=1e-10)
    np.testing.assert_allclose(fit.translation, truth.translation, atol=1e-9 * (1 + truth.scale))
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0)


def test_rigid_fit_and_matches_scipy_align_vectors_weighted():
    rng = np.random.default_rng(7)
    src = rng.normal(size=(30, 3))
    truth = Similarity(1.0, Rotation.random(random_state=3).as_matrix(), [1.0, -2.0, 0.5])
    dst = truth.apply(src) + rng.normal(scale=0.05, size=src.shape)
    weights = rng.uniform(0.1, 2.0, size=30)
    fit = umeyama(src, dst, weights, with_scale=False)
    assert fit.scale == 1.0
    # Same problem for scipy: rotation of the weighted-centred sets.
    centre_src = np.average(src, axis=0, weights=weights)
    centre_dst = np.average(dst, axis=0, weights=weights)
    reference, _ = Rotation.align_vectors(dst - centre_dst, src - centre_src, weights=weights)
    np.testing.assert_allclose(fit.rotation, reference.as_matrix(), atol=1e-10)
    np.testing.assert_allclose(fit.translation, centre_dst - fit.rotation @ centre_src, atol=1e-10)


def test_weighted_scale_matches_closed_form_svd():
    rng = np.random.default_rng(11)
    src = rng.normal(size=(25, 3))
    dst = rng.normal(size=(25, 3))  # not a similarity: the optimum is still defined
    weights = rng.uniform(0.0, 1.0, size=25)
    fit = umeyama(src, dst, weights)
    w = weights / weights.sum()
    x, y = src - w @ src, dst - w @ dst
    u, s, vt = np.linalg.svd((w[:, None] * y).T @ x)
    d = np.diag([1, 1, np.sign(np.linalg.det(u @ vt))])
    np.testing.assert_allclose(fit.rotation, u @ d @ vt, atol=1e-10)
    assert fit.scale == pytest.approx(np.trace(np.diag(s) @ d) / np.sum(w * (x**2).sum(1)), rel=1e-10)


@pytest.mark.parametrize("magnitude", [1e-6, 1e6])
def test_tiny_and_huge_coordinates_stay_accurate(magnitude):
    rng = np.random.default_rng(2)
    truth = Similarity(3.0, Rotation.random(random_state=5).as_matrix(), rng.normal(size=3) * magnitude)
    src = (rng.normal(size=(15, 3)) + 5.0) * magnitude  # offset from the origin as well
    fit = umeyama(src, truth.apply(src))
    assert fit.scale == pytest.approx(3.0, rel=1e-9)
    np.testing.assert_allclose(fit.rotation, truth.rotation, atol=1e-9)
    np.testing.assert_allclose(fit.translation / magnitude, truth.translation / magnitude, atol=1e-8)


def test_coplanar_points_give_a_proper_rotation():
    rng = np.random.default_rng(4)
    src = np.c_[rng.normal(size=(12, 2)), np.zeros(12)]
    truth = random_similarity(rng)
    fit = umeyama(src, truth.apply(src))
    np.testing.assert_allclose(fit.rotation, truth.rotation, atol=1e-9)
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0)


def test_ransac_with_noise_and_30_percent_outliers():
    rng = np.random.default_rng(0)
    for _ in range(3):
        truth = random_similarity(rng)
        n = 200
        src = rng.normal(size=(n, 3))
        dst = truth.apply(src) + rng.normal(scale=0.005 * truth.scale, size=(n, 3))
        outlier = rng.random(n) < 0.3
        dst[outlier] = truth.apply(rng.normal(size=(outlier.sum(), 3)) * 3)
        fit, inliers = ransac_similarity(src, dst, threshold=0.03 * truth.scale, rng=1)
        assert rotation_error_deg(fit.rotation, truth.rotation) < 0.5
        assert fit.scale == pytest.approx(truth.scale, rel=0.01)
        assert not np.any(inliers & outlier)
        assert np.mean(inliers[~outlier]) > 0.95


def test_weights_decide_which_consensus_wins():
    rng = np.random.default_rng(5)
    first, second = random_similarity(rng), random_similarity(rng)
    src = rng.normal(size=(100, 3))
    dst = first.apply(src)
    majority = np.arange(100) < 60  # 60 points follow `second`, but with negligible weight
    dst[majority] = second.apply(src[majority])
    weights = np.where(majority, 1e-4, 1.0)
    fit, inliers = ransac_similarity(src, dst, weights, threshold=1e-6 * (1 + first.scale), rng=0)
    np.testing.assert_allclose(fit.rotation, first.rotation, atol=1e-8)
    assert np.array_equal(inliers, ~majority)
    # Zero weight: those points are ignored altogether by the plain fit.
    fit = umeyama(src, dst, np.where(majority, 0.0, 1.0))
    np.testing.assert_allclose(fit.rotation, first.rotation, atol=1e-9)


def test_ransac_reproducible_and_reports_no_consensus():
    rng = np.random.default_rng(9)
    src, dst = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    with pytest.raises(NoConsensusError, match="inliers"):
        ransac_similarity(src, dst, threshold=1e-3, min_inliers=10)
    truth = random_similarity(rng)
    dst = truth.apply(src)
    a = ransac_similarity(src, dst, threshold=1e-6 * truth.scale, rng=3)
    b = ransac_similarity(src, dst, threshold=1e-6 * truth.scale, rng=3)
    np.testing.assert_array_equal(a[0].as_matrix(), b[0].as_matrix())


@pytest.mark.parametrize("src, dst, weights, message", [
    (np.zeros((2, 3)), np.zeros((2, 3)), None, "at least 3"),
    (np.outer(np.arange(6.0), [1, 2, 3]), np.outer(np.arange(6.0), [3, 1, 2]), None, "collinear"),
    (np.ones((5, 3)), np.random.default_rng(0).normal(size=(5, 3)), None, "coincide"),
    (np.eye(3), np.eye(3), np.zeros(3), "all zero"),
    (np.array([[np.nan, 0, 0], [1, 0, 0], [0, 1, 0]]), np.eye(3), None, "NaN"),
    (np.eye(3), np.eye(3), np.array([1.0, -1.0, 1.0]), "non-negative"),
    (np.eye(3), np.eye(4)[:, :3], None, "same shape"),
])
def test_degenerate_input_is_a_clear_error(src, dst, weights, message):
    with pytest.raises(InputError, match=message):
        umeyama(src, dst, weights)


def test_ransac_on_collinear_points_says_so():
    line = np.outer(np.arange(10.0), [1.0, 0.5, 0.2])
    with pytest.raises(NoConsensusError, match="collinear"):
        ransac_similarity(line, line * 2, threshold=0.1)


def test_similarity_algebra():
    rng = np.random.default_rng(1)
    t1, t2 = random_similarity(rng), random_similarity(rng)
    points = rng.normal(size=(7, 3))
    np.testing.assert_allclose(t1.inverse().apply(t1.apply(points)), points, atol=1e-9)
    np.testing.assert_allclose((t1 @ t2).apply(points), t1.apply(t2.apply(points)), rtol=1e-10, atol=1e-8)
    homogeneous = np.c_[points, np.ones(7)] @ t1.as_matrix().T
    np.testing.assert_allclose(homogeneous[:, :3], t1.apply(points), rtol=1e-12, atol=1e-9)
    again = Similarity.from_matrix(t1.as_matrix())
    assert again.scale == pytest.approx(t1.scale)
    np.testing.assert_allclose(again.rotation, t1.rotation, atol=1e-12)
    with pytest.raises(ValueError):
        Similarity(0.0, np.eye(3), np.zeros(3))
