"""Levenberg-Marquardt of the global alignment: its hand-built Jacobian against autograd, and what it solves."""
import numpy as np
import pytest
import torch

from fingersplat3d.align.solve.global_opt import (GlobalAlignConfig, alignment_problem, field_grids, global_align,
                                                  reached, spanning_tree)
from fingersplat3d.align.solve.levenberg import _system, levenberg_marquardt
from fingersplat3d.eval import relative_rotation_errors
from fingersplat3d.synth import SynthConfig, synthesize

from test_global_opt import _exact_pair


@pytest.fixture(scope="module")
def capture():
    return synthesize(0, SynthConfig(size=(320, 256))).capture


def _problem(capture, config, tilt=0.03, seed=0, noise_px=0.3, min_turns=None, turn_noise=0.01):
    from fingersplat3d.align.solve import global_opt

    rng = np.random.default_rng(seed)
    pairs = [_exact_pair(capture, 0, 1, rng, tilt=tilt, noise_px=noise_px), _exact_pair(capture, 1, 2, rng, tilt=tilt, noise_px=noise_px),
             _exact_pair(capture, 0, 2, rng, tilt=tilt, noise_px=noise_px)]
    depths = [v.depth * (1.0 + 0.1 * np.sin(np.arange(v.width) / 40.0))[None, :] for v in capture.views]  # a shape to correct
    focal = np.full(3, capture.views[0].camera.K[0, 0])
    root, tree = spanning_tree(3, pairs)
    aligned = reached(3, root, tree)
    scene = float(np.nanmedian(depths[root]))
    rotations, translations, log_scales = global_opt._chain(3, root, tree, pairs, scene)
    grids = field_grids(depths, config)
    rng = np.random.default_rng(seed + 1)
    initial = global_opt.InitialState(rotations, translations, log_scales, np.full(3, 0.1), np.log(focal) + 0.05,
                                      [rng.normal(0, 0.05, g.size) for g in grids])
    problem, _ = alignment_problem(depths, focal, pairs, config, grids, initial, aligned, root, min_turns)
    with torch.no_grad():
        problem.omega.add_(torch.as_tensor(rng.normal(0, turn_noise, problem.omega.shape)))
    return problem, pairs, depths, focal


@pytest.mark.gradcheck
@pytest.mark.parametrize("shared, bounded, pivot", [(True, False, True), (False, False, True), (True, True, True),
                                                    (True, False, False)])
def test_the_built_jacobian_gives_the_loss_gradient(capture, shared, bounded, pivot):
    """2 J^T r (the IRLS system) equals autograd's gradient of the true loss, every unknown included (and the
    hinge rows of least turns, two of three pairs held below their bound), with the translation unknowns the pivot
    in each camera's frame (the chain onto the rotations included) or the camera centres (as a rig holds them)."""
    config = GlobalAlignConfig(shared_relief=shared, shared_focal=shared, pivot_poses=pivot, turn_bound_weight=1e3)
    min_turns = np.array([[np.nan, 1.2, 0.1], [1.2, np.nan, 1.5], [0.1, 1.5, np.nan]]) if bounded else None
    problem, *_ = _problem(capture, config, noise_px=2.0, min_turns=min_turns)  # residuals on both sides of the Cauchy scale
    assert problem.pivoted == pivot
    assert (problem.turn_bound_rows(problem.omega.detach()) > 0).sum() == (2 if bounded else 0)
    residual, jacobian = _system(problem)
    problem.zero_grad()
    problem().backward()
    expected = torch.cat([(p.grad if p.grad is not None else torch.zeros_like(p)).reshape(-1)
                          for p in (problem.omega, problem.translation, problem.log_scale, problem.log_alpha,
                                    problem.log_focal, problem.field)]).numpy()
    built = 2.0 * (jacobian.T @ residual)  # the root's pose (the gauge) has no column: both are 0 there
    assert np.isfinite(residual).all() and np.abs(expected).max() > 0
    assert np.allclose(built, expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())


def test_the_step_lowers_the_loss_and_recovers_the_rotations(capture):
    config = GlobalAlignConfig()
    problem, *_ = _problem(capture, config, tilt=0.05)
    with torch.no_grad():
        before = float(problem())
    history = levenberg_marquardt(problem, iterations=15)
    assert history[0] == pytest.approx(before) and all(b <= a for a, b in zip(history, history[1:]))
    assert history[-1] < 0.5 * before


