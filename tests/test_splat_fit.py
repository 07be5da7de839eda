"""Fitting Gaussians: presets, budget, density control, pose refinement, convergence on a known scene."""
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from fingersplat3d.scene import Camera, View, look_at
from fingersplat3d.splat import Gaussians, rgb_to_sh
from fingersplat3d.splat.adam import Adam
from fingersplat3d.splat.config import PRESETS, SplatConfig, differences_from_preset, preset
from fingersplat3d.splat.fit import MIN_COARSE_PERIOD_PX, fit_camera, fit_gaussians, gaussian_budget, halved, render_camera
from fingersplat3d.splat.strategy import GAUSSIAN_GROUPS, GradientStats, densify_and_prune, gaussians_of


def test_presets_trade_time_for_detail():
    fast, balanced, accurate = PRESETS["fast"], PRESETS["balanced"], PRESETS["accurate"]
    assert fast.iterations < balanced.iterations < accurate.iterations
    assert fast.gaussians_per_cell <= balanced.gaussians_per_cell <= accurate.gaussians_per_cell
    assert preset("fast", iterations=7).iterations == 7 and preset("fast", iterations=None) == fast
    with pytest.raises(ValueError, match="unknown splat preset"):
        preset("fastest")
    assert preset("fast").preset == "fast" and differences_from_preset(preset("fast")) == {}
    assert differences_from_preset(preset("balanced", iterations=9, gaussians_per_cell=2.0)) == {"iterations": 9, "gaussians_per_cell": 2.0}
    assert "iterations" in differences_from_preset(SplatConfig())  # no preset: every setting is listed
    with pytest.raises(ValueError, match="unknown splat setting"):
        preset("fast", iteration=3)
    with pytest.raises(ValueError):
        SplatConfig(iterations=-1)
    for bad in (-0.1, float("nan")):
        with pytest.raises(ValueError, match="lambda_solid"):
            SplatConfig(lambda_solid=bad)


def _striped_view(period: float, size=(160, 128), box=(20, 140, 30, 100)) -> View:
    x = np.arange(size[0])[None, :].repeat(size[1], 0)
    image = (0.5 + 0.3 * np.sin(2 * np.pi * x / period)).astype(np.float32)
    mask = np.zeros((size[1], size[0]), bool)
    mask[box[2]:box[3], box[0]:box[1]] = True
    return View("v", np.where(mask, image, 0.03).astype(np.float32), mask)


def test_budget_follows_finger_area_and_ridge_frequency():
    config = SplatConfig(min_gaussians=1, view_overlap=1.0)
    coarse, fine = gaussian_budget([_striped_view(12.0)], config), gaussian_budget([_striped_view(6.0)], config)
    assert 3.0 < fine / coarse < 5.0  # (period / 4)^2 cells: half the period, four times the Gaussians
    small = gaussian_budget([_striped_view(12.0, box=(20, 80, 30, 100))], config)
    assert 0.4 < small / coarse < 0.6  # half the area, half the budget
    assert gaussian_budget([_striped_view(12.0)], replace(config, gaussians_per_cell=2.0)) == pytest.approx(2 * coarse, rel=0.01)
    assert gaussian_budget([_striped_view(12.0)], replace(config, max_gaussians=50, min_gaussians=10)) == 50


def _plane_scene(n_side=14, channels=1):
    """A textured square of Gaussians at z = 0 seen by cameras 10 units away."""
    u = torch.linspace(-1.0, 1.0, n_side)
    grid = torch.stack(torch.meshgrid(u, u, indexing="xy"), -1).reshape(-1, 2)
    n = len(grid)
    means = torch.cat([grid, torch.zeros(n, 1)], 1)
    colours = 0.5 + 0.35 * torch.sin(3.0 * grid[:, :1] * math.pi)
    colours = colours.repeat(1, channels) if channels > 1 else colours
    spacing = 2.0 / (n_side - 1)
    return Gaussians(means, torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1), torch.full((n, 3), math.log(0.6 * spacing)),
                     torch.full((n,), 2.0), rgb_to_sh(colours))


def _cameras(angles=(-20.0, 20.0), size=(64, 48), focal=90.0):
    cameras = []
    for angle in angles:
        eye = 10.0 * np.array([np.sin(np.radians(angle)), 0.0, -np.cos(np.radians(angle))])
        cameras.append(Camera.from_focal(focal, size[0], size[1], look_at(eye, [0, 0, 0], [0, -1, 0])))
    return cameras


