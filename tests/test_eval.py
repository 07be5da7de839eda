"""Depth and pose metrics: exact recovery of known relations, and numerically stable angles."""
import numpy as np
import pytest

from fingersplat3d.eval.depth import DepthErrors, align_scale, align_scale_shift, depth_errors, errors_by_backing
from fingersplat3d.eval.poses import (relative_rotation_errors, rotation_angle_deg, translation_direction_errors,
                                      vector_angle_deg, view_pairs, view_turn_deg)
from fingersplat3d.scene import look_at
from fingersplat3d.synth.rigs import rotation_about


def _gt_depth(seed: int = 0, shape=(48, 64)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:shape[0], 0:shape[1]]
    depth = 300.0 + 5.0 * np.cos(u / 9.0) + 3.0 * np.sin(v / 7.0) + 0.1 * rng.standard_normal(shape)
    depth[:5] = np.nan  # background rows
    return depth.astype(np.float32)


def test_scale_shift_recovers_an_exact_affine_relation():
    gt = _gt_depth()
    pred = (gt - 290.0) / 2.5  # relative depth: gt = 2.5 * pred + 290
    pred[10, 10] = np.nan
    scale, shift = align_scale_shift(pred, gt)
    assert scale == pytest.approx(2.5, rel=1e-5) and shift == pytest.approx(290.0, rel=1e-6)
    errors = depth_errors(pred, gt)
    assert isinstance(errors, DepthErrors)
    assert errors.mae < 1e-4 and errors.rmse < 1e-4 and errors.p90_abs < 1e-4
    assert errors.n == np.isfinite(gt).sum() - 1
    assert errors.coverage == pytest.approx(errors.n / np.isfinite(gt).sum())


def test_scale_only_and_no_alignment():
    gt = _gt_depth()
    assert align_scale(gt / 4.0, gt) == pytest.approx(4.0, rel=1e-6)
    assert depth_errors(gt / 4.0, gt, align="scale").mae < 1e-4
    errors = depth_errors(gt + 1.5, gt, align="none")
    assert (errors.scale, errors.shift) == (1.0, 0.0)
    assert errors.mae == pytest.approx(1.5, abs=1e-4) and errors.median_abs == pytest.approx(1.5, abs=1e-4)


def test_noise_level_is_recovered_after_alignment():
    gt = _gt_depth(shape=(200, 300))
    noise = np.random.default_rng(1).normal(0.0, 0.2, gt.shape)
    pred = 0.01 * (gt + noise) - 2.0  # arbitrary units, noise of 0.2 mm in gt units
    errors = depth_errors(pred, gt)
    assert errors.rmse == pytest.approx(0.2, rel=0.03)
    assert errors.mae == pytest.approx(0.2 * np.sqrt(2 / np.pi), rel=0.03)
    assert errors.median_abs == pytest.approx(0.2 * 0.6745, rel=0.05)
    assert errors.p90_abs == pytest.approx(0.2 * 1.6449, rel=0.05)


def test_mask_coverage_and_weights():
    gt = _gt_depth()
    pred = gt.copy()
    pred[:, :32] = np.nan  # prediction covers half the image
    mask = np.zeros(gt.shape, bool)
    mask[:, 16:48] = True
    errors = depth_errors(pred, gt, mask=mask)
    assert errors.coverage == pytest.approx(0.5) and errors.n == np.isfinite(gt[:, 32:48]).sum()
    # Weights: an outlier with zero weight changes nothing; equal weights match no weights.
    corrupted = gt + 0.0
    corrupted[20, 20] += 50.0
    weights = np.ones(gt.shape)
    weights[20, 20] = 0.0
    assert depth_errors(corrupted, gt, weights=weights).mae < 1e-4
    plain, weighted = depth_errors(corrupted, gt), depth_errors(corrupted, gt, weights=np.full(gt.shape, 3.0))
    assert weighted.weighted and not plain.weighted
    for name in ("mae", "rmse", "median_abs", "scale", "shift"):
        assert getattr(weighted, name) == pytest.approx(getattr(plain, name), rel=1e-6, abs=1e-9)
    assert weighted.p90_abs == pytest.approx(plain.p90_abs, rel=1e-3)  # midpoint vs linear quantile rule
    # Weights that repeat pixels give the statistics of the repeated sample.
    pred, truth = gt[10:12, 10:14].ravel(), gt[10:12, 10:14].ravel() + np.arange(8.0)
    twice = np.r_[np.ones(4), 2 * np.ones(4)]
    repeated = depth_errors(np.r_[pred, pred[4:]], np.r_[truth, truth[4:]], align="none")
    by_weight = depth_errors(pred, truth, align="none", weights=twice)
    assert by_weight.mae == pytest.approx(repeated.mae) and by_weight.rmse == pytest.approx(repeated.rmse)
    assert by_weight.median_abs == pytest.approx(repeated.median_abs)