@pytest.mark.slow
def test_lm_and_lbfgs_agree_where_both_converge(capture):
    rng = np.random.default_rng(0)
    pairs = [_exact_pair(capture, 0, 1, rng, tilt=0.03), _exact_pair(capture, 1, 2, rng, tilt=0.03)]
    depths = [v.depth for v in capture.views]
    focal = capture.views[0].camera.K[0, 0]
    truth = [v.camera.world_to_cam for v in capture.views]
    lm = global_align(depths, focal, pairs, GlobalAlignConfig())
    lbfgs = global_align(depths, focal, pairs, GlobalAlignConfig(solver="lbfgs", iterations=150, polish_iterations=1000))
    assert np.max(relative_rotation_errors(lm.world_to_cam, truth)) < 1.0
    assert np.max(relative_rotation_errors(lm.world_to_cam, lbfgs.world_to_cam)) < 0.3
    assert lm.loss_history[-1] <= lbfgs.loss_history[-1] * 1.01


def test_the_lbfgs_solver_lowers_the_loss_and_keeps_its_views_placed(capture):
    """The ``lbfgs`` solver, a few iterations (the agreement with Levenberg-Marquardt at convergence is a slow test)."""
    rng = np.random.default_rng(0)
    pairs = [_exact_pair(capture, 0, 1, rng, tilt=0.03), _exact_pair(capture, 1, 2, rng, tilt=0.03)]
    depths = [v.depth for v in capture.views]
    result = global_align(depths, capture.views[0].camera.K[0, 0], pairs,
                          GlobalAlignConfig(solver="lbfgs", iterations=20, polish_iterations=20))
    history = result.loss_history
    assert all(result.aligned) and np.isfinite(history).all() and history[-1] < history[0]
    assert all(np.isfinite(pose).all() for pose in result.world_to_cam)


def test_turn_uncertainty_is_symmetric_and_grows_with_the_noise(capture):
    from fingersplat3d.align.solve.levenberg import turn_uncertainty_deg

    sigmas = []
    for noise in (0.2, 2.0):
        problem, *_ = _problem(capture, GlobalAlignConfig(), noise_px=noise)
        levenberg_marquardt(problem, iterations=15)
        sigma = turn_uncertainty_deg(problem, [True, True, True])
        assert np.isnan(np.diag(sigma)).all() and np.allclose(sigma, sigma.T, equal_nan=True)
        off = sigma[~np.eye(3, dtype=bool)]
        assert np.isfinite(off).all() and (off > 0).all()
        sigmas.append(off)
    assert (sigmas[1] > 2 * sigmas[0]).all()  # ten times the pixel noise: a much less sure turn
    assert np.isnan(turn_uncertainty_deg(problem, [True, True, False])[0, 2])


def test_the_curvature_asked_for_afterwards_is_the_solves_own(capture):
    """A registration solves without the curvature and asks for it once, from the problem set up again at the
    solution (turn_uncertainty_of): the same as the solve's own, the rotations' tangent taken at the solution."""
    from fingersplat3d.align.solve.global_opt import turn_uncertainty_of

    rng = np.random.default_rng(3)
    pairs = [_exact_pair(capture, a, b, rng, tilt=0.03, noise_px=0.5) for a, b in ((0, 1), (1, 2), (0, 2))]
    depths = [v.depth * (1.0 + 0.1 * np.sin(np.arange(v.width) / 40.0))[None, :] for v in capture.views]
    focal = capture.views[0].camera.K[0, 0]
    solved = global_align(depths, focal, pairs)
    without = global_align(depths, focal, pairs, uncertainty=False)
    assert without.turn_uncertainty_deg is None
    again = turn_uncertainty_of(without, depths, focal, pairs)
    off = ~np.eye(3, dtype=bool)
    assert np.isnan(np.diag(again)).all() and (again[off] > 0).all()
    assert np.allclose(again[off], solved.turn_uncertainty_deg[off], rtol=0.02)
    assert turn_uncertainty_of(without, depths, focal, []) is None  # nothing matched: no curvature