def _views(truth: Gaussians, cameras):
    views = []
    for k, camera in enumerate(cameras):
        with torch.no_grad():
            out = render_camera(truth, camera, near=0.1)
        mask = out.alpha.numpy() > 0.5
        views.append(View(f"v{k}", out.color.numpy()[..., 0], mask))
    return views


def test_fit_recovers_a_known_scene_from_a_perturbed_start():
    truth = _plane_scene()
    cameras = _cameras()
    views = _views(truth, cameras)
    generator = torch.Generator().manual_seed(1)
    start = truth.with_(sh_dc=truth.sh_dc + 0.8 * torch.randn(truth.sh_dc.shape, generator=generator),
                        means=truth.means + 0.02 * torch.randn(truth.means.shape, generator=generator))
    config = SplatConfig(iterations=60, refine_poses=False, densify_from=1000, lr_colors=0.1, lr_means=1e-3,
                         lr_means_final=1e-4, min_gaussians=1)
    fit = fit_gaussians(start, views, cameras, config, device="cpu")
    assert len(fit.losses) == 60 and all(math.isfinite(x) for x in fit.losses)
    assert np.mean(fit.losses[-10:]) < 0.35 * np.mean(fit.losses[:3])
    colour_error = lambda g: float((g.colors - truth.colors).abs().mean())  # noqa: E731
    assert colour_error(fit.gaussians) < 0.5 * colour_error(start)