def test_depth_errors_refuse_bad_input():
    gt = _gt_depth()
    with pytest.raises(ValueError, match="shape"):
        depth_errors(gt[:, :10], gt)
    with pytest.raises(ValueError, match="no pixel in common"):
        depth_errors(np.full(gt.shape, np.nan), gt)
    with pytest.raises(ValueError, match="align must be one of"):
        depth_errors(gt, gt, align="affine")
    with pytest.raises(ValueError, match="mask"):
        depth_errors(gt, gt, mask=np.ones((3, 3), bool))


def test_errors_split_by_a_second_views_backing_count_each_scored_pixel_once():
    from fingersplat3d.align.transfer import backing_on

    error = np.array([[1.0, 2.0, 3.0, np.nan], [4.0, 5.0, 6.0, 7.0]])
    backing = np.array([[1, 1, 0, 1], [0, -1, 0, 1]], np.int8)  # -1: no surface, in neither part
    split = errors_by_backing(error, backing)
    assert split.mae_two_views == pytest.approx((1 + 2 + 7) / 3) and split.mae_one_view == pytest.approx((3 + 4 + 6) / 3)
    assert split.share_two_views == pytest.approx(3 / 6)  # the NaN error and the -1 cell count nowhere
    alone = errors_by_backing(error, np.zeros_like(backing))  # a single photo: nothing backed
    assert alone.share_two_views == 0 and np.isnan(alone.mae_two_views) and np.isfinite(alone.mae_one_view)
    with pytest.raises(ValueError, match="shape"):
        errors_by_backing(error, backing[:, :3])
    # A map at a stride, on a finer grid: every cell becomes a block of its own value, nothing else appears.
    fine = backing_on(backing, (8, 16))
    assert fine.shape == (8, 16) and fine.dtype == np.int8 and set(np.unique(fine)) == {-1, 0, 1}
    assert (fine[::4, ::4] == backing).all() and (fine[4:8, 4:8] == -1).all()


def test_constant_prediction_is_scored_by_the_spread_of_the_truth():
    gt = _gt_depth()
    errors = depth_errors(np.full(gt.shape, 7.0), gt)
    assert np.isfinite(errors.scale) and errors.scale == 1.0
    assert errors.rmse == pytest.approx(np.nanstd(gt.astype(np.float64)), rel=1e-6)


def _random_rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize("degrees", [0.0, np.degrees(1e-8), 1e-3, 90.0, 179.999, 180.0])
def test_rotation_angle_is_accurate_over_the_whole_range(degrees):
    rng = np.random.default_rng(3)
    for _ in range(5):
        base = _random_rotation(rng)
        axis = rng.standard_normal(3)
        rotated = rotation_about(axis / np.linalg.norm(axis), degrees) @ base
        angle = rotation_angle_deg(rotated, base)
        assert angle == pytest.approx(degrees, rel=1e-6, abs=1e-12)
        assert rotation_angle_deg(base, rotated) == pytest.approx(angle, rel=1e-9, abs=1e-12)
    assert rotation_angle_deg(base, base) < 1e-12


def test_rotation_angle_of_identical_and_stacked_rotations():
    assert rotation_angle_deg(np.eye(3), np.eye(3)) == 0.0
    stack = np.stack([rotation_about(np.array([0.0, 0.0, 1.0]), a) for a in (10.0, 20.0, 30.0)])
    np.testing.assert_allclose(rotation_angle_deg(stack, np.eye(3)), [10.0, 20.0, 30.0], rtol=1e-12)
    with pytest.raises(ValueError, match="3, 3"):
        rotation_angle_deg(np.eye(4), np.eye(3))


def test_vector_angle():
    assert vector_angle_deg([1, 0, 0], [0, 2, 0]) == pytest.approx(90.0)
    assert vector_angle_deg([1, 0, 0], [-1, 1e-9, 0]) == pytest.approx(180.0, abs=1e-6)
    assert np.isnan(vector_angle_deg([0, 0, 0], [1, 0, 0]))


@pytest.mark.parametrize("roll", [0.0, 90.0, -90.0, 25.0, 179.0])
def test_view_turn_is_the_optical_axes_angle_whatever_the_roll(roll):
    """A side camera 45° round the finger whose photo is turned in its plane turns 45° about the finger, rolled
    ``roll``; the rotation's own angle mixes the two."""
    from scipy.spatial.transform import Rotation

    a = Rotation.from_euler("y", 10.0, degrees=True)
    b = Rotation.from_euler("z", roll, degrees=True) * Rotation.from_euler("y", 45.0, degrees=True) * a
    turn, rolled = view_turn_deg(a.as_matrix(), b.as_matrix())
    assert turn == pytest.approx(45.0, abs=1e-9) and rolled == pytest.approx(roll, abs=1e-9)
    own = rotation_angle_deg(b.as_matrix() @ a.as_matrix().T, np.eye(3))
    assert own >= turn - 1e-9 and (roll == 0.0) == (own == pytest.approx(45.0, abs=1e-6))
    assert view_turn_deg(b.as_matrix(), a.as_matrix())[0] == pytest.approx(45.0, abs=1e-9)  # either way round