def test_fuse_reports_the_turn_uncertainty_of_every_pair(capture):
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.scene import Capture

    blind = Capture(tuple(v.with_(camera=None, depth=None) for v in capture.views), capture.metadata)
    report = fuse(blind, FuseConfig(splat=None)).report["alignment"]
    assert set(report["turn_uncertainty_deg"]) == {"left-center", "left-right", "center-right"}
    assert all(0 < value < 5 for value in report["turn_uncertainty_deg"].values())
    assert set(report["turn_sensitivity_deg"]) == set(report["turn_uncertainty_deg"])
    assert all(0 <= value < 5 for value in report["turn_sensitivity_deg"].values())
    known = fuse(blind, FuseConfig(splat=None, focal_px=float(capture.views[0].camera.K[0, 0]))).report["alignment"]
    assert "turn_sensitivity_deg" not in known  # a known focal is held: nothing to probe


def test_the_solved_turns_keep_to_their_bounds(capture):
    """A least turn above the one the matches want holds the pair at it (to a hair); a bound below it does not bind
    (the hinge rows' weight as it was when they were on by default)."""
    from fingersplat3d.eval.poses import rotation_angle_deg

    config = GlobalAlignConfig(turn_bound_weight=1e3)
    bounds = np.full((3, 3), np.nan)
    bounds[0, 1] = bounds[1, 0] = np.radians(52.0)  # the true turn is 45
    bounds[1, 2] = bounds[2, 1] = np.radians(30.0)
    problem, *_ = _problem(capture, config, tilt=0.05, min_turns=bounds)
    levenberg_marquardt(problem, iterations=30)
    with torch.no_grad():
        rotations = problem.rotations().numpy()
    assert rotation_angle_deg(rotations[0], rotations[1]) > 51.5
    assert rotation_angle_deg(rotations[1], rotations[2]) > 35.0  # measured 40-50: its neighbour pulls, not its bound


def _autodiff_row_derivatives(problem, local):
    """The slow reference: forward-mode products of :meth:`AlignmentProblem.row_residuals`, one per local unknown."""
    from fingersplat3d.align.solve.row_jacobian import ROW_UNKNOWNS

    names = [name for name, _ in ROW_UNKNOWNS]
    columns = []
    for name, width in ROW_UNKNOWNS:
        for k in range(width):
            tangent = tuple(torch.zeros_like(local[n]) for n in names)
            tangent[names.index(name)][:, k] = 1.0
            columns.append(torch.func.jvp(lambda *args: problem.row_residuals(**dict(zip(names, args))),
                                          tuple(local[n] for n in names), tangent)[1])
    return torch.stack(columns, 2)  # [M, 4, 20]


@pytest.mark.gradcheck
@pytest.mark.parametrize("omega_scale", [0.0, 1e-6, 0.3])
def test_closed_form_row_derivatives_equal_autodiff(capture, omega_scale):
    """Every per-correspondence derivative, rotation updates at zero, tiny (the series branch) and large."""
    from fingersplat3d.align.solve.row_jacobian import row_residuals_and_derivatives

    problem, *_ = _problem(capture, GlobalAlignConfig(shared_relief=False, shared_focal=False), noise_px=2.0)
    with torch.no_grad():
        problem.omega.copy_(torch.as_tensor(np.random.default_rng(3).normal(0, 1, problem.omega.shape)) * omega_scale)
    local = problem.row_unknowns()
    rows, derivatives = row_residuals_and_derivatives(problem, local)
    with torch.no_grad():
        expected_rows = problem.row_residuals(**local)
    expected = _autodiff_row_derivatives(problem, local)
    assert rows.shape == expected_rows.shape and derivatives.shape == expected.shape == (rows.shape[0], 4, 20)
    assert torch.allclose(rows, expected_rows, rtol=1e-10, atol=1e-10)
    assert torch.allclose(derivatives, expected, rtol=1e-7, atol=1e-9 * float(expected.abs().max()))


def test_left_jacobian_is_the_exponential_maps_first_order():
    """``Exp(w + d) ~ Exp(J_l(w) d) Exp(w)`` to second order in ``d``, on both sides of the series switch."""
    from fingersplat3d.rotations import axis_angle_to_matrix, left_jacobian

    rng = np.random.default_rng(0)
    for norm in (0.0, 5e-5, 1e-3, 1.0, 3.0):
        w = torch.as_tensor(rng.normal(size=3), dtype=torch.float64)
        w = w / w.norm() * norm
        d = torch.as_tensor(rng.normal(size=3), dtype=torch.float64) * 1e-6
        moved = axis_angle_to_matrix(w + d)
        predicted = axis_angle_to_matrix(left_jacobian(w) @ d) @ axis_angle_to_matrix(w)
        assert torch.allclose(moved, predicted, atol=1e-11)


