"""Global alignment: recovers known cameras from exact correspondences, stays finite at the extremes."""
import numpy as np
import pytest

from fingersplat3d.align.solve.global_opt import GlobalAlignConfig, PairCorrespondences, global_align, spanning_tree
from fingersplat3d.eval import relative_rotation_errors
from fingersplat3d.synth import SynthConfig, synthesize


@pytest.fixture(scope="module")
def capture():
    return synthesize(0, SynthConfig(size=(320, 256))).capture


def _exact_pair(capture, a, b, rng, count=200, noise_px=0.3, tilt=0.0):
    """Ground-truth correspondences a -> b and a perturbed initial relative pose."""
    from scipy.spatial.transform import Rotation

    va, vb = capture.views[a], capture.views[b]
    pixels = np.argwhere(va.mask)[:, ::-1]
    pixels = pixels[rng.choice(len(pixels), 4000)].astype(np.float64)
    points = va.camera.unproject(pixels, va.depth[pixels[:, 1].astype(int), pixels[:, 0].astype(int)])
    uv, z = vb.camera.project(points)
    inside = np.all(np.isfinite(uv), 1) & (uv[:, 0] > 0) & (uv[:, 0] < vb.width - 1) & (uv[:, 1] > 0) & (uv[:, 1] < vb.height - 1)
    seen = np.full(len(uv), np.inf)
    seen[inside] = vb.depth[np.round(uv[inside, 1]).astype(int), np.round(uv[inside, 0]).astype(int)]
    visible = np.abs(seen - z) < 0.05
    uv_a, uv_b = pixels[visible][:count], uv[visible][:count] + rng.normal(0, noise_px, (min(count, visible.sum()), 2))
    b_to_a = va.camera.world_to_cam @ vb.camera.cam_to_world
    b_to_a[:3, :3] = Rotation.from_rotvec(rng.normal(0, tilt, 3)).as_matrix() @ b_to_a[:3, :3]
    return PairCorrespondences(a, b, uv_a, uv_b, np.ones(len(uv_a)), b_to_a)


def test_recovers_rotations_from_exact_depth_and_correspondences(capture):
    rng = np.random.default_rng(0)
    pairs = [_exact_pair(capture, 0, 1, rng, tilt=0.03), _exact_pair(capture, 1, 2, rng, tilt=0.03)]
    depths = [v.depth for v in capture.views]
    focal = capture.views[0].camera.K[0, 0]
    result = global_align(depths, focal, pairs, GlobalAlignConfig(iterations=150))
    errors = relative_rotation_errors(result.world_to_cam, [v.camera.world_to_cam for v in capture.views])
    assert np.max(errors) < 2.5  # from ~2.5 degrees of initial error per pair
    assert result.residual_px < 1.0
    assert all(result.aligned) and np.isfinite(result.loss_history).all()
    assert result.loss_history[-1] < result.loss_history[0]


def test_no_pairs_keeps_views_apart_and_finite(capture):
    depths = [v.depth for v in capture.views]
    result = global_align(depths, 500.0, [])
    assert result.aligned == [True, False, False] or sum(result.aligned) == 1
    assert all(np.isfinite(p).all() for p in result.cam_to_world)
    assert np.isnan(result.residual_px)


@pytest.mark.parametrize("focal", [1e-3, 1e7])
def test_extreme_focal_guesses_stay_finite(capture, focal):
    rng = np.random.default_rng(1)
    pairs = [_exact_pair(capture, 0, 1, rng)]
    result = global_align([v.depth for v in capture.views[:2]], focal, pairs, GlobalAlignConfig(iterations=30, polish_iterations=10))
    assert all(np.isfinite(p).all() for p in result.cam_to_world) and np.isfinite(result.focals).all()
    assert all(np.isfinite(d[np.isfinite(capture.views[i].depth)]).all() for i, d in enumerate(result.depths))


def test_zero_weights_and_nan_depth_stay_finite(capture):
    rng = np.random.default_rng(2)
    pair = _exact_pair(capture, 0, 1, rng)
    zero = PairCorrespondences(0, 1, pair.uv_a, pair.uv_b, np.zeros(len(pair.weight)), pair.b_to_a)
    depths = [np.full_like(capture.views[0].depth, np.nan), capture.views[1].depth]
    for pairs, maps in (([zero], [v.depth for v in capture.views[:2]]), ([pair], depths)):
        result = global_align(maps, 300.0, pairs, GlobalAlignConfig(iterations=20, polish_iterations=5))
        assert all(np.isfinite(p).all() for p in result.cam_to_world)