def _rig(count: int = 4) -> list[np.ndarray]:
    poses = []
    for index in range(count):
        angle = np.radians(-45.0 + 30.0 * index)
        eye = 120.0 * np.array([np.sin(angle), 0.2 * index, -np.cos(angle)])
        poses.append(look_at(eye, [0.0, 0.0, 0.0], [0.0, -1.0, 0.0]))
    return poses


def _similarity(rng, scale: float) -> tuple[np.ndarray, float]:
    """A world change ``x' = scale * (G x)``; poses become ``world_to_cam' = S(T G^-1 / scale)``."""
    G = np.eye(4)
    G[:3, :3] = _random_rotation(rng)
    G[:3, 3] = rng.normal(0, 50, 3)
    return G, scale


def _moved(pose: np.ndarray, G: np.ndarray, scale: float) -> np.ndarray:
    moved = pose @ np.linalg.inv(G)
    moved[:3, 3] *= scale  # camera frame keeps its orientation; the world (and baselines) scale
    return moved


def test_relative_errors_vanish_under_a_global_similarity():
    gt = _rig()
    G, scale = _similarity(np.random.default_rng(5), 0.037)
    pred = [_moved(pose, G, scale) for pose in gt]
    rotation = relative_rotation_errors(pred, gt)
    translation = translation_direction_errors(pred, gt)
    assert rotation.shape == translation.shape == (6,)
    assert np.all(rotation < 1e-9) and np.all(translation < 1e-9)
    np.testing.assert_array_equal(view_pairs(4)[:3], [[0, 1], [0, 2], [0, 3]])


def test_the_world_similarity_takes_a_reconstructions_world_onto_the_true_one():
    from fingersplat3d.eval.poses import world_similarity

    gt = _rig()
    G, scale = _similarity(np.random.default_rng(6), 0.037)
    pred = [_moved(pose, G, scale) for pose in gt]  # pred world = scale * G (true world)
    found = world_similarity(pred, gt)
    points = np.random.default_rng(7).normal(0, 30, (20, 3))
    in_pred = scale * (points @ G[:3, :3].T + G[:3, 3])
    np.testing.assert_allclose(found.apply(in_pred), points, atol=1e-6)
    with pytest.raises(ValueError, match="two views"):
        world_similarity(pred[:1], gt[:1])


def test_relative_rotation_error_equals_a_known_perturbation():
    gt = _rig()
    pred = [pose.copy() for pose in gt]
    tilt = rotation_about(np.array([0.3, 1.0, -0.2]) / np.linalg.norm([0.3, 1.0, -0.2]), 2.5)
    pred[2][:3, :3] = tilt @ pred[2][:3, :3]  # camera 2 turned by 2.5 degrees about its own centre...
    pred[2][:3, 3] = tilt @ pred[2][:3, 3]  # ...so its centre stays where it was
    errors = relative_rotation_errors(pred, gt)
    touches_two = (view_pairs(4) == 2).any(axis=1)
    np.testing.assert_allclose(errors[touches_two], 2.5, rtol=1e-9)
    assert np.all(errors[~touches_two] < 1e-9)


def test_translation_direction_error_equals_a_known_baseline_rotation():
    gt = _rig(2)
    pred = [gt[0].copy(), gt[1].copy()]
    baseline = gt[0][:3, 3] - gt[0][:3, :3] @ gt[1][:3, :3].T @ gt[1][:3, 3]  # t_01
    axis = np.cross(baseline, [0.0, 0.0, 1.0])
    turned = rotation_about(axis / np.linalg.norm(axis), 7.0) @ baseline * 3.0  # turned 7 degrees, longer
    pred[0][:3, 3] += turned - baseline  # move camera 0 so that t_01 becomes `turned`
    assert translation_direction_errors(pred, gt)[0] == pytest.approx(7.0, rel=1e-9)
    assert relative_rotation_errors(pred, gt)[0] < 1e-9


def test_pose_errors_refuse_bad_input_and_handle_degenerate_cases():
    gt = _rig(3)
    with pytest.raises(ValueError, match="2 predicted poses but 3"):
        relative_rotation_errors(gt[:2], gt)
    with pytest.raises(ValueError, match="4x4"):
        translation_direction_errors([pose[:3] for pose in gt], gt)
    with pytest.raises(ValueError, match="NaN"):
        relative_rotation_errors([np.full((4, 4), np.nan)] * 3, gt)
    assert relative_rotation_errors(gt[:1], gt[:1]).shape == (0,)
    coincident = [gt[0], gt[0].copy(), gt[2]]
    coincident[1][:3, :3] = rotation_about(np.array([0.0, 1.0, 0.0]), 5.0) @ coincident[1][:3, :3]
    coincident[1][:3, 3] = rotation_about(np.array([0.0, 1.0, 0.0]), 5.0) @ coincident[1][:3, 3]
    errors = translation_direction_errors(coincident, gt)
    assert np.isnan(errors[0]) and np.all(np.isfinite(errors[1:]))


def test_metrics_are_pure_numpy():
    import subprocess
    import sys

    code = ("import sys, fingersplat3d.eval.depth, fingersplat3d.eval.poses; "
            "print(sorted(m for m in ('open3d', 'torch', 'cv2') if m in sys.modules))")
    output = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert output.strip() == "[]"