def test_pivoted_cameras_start_where_they_were_and_turn_about_the_pivot(capture):
    """The pivot unknowns reproduce the initial camera centres; a rotation update with the pivot unknowns held turns
    a camera about the pivot (it stays at the same place in the camera's frame, at the same distance)."""
    problem, *_ = _problem(capture, GlobalAlignConfig(), turn_noise=0.0)
    unpivoted, *_ = _problem(capture, GlobalAlignConfig(pivot_poses=False), turn_noise=0.0)
    with torch.no_grad():
        torch.testing.assert_close(problem.translations(), unpivoted.translations())
        pivot = problem.pivot
        before = torch.einsum("nji,nj->ni", problem.rotations(), pivot - problem.translations())
        problem.omega.add_(torch.tensor([0.0, 0.4, 0.1], dtype=torch.float64))
        after = torch.einsum("nji,nj->ni", problem.rotations(), pivot - problem.translations())
    free = problem.free.bool()
    torch.testing.assert_close(after[free], before[free])
    assert not torch.allclose(problem.translations()[free], unpivoted.translations()[free])


def test_two_views_keep_the_camera_centres_as_unknowns(capture):
    rng = np.random.default_rng(0)
    pairs = [_exact_pair(capture, 0, 1, rng, tilt=0.03)]
    depths = [v.depth for v in capture.views[:2]]
    config = GlobalAlignConfig()
    grids = field_grids(depths, config)
    root, tree = spanning_tree(2, pairs)
    from fingersplat3d.align.solve import global_opt

    rotations, translations, log_scales = global_opt._chain(2, root, tree, pairs, float(np.nanmedian(depths[root])))
    initial = global_opt.InitialState(rotations, translations, log_scales, np.zeros(2), np.log(np.full(2, 900.0)),
                                      [np.zeros(g.size) for g in grids])
    problem, _ = alignment_problem(depths, np.full(2, 900.0), pairs, config, grids, initial, [True, True], root)
    assert not problem.pivoted


def _exact_three(capture):
    """Exact matches between every two of the capture's three views, their true depths and focal."""
    rng = np.random.default_rng(0)
    pairs = [_exact_pair(capture, 0, 1, rng, tilt=0.03), _exact_pair(capture, 1, 2, rng, tilt=0.03),
             _exact_pair(capture, 0, 2, rng, tilt=0.03)]
    return pairs, [v.depth for v in capture.views], capture.views[0].camera.K[0, 0]


def test_turn_sensitivity_is_small_where_three_views_pin_the_turns_and_large_for_two(capture):
    """The probe of align/solve/sensitivity.py: three views with exact matches hold their turns while the focal is
    held off (a fraction of a degree); two views, whose turn follows the focal, move by more."""
    from fingersplat3d.align.solve.sensitivity import focal_probe

    pairs, depths, focal = _exact_three(capture)
    config = GlobalAlignConfig()
    three = global_align(depths, focal, pairs, config)
    moves = focal_probe(three, depths, focal, pairs, config).moves
    assert moves.shape == (3, 3) and np.allclose(np.diag(moves), 0) and np.allclose(moves, moves.T)
    assert np.nanmax(moves) < 1.0
    two = global_align(depths[:2], focal, pairs[:1], config)
    two_moves = focal_probe(two, depths[:2], focal, pairs[:1], config).moves
    assert two_moves[0, 1] > 3 * np.nanmax(moves)  # measured 11.1 against 0.62 (4.1 before the shorter probe)
    assert focal_probe(two, depths[:2], focal, pairs[:1], GlobalAlignConfig(optimize_focal=False)) is None
    unreached = global_align(depths, focal, pairs[:1], config)  # view 2 has no pair
    assert np.isnan(focal_probe(unreached, depths, focal, pairs[:1], config).moves[0, 2])