def test_spanning_tree_prefers_strong_pairs_and_skips_disconnected():
    def pair(a, b, n):
        return PairCorrespondences(a, b, np.zeros((n, 2)), np.zeros((n, 2)), np.ones(n), np.eye(4))

    root, edges = spanning_tree(4, [pair(0, 1, 5), pair(1, 2, 50), pair(0, 2, 10)])
    assert root in (1, 2) and len(edges) == 2 and 3 not in {v for e in edges for v in e}


def _bowed(view, share):
    """The view's true depth with a bowl across the finger (``share`` of its median depth at the middle, 0 at the
    outline's top and bottom rows): a section the pointmap prior gets wrong."""
    depth = view.depth.astype(np.float64)
    rows = np.where(view.mask.any(1))[0]
    across = (np.arange(depth.shape[0])[:, None] - rows.mean()) / (0.5 * (rows.max() - rows.min()))
    return depth + share * np.nanmedian(depth) * (1 - across ** 2)


def test_fields_take_up_a_section_unlike_the_pointmaps(capture):
    """Three views on pointmaps bowed by 3 % of their depth: the depth fields bend to take the difference up, so the
    turns and the focal stay where the correspondences put them (held stiff, as before stop 78: 0.61 degrees off,
    the focal 15 % long)."""
    rng = np.random.default_rng(0)
    pairs = [_exact_pair(capture, a, b, rng, tilt=0.03) for a, b in ((0, 1), (1, 2), (0, 2))]
    focal = capture.views[0].camera.K[0, 0]
    result = global_align([_bowed(v, 0.03) for v in capture.views], focal, pairs)
    errors = relative_rotation_errors(result.world_to_cam, [v.camera.world_to_cam for v in capture.views])
    assert np.max(errors) < 0.3
    assert abs(result.focals[0] / focal - 1) < 0.05


def test_two_views_keep_stiffer_fields(capture):
    from fingersplat3d.align.solve.global_opt import _state_of, alignment_problem, field_grids

    rng = np.random.default_rng(0)
    config = GlobalAlignConfig()
    depths = [v.depth for v in capture.views]
    focal = capture.views[0].camera.K[0, 0]
    for count, expected in ((2, config.two_view_field_smoothness), (3, config.field_smoothness)):
        pairs = [_exact_pair(capture, a, a + 1, rng) for a in range(count - 1)]
        solved = global_align(depths[:count], focal, pairs, config)
        problem, _ = alignment_problem(depths[:count], np.full(count, focal), pairs, config, field_grids(depths[:count], config),
                                       _state_of(solved), solved.aligned, solved.root)
        assert problem.field_smoothness == expected
    assert config.two_view_field_smoothness > config.field_smoothness


def test_three_views_of_which_two_stand_in_one_place_keep_the_two_view_fields(capture):
    """Two views a degree apart hold no more relief than one: beside a third, the fields stay as stiff as two views'
    (another group's renders at rolls 47 and 48 with a third, docs/measurements.md, stop 84); the pivot and the turn
    bound keep the view count."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    from fingersplat3d.align.solve.global_opt import _state_of, alignment_problem, field_grids

    rng = np.random.default_rng(0)
    config = GlobalAlignConfig()
    depths = [v.depth for v in capture.views]
    focal = capture.views[0].camera.K[0, 0]
    pairs = [_exact_pair(capture, a, b, rng) for a, b in ((0, 1), (1, 2))]
    solved = global_align(depths, focal, pairs, config)
    state = _state_of(solved)
    rotations = np.asarray(state.rotations, np.float64).copy()  # cam_to_world: view 2 one degree from view 1
    rotations[2] = Rotation.from_euler("y", 1.0, degrees=True).as_matrix() @ rotations[1]
    for initial, expected in ((state, config.field_smoothness), (replace(state, rotations=rotations),
                                                                  config.two_view_field_smoothness)):
        problem, _ = alignment_problem(depths, np.full(3, focal), pairs, config, field_grids(depths, config), initial,
                                       solved.aligned, solved.root)
        assert problem.field_smoothness == expected and problem.pivot is not None