@pytest.mark.parametrize("size", [(64, 48), (65, 49)])
def test_halved_view_keeps_the_camera_the_texture_and_the_mask(size):
    truth = _plane_scene()
    camera = _cameras(size=size)[0]
    view = _views(truth, [camera])[0]
    depth = np.where(view.mask, 10.0, np.nan).astype(np.float32)
    small, small_camera, small_depth = halved(view, camera, depth)
    assert (small.width, small.height) == (size[0] // 2, size[1] // 2) == small_camera.size
    points = np.array([[0.3, -0.2, 0.0], [-0.5, 0.4, 0.1]])
    (full_uv, _), (half_uv, _) = camera.project(points), small_camera.project(points)
    # pixel centres at integer coordinates: half pixel x covers full pixels 2x and 2x + 1
    np.testing.assert_allclose(half_uv, (full_uv + 0.5) * np.array(small_camera.size) / np.array(camera.size) - 0.5,
                               atol=1e-9)
    assert abs(small.image[small.mask].mean() - view.image[view.mask].mean()) < 0.02
    assert abs(small.mask.mean() - view.mask.mean()) < 0.05
    assert np.isfinite(small_depth[small.mask]).all() and np.isnan(small_depth[~small.mask]).all()
    assert halved(View("nomask", view.image), camera)[0].mask is None


def test_coarse_start_fits_as_well_as_full_resolution_steps():
    truth = _plane_scene()
    cameras = _cameras(size=(96, 72), focal=300.0)  # the stripes ~20 px apart: 10 px at half resolution
    views = _views(truth, cameras)
    generator = torch.Generator().manual_seed(1)
    start = truth.with_(sh_dc=truth.sh_dc + 0.8 * torch.randn(truth.sh_dc.shape, generator=generator))
    base = SplatConfig(iterations=60, refine_poses=False, densify_from=1000, lr_colors=0.1, min_gaussians=1)
    error = lambda g: float((g.colors - truth.colors).abs().mean())  # noqa: E731
    full = fit_gaussians(start, views, cameras, base, device="cpu")
    coarse = fit_gaussians(start, views, cameras, replace(base, coarse_fraction=0.5), device="cpu")
    assert len(coarse.losses) == 60 and all(math.isfinite(x) for x in coarse.losses)
    assert full.coarse_steps == 0 and coarse.coarse_steps == 30
    assert error(coarse.gaussians) < 0.5 * error(start)
    assert error(coarse.gaussians) < 1.5 * error(full.gaussians) + 0.01
    with pytest.raises(ValueError, match="coarse_fraction"):
        SplatConfig(coarse_fraction=1.0)


def test_ridges_too_fine_to_halve_keep_every_step_at_full_resolution():
    truth = _plane_scene()
    cameras = _cameras(size=(96, 72), focal=300.0)
    views = _views(truth, cameras)
    config = SplatConfig(iterations=6, refine_poses=False, densify_from=1000, min_gaussians=1, coarse_fraction=0.5)
    fine = fit_gaussians(truth, views, cameras, config, device="cpu", periods=[MIN_COARSE_PERIOD_PX - 0.5] * 2)
    coarse = fit_gaussians(truth, views, cameras, config, device="cpu", periods=[MIN_COARSE_PERIOD_PX, 20.0])
    assert fine.coarse_steps == 0 and coarse.coarse_steps == 3


def test_density_control_respects_budget_and_keeps_adam_state():
    model = _plane_scene(n_side=10)
    parameters = [torch.nn.Parameter(t.clone()) for t in model.tensors()]
    optimizer = Adam([{"params": [p], "lr": 1e-3, "name": name} for p, name in zip(parameters, GAUSSIAN_GROUPS)])
    sum(p.sum() for p in parameters).backward()
    optimizer.step()
    n = len(model)
    stats = GradientStats.zeros(n, torch.device("cpu"))
    stats.add(torch.full((n, 2), 1.0), torch.ones(n, dtype=torch.int32), 64, 48)
    with torch.no_grad():  # make the first 10 Gaussians transparent: they must go
        optimizer.param_groups[3]["params"][0][:10] = -20.0
    config = SplatConfig(percent_dense=0.05, prune_opacity=0.005)
    result = densify_and_prune(optimizer, stats, config, extent=2.0, budget=n + 15,
                               generator=torch.Generator().manual_seed(0))
    grown = gaussians_of(optimizer)
    assert result.pruned == 10 and result.cloned + result.split == 25  # budget: n - 10 kept + 25 new = n + 15
    assert len(grown) == result.total == n + 15  # a split replaces one Gaussian by two: +1 each
    for group in optimizer.param_groups[:5]:
        parameter = group["params"][0]
        state = optimizer.state[parameter]
        assert state["exp_avg"].shape == parameter.shape and state["exp_avg_sq"].shape == parameter.shape
    assert len(stats.mean()) == len(grown)


def test_split_children_are_smaller_and_inside_the_parent():
    model = _plane_scene(n_side=4)
    parameters = [torch.nn.Parameter(t.clone()) for t in model.tensors()]
    optimizer = Adam([{"params": [p], "lr": 1e-3, "name": name} for p, name in zip(parameters, GAUSSIAN_GROUPS)])
    stats = GradientStats.zeros(len(model), torch.device("cpu"))
    stats.add(torch.ones(len(model), 2), torch.ones(len(model), dtype=torch.int32), 64, 48)
    result = densify_and_prune(optimizer, stats, SplatConfig(percent_dense=0.0), extent=10.0, budget=100,
                               generator=torch.Generator().manual_seed(0))
    grown = gaussians_of(optimizer)
    assert result.split == len(model) and len(grown) == 2 * len(model)
    assert torch.allclose(grown.scales, model.scales.repeat(2, 1) / 1.6, rtol=1e-5)
    offsets = (grown.means - model.means.repeat(2, 1)).norm(dim=-1) / model.scales.max(-1).values.repeat(2)
    assert offsets.max() < 5.0


def test_pose_refinement_and_test_view_alignment_recover_a_perturbed_camera():
    truth = _plane_scene(n_side=20)
    cameras = _cameras(angles=(-15.0, 0.0, 15.0), size=(96, 72))
    views = _views(truth, cameras)
    pose = cameras[2].world_to_cam.copy()
    nudge = np.eye(4)
    angle = np.radians(1.0)
    nudge[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    wrong = Camera(cameras[2].K, nudge @ pose, 96, 72)
    aligned = fit_camera(truth, wrong, views[2].image, views[2].mask, iterations=50, lr_rotation=5e-3)

    def angle_to_truth(camera):
        relative = camera.rotation @ cameras[2].rotation.T
        return np.degrees(np.arccos(np.clip((np.trace(relative) - 1) / 2, -1, 1)))

    assert angle_to_truth(wrong) == pytest.approx(1.0, abs=1e-6)
    assert angle_to_truth(aligned) < 0.3
    config = SplatConfig(iterations=60, refine_poses=True, lr_pose_rotation=5e-3, densify_from=1000,
                         lr_colors=0.0, lr_means=0.0, lr_means_final=0.0, lr_scales=0.0, lr_quats=0.0, lr_opacity=0.0)
    fit = fit_gaussians(truth, views, [cameras[0], cameras[1], wrong], config, device="cpu")
    assert angle_to_truth(fit.cameras[2]) < 0.5 * angle_to_truth(wrong)
    assert np.allclose(fit.cameras[0].world_to_cam, cameras[0].world_to_cam)  # the gauge view never moves


def test_rgb_model_has_three_channels_and_grayscale_mismatch_is_an_error():
    truth = _plane_scene(channels=3)
    cameras = _cameras()
    gray_views = [View(f"v{k}", np.zeros((48, 64), np.float32), np.ones((48, 64), bool)) for k in range(2)]
    with pytest.raises(ValueError, match="colour channel"):
        fit_gaussians(truth, gray_views, cameras, SplatConfig(iterations=1), device="cpu")
    with torch.no_grad():
        assert render_camera(truth, cameras[0], near=0.1).color.shape == (48, 64, 3)


def test_depth_prior_pulls_the_surface_onto_the_geometry():
    truth = _plane_scene(n_side=14)
    cameras = _cameras(angles=(-10.0, 10.0))
    views = _views(truth, cameras)
    depths = []
    for camera in cameras:
        with torch.no_grad():
            out = render_camera(truth, camera, near=0.1)
        depths.append(np.where(out.alpha.numpy() > 0.5, out.depth.numpy(), np.nan))
    shifted = truth.with_(means=truth.means + torch.tensor([0.0, 0.0, 0.3]))  # 0.3 units behind the truth
    frozen = dict(refine_poses=False, densify_from=1000, lr_colors=0.0, lr_scales=0.0, lr_quats=0.0, lr_opacity=0.0,
                  lr_means=0.02, lr_means_final=0.02, lambda_silhouette=0.0)
    free = fit_gaussians(shifted, views, cameras, SplatConfig(iterations=30, lambda_depth=0.0, **frozen), device="cpu")
    held = fit_gaussians(shifted, views, cameras, SplatConfig(iterations=30, lambda_depth=10.0, **frozen), device="cpu",
                         depths=depths)
    offset = lambda fit: float((fit.gaussians.means[:, 2] - truth.means[:, 2]).mean())  # noqa: E731
    assert abs(offset(held)) < 0.5 * abs(offset(free)) and abs(offset(held)) < 0.15


def test_test_view_alignment_never_ends_worse_than_it_starts():
    truth = _plane_scene(n_side=20)
    cameras = _cameras(angles=(-15.0, 0.0, 15.0), size=(96, 72))
    views = _views(truth, cameras)
    # From the exact camera there is nothing to gain: the camera comes back (or one that matches as well).
    aligned = fit_camera(truth, cameras[1], views[1].image, views[1].mask, iterations=20, lr_rotation=5e-2)
    @torch.no_grad()
    def loss(camera):
        out = render_camera(truth, camera, near=0.1)
        return float((out.color[..., 0] - torch.from_numpy(views[1].image).float()).abs().mean())

    assert loss(aligned) <= loss(cameras[1]) + 1e-6


def test_adam_follows_torch_adam():
    """The fit's Adam (no torch._dynamo import) takes torch.optim.Adam's steps: several groups and rates, a tiny
    ``eps`` as the fit uses, gradients that vanish on some entries, a parameter with no gradient."""
    rng = np.random.default_rng(0)
    start = [torch.as_tensor(rng.normal(size=shape), dtype=torch.float32) for shape in ((50, 3), (50,), (4, 3))]
    ours = [torch.nn.Parameter(t.clone()) for t in start]
    theirs = [torch.nn.Parameter(t.clone()) for t in start]
    rates = (1e-2, 3e-3, 0.0)
    mine = Adam([{"params": [p], "lr": lr, "name": str(i)} for i, (p, lr) in enumerate(zip(ours, rates))], eps=1e-15)
    reference = torch.optim.Adam([{"params": [p], "lr": lr} for p, lr in zip(theirs, rates)], eps=1e-15)
    for step in range(30):
        for parameters, optimizer in ((ours, mine), (theirs, reference)):
            optimizer.zero_grad(set_to_none=True)
            loss = (parameters[0] ** 3).sum() + (torch.relu(parameters[1]) * step).sum()  # parameters[2]: no gradient
            loss.backward()
            optimizer.step()
    for a, b in zip(ours, theirs):
        assert torch.allclose(a, b, rtol=1e-5, atol=1e-6)
    assert not torch.equal(ours[0], start[0]) and torch.equal(ours[2], start[2])
    assert mine.state[ours[0]]["step"] == 30 and ours[2] not in mine.state


def test_pose_refinement_holds_still_with_near_orthographic_cameras():
    """A camera 50 times as far with a 50 times longer focal sees the same image; turning it moves the image 50 times
    as far, and a turn there looks like a shift. Refined from the true poses, the poses must stay (they drifted by
    hundreds of pixels on another group's near-orthographic renders before the turn's rate followed the focal)."""
    from fingersplat3d.splat.fit import LONG_FOCAL, rotation_step_scale

    truth = _plane_scene(n_side=20)
    config = SplatConfig(iterations=40, refine_poses=True, densify_from=1000, lr_colors=0.0, lr_means=0.0,
                         lr_means_final=0.0, lr_scales=0.0, lr_quats=0.0, lr_opacity=0.0, lambda_silhouette=0.0)
    drift = {}
    for far in (1.0, 50.0):
        cameras = []
        for angle in (-15.0, 0.0, 15.0):
            eye = 10.0 * far * np.array([np.sin(np.radians(angle)), 0.0, -np.cos(np.radians(angle))])
            cameras.append(Camera.from_focal(90.0 * far, 96, 72, look_at(eye, [0, 0, 0], [0, -1, 0])))
        scales = [rotation_step_scale(camera) for camera in cameras]
        assert scales == ([1.0] * 3 if 90.0 * far <= LONG_FOCAL * 96 else [pytest.approx((LONG_FOCAL * 96 / 4500.0) ** 2)] * 3)
        views = _views(truth, cameras)
        fit = fit_gaussians(truth, views, cameras, config, device="cpu")
        shifts = []
        for before, after in zip(cameras[1:], fit.cameras[1:]):
            centre = np.zeros((1, 3))
            shifts.append(float(np.linalg.norm(after.project(centre)[0] - before.project(centre)[0])))
        drift[far] = max(shifts)  # pixels the scene's centre moved in the refined views
    assert drift[50.0] < 1.0 and drift[50.0] < 3.0 * drift[1.0] + 0.2


def test_frozen_gaussians_stay_put_while_the_others_fit():
    truth = _plane_scene()
    cameras = _cameras()
    views = _views(truth, cameras)
    generator = torch.Generator().manual_seed(3)
    start = truth.with_(sh_dc=truth.sh_dc + 0.8 * torch.randn(truth.sh_dc.shape, generator=generator))
    frozen = torch.arange(len(start)) % 2 == 0
    config = SplatConfig(iterations=30, refine_poses=False, densify_from=1000, lr_colors=0.1, min_gaussians=1)
    fit = fit_gaussians(start, views, cameras, config, device="cpu", frozen=frozen)
    for before, after in zip(start.tensors(), fit.gaussians.tensors()):
        assert torch.equal(before[frozen], after[frozen])
    assert not torch.equal(start.sh_dc[~frozen], fit.gaussians.sh_dc[~frozen])
    assert np.mean(fit.losses[-5:]) < np.mean(fit.losses[:3])
    with pytest.raises(ValueError, match="frozen"):  # rows that densification would renumber
        fit_gaussians(start, views, cameras, replace(config, densify_from=10), device="cpu", frozen=frozen)
    with pytest.raises(ValueError, match="frozen"):
        fit_gaussians(start, views, cameras, config, device="cpu", frozen=frozen[:-1])


def test_solid_term_makes_the_skin_opaque_where_the_photo_alone_would_not():
    truth = _plane_scene()
    cameras = _cameras()
    views = _views(truth, cameras)
    start = truth.with_(opacity_logits=torch.full_like(truth.opacity_logits, -1.0))  # a see-through start
    config = SplatConfig(iterations=40, refine_poses=False, densify_from=1000, lr_colors=0.05, min_gaussians=1,
                         lambda_solid=0.0)

    def alpha_on_finger(model):
        with torch.no_grad():
            return float(np.mean([render_camera(model, c, near=0.1).alpha.numpy()[v.mask].mean()
                                  for c, v in zip(cameras, views)]))

    free = fit_gaussians(start, views, cameras, config, device="cpu").gaussians
    solid = fit_gaussians(start, views, cameras, replace(config, lambda_solid=5.0), device="cpu").gaussians
    assert alpha_on_finger(solid) > alpha_on_finger(free) + 0.02
    assert alpha_on_finger(solid) > alpha_on_finger(start)