def test_the_focal_probe_says_when_the_photos_do_not_hold_the_focal(capture, monkeypatch):
    """focal_probe: three views with exact matches raise the loss when the focal is held 10 % longer (held, no second
    probe); two views, whose loss is flat along the focal, are probed shorter too, and that probe's larger move is
    their sensitivity."""
    from fingersplat3d.align.solve import sensitivity
    from fingersplat3d.align.solve.sensitivity import EXCLUDED_LOSS_RISE, FLAT_LOSS_RISE, focal_probe

    pairs, depths, focal = _exact_three(capture)
    config = GlobalAlignConfig()
    three = focal_probe(global_align(depths, focal, pairs, config), depths, focal, pairs, config)
    assert three.held and three.longer_loss_rise > FLAT_LOSS_RISE and three.shorter_share is None  # measured +8.5 %
    assert three.summary() == {"held": True, "longer_loss_rise": round(three.longer_loss_rise, 4)}
    two_alignment = global_align(depths[:2], focal, pairs[:1], config)
    two = focal_probe(two_alignment, depths[:2], focal, pairs[:1], config)
    assert not two.held and two.longer_loss_rise < FLAT_LOSS_RISE  # measured -0.5 %
    assert 0.3 < two.shorter_share < 1.0 and two.shorter_loss_rise <= EXCLUDED_LOSS_RISE  # measured 0.73, +9.8 %
    from dataclasses import replace

    unknown = focal_probe(replace(two_alignment, loss_history=[]), depths[:2], focal, pairs[:1], config)
    assert unknown.held and unknown.summary()["longer_loss_rise"] is None  # no loss to compare: no evidence either way
    monkeypatch.setattr(sensitivity, "FLAT_LOSS_RISE", -np.inf)  # the longer probe alone, as before
    longer = focal_probe(two_alignment, depths[:2], focal, pairs[:1], config)
    assert longer.held and two.moves[0, 1] > 2 * longer.moves[0, 1]  # measured 11.1 against 4.1


def test_the_short_end_of_a_flat_focal_valley_is_where_the_loss_meets_the_tolerance(monkeypatch):
    """short_end walks the focal down while the loss stays within the tolerance and stops where it meets it
    (interpolated between steps); None when the first step already leaves it, the last step within it when the
    interpolated one cannot be compared, and the whole walk when the valley never rises."""
    from types import SimpleNamespace

    from fingersplat3d.align.solve import sensitivity
    from fingersplat3d.align.solve.sensitivity import SHORT_END_STEP, short_end

    def valley(rise_of_share):
        monkeypatch.setattr(sensitivity, "_held_at", lambda alignment, *args: SimpleNamespace(share=args[-1]))
        monkeypatch.setattr(sensitivity, "_loss_rise", lambda held, alignment: rise_of_share(held.share))

    valley(lambda share: 2.0 * np.log(share) ** 2)  # +10 % at share exp(-sqrt(0.05)) = 0.80
    held, share = short_end(None, [], 1.0, [], GlobalAlignConfig(), 0.10)
    assert held.share == share and abs(share - np.exp(-np.sqrt(0.05))) < 0.02
    valley(lambda share: 5.0 * (1.0 - share))  # +50 % at the first step
    assert short_end(None, [], 1.0, [], GlobalAlignConfig(), 0.10) is None
    valley(lambda share: 0.0)  # flat all the way: the walk's last step
    assert short_end(None, [], 1.0, [], GlobalAlignConfig(), 0.10)[1] == pytest.approx(SHORT_END_STEP ** 12)
    valley(lambda share: 2.0 * np.log(share) ** 2 if share in (SHORT_END_STEP, SHORT_END_STEP ** 2, SHORT_END_STEP ** 3)
           else float("nan"))
    assert short_end(None, [], 1.0, [], GlobalAlignConfig(), 0.10)[1] == pytest.approx(SHORT_END_STEP ** 2)


def test_two_views_are_held_to_their_least_turns_and_three_are_not(capture):
    """The hinge rows of least turns: on where two views are aligned (their bas-relief valley open, the relief from
    the prior's section), off where three are (``GlobalAlignConfig.two_view_turn_bound_weight``, ``turn_bound_weight``)."""
    from fingersplat3d.eval.poses import rotation_angle_deg

    config = GlobalAlignConfig()
    bounds = np.full((3, 3), np.nan)
    bounds[0, 1] = bounds[1, 0] = np.radians(52.0)  # the true turn is 45
    problem, pairs, depths, focal = _problem(capture, config, min_turns=bounds)
    assert problem.turn_bound_weight == config.turn_bound_weight == 0.0
    three = global_align(depths, focal, pairs, config, min_turns=bounds)
    two = global_align(depths, focal, pairs[:1], config, min_turns=bounds)  # views 0 and 1 alone
    assert all(three.aligned) and two.aligned == [True, True, False]
    assert rotation_angle_deg(three.cam_to_world[0][:3, :3], three.cam_to_world[1][:3, :3]) < 48.0
    assert rotation_angle_deg(two.cam_to_world[0][:3, :3], two.cam_to_world[1][:3, :3]) > 51.0
