"""The model's one view-dependent term: skin darker where a camera sees it at a slant (and the estimate of it)."""
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from fingersplat3d.errors import InputError
from fingersplat3d.io.gaussians_ply import EXPONENT_COMMENT, read_gaussians_ply, write_gaussians_ply
from fingersplat3d.rotations import matrix_to_quaternion
from fingersplat3d.scene import Camera, View, look_at
from fingersplat3d.splat import Gaussians, rgb_to_sh
from fingersplat3d.splat.config import SplatConfig
from fingersplat3d.splat.fit import fit_gaussians, render_camera
from fingersplat3d.splat.shading import MAX_EXPONENT, MIN_FACING, _facing_cosines_torch, facing_cosines, shade
from fingersplat3d.splat.shading_estimate import ShadingEstimate, estimate_shading

SIZE = (128, 96)


def _camera(angle_deg: float, distance: float = 12.0, size=SIZE) -> Camera:
    """A camera on the circle about the y axis, looking at the origin (0 degrees: on -z)."""
    angle = math.radians(angle_deg)
    eye = distance * np.array([math.sin(angle), 0.0, -math.cos(angle)])
    return Camera.from_focal(110.0, size[0], size[1], look_at(eye, [0, 0, 0], [0, -1, 0]))


def _half_cylinder(exponent: float = 0.0, radius: float = 2.0, rows: int = 28, columns: int = 60) -> Gaussians:
    """Flat discs tangent to the near half of a cylinder about the y axis (its normals radial), textured slowly."""
    theta = torch.linspace(-0.48 * math.pi, 0.48 * math.pi, columns)
    y = torch.linspace(-1.6, 1.6, rows)
    theta, y = torch.meshgrid(theta, y, indexing="xy")
    theta, y = theta.reshape(-1), y.reshape(-1)
    normal = torch.stack([torch.sin(theta), torch.zeros_like(theta), -torch.cos(theta)], 1)
    means = radius * normal + torch.stack([torch.zeros_like(y), y, torch.zeros_like(y)], 1)
    tangent = torch.stack([torch.cos(theta), torch.zeros_like(theta), torch.sin(theta)], 1)
    along = torch.tensor([0.0, 1.0, 0.0]).expand_as(tangent)
    frames = torch.stack([along, tangent, normal], 2)  # columns: the disc's axes (a rotation), the third its normal
    quats = matrix_to_quaternion(frames)
    step = float(radius * (theta.max() - theta.min()) / (columns - 1))
    log_scales = torch.log(torch.tensor([0.7 * 3.2 / (rows - 1), 0.7 * step, 0.05 * step])).expand(len(means), 3).clone()
    albedo = (0.55 + 0.15 * torch.sin(1.3 * theta) * torch.cos(1.1 * y))[:, None]
    return Gaussians(means, quats, log_scales, torch.full((len(means),), 4.0), rgb_to_sh(albedo), exponent)


def _photos(model: Gaussians, cameras, log_gains):
    """Each camera's render, its exposure ``exp(log_gain)``, mask and depth."""
    views, depths = [], []
    for k, (camera, gain) in enumerate(zip(cameras, log_gains)):
        with torch.no_grad():
            out = render_camera(model, camera, near=0.1)
        mask = out.alpha.numpy() > 0.5
        image = math.exp(gain) * out.color.numpy()[..., 0]
        views.append(View(f"v{k}", np.where(mask, image, 0.0).astype(np.float32), mask))
        depths.append(np.where(mask, out.depth.numpy(), np.nan).astype(np.float32))
    return views, depths


def test_shade_is_the_identity_without_exponent_and_darkens_with_the_slant():
    colors = torch.rand(50, 3)
    cosines = torch.linspace(MIN_FACING, 1.0, 50)
    assert torch.equal(shade(colors, cosines, 0.0), colors)
    assert torch.allclose(shade(colors, torch.ones(50), 0.7), colors)  # face on: the albedo
    shaded = shade(torch.ones(50, 1), cosines, 0.5)[:, 0]
    assert torch.all(shaded[1:] > shaded[:-1])  # the more slanted, the darker
    assert torch.allclose(shade(torch.ones(1, 1), torch.tensor([0.25]), 0.5), torch.tensor([[0.5]]))
    # held in [0, MAX_EXPONENT], finite and positive at the extremes
    assert torch.allclose(shade(colors, cosines, -3.0), colors)
    extreme = shade(colors + 0.1, torch.full((50,), MIN_FACING), 1e6)
    assert torch.isfinite(extreme).all() and (extreme > 0).all()
    assert torch.allclose(extreme, shade(colors + 0.1, torch.full((50,), MIN_FACING), MAX_EXPONENT))


def test_shade_gradients_match_finite_differences_in_float64():
    colors = torch.rand(6, 2, dtype=torch.float64, requires_grad=True)
    cosines = torch.linspace(0.1, 1.0, 6, dtype=torch.float64)
    exponent = torch.tensor(0.4, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda c, k: shade(c, cosines, k), (colors, exponent))


def test_facing_cosines_follow_the_shortest_axis_and_stay_finite():
    flat = torch.log(torch.tensor([[1.0, 1.0, 0.1]]))
    means = torch.zeros(1, 3)
    identity = torch.tensor([[1.0, 0.0, 0.0, 0.0]])
    for angle in (0.0, 30.0, 60.0, -60.0):
        camera = _camera(angle)
        cosine = facing_cosines(means, identity, flat, torch.as_tensor(camera.world_to_cam, dtype=torch.float32))
        assert float(cosine) == pytest.approx(math.cos(math.radians(angle)), abs=1e-5)
    # the shortest axis along x instead: a camera on -z sees it edge on
    edge_on = facing_cosines(means, identity, torch.log(torch.tensor([[0.1, 1.0, 1.0]])),
                             torch.as_tensor(_camera(0.0).world_to_cam, dtype=torch.float32))
    assert float(edge_on) == pytest.approx(MIN_FACING)
    # a zero quaternion (identity), a centre at the camera itself, no Gaussians: finite, no gradient
    camera = _camera(0.0)
    at_camera = torch.tensor(camera.center[None], dtype=torch.float32, requires_grad=True)
    values = facing_cosines(at_camera, torch.zeros(1, 4), flat, torch.as_tensor(camera.world_to_cam, dtype=torch.float32))
    assert torch.isfinite(values).all() and not values.requires_grad
    assert facing_cosines(torch.zeros(0, 3), torch.zeros(0, 4), torch.zeros(0, 3), torch.eye(4)).shape == (0,)


def test_facing_cosines_on_the_cpu_are_the_tensor_formula():
    """The CPU's compiled pass against the tensor version (CUDA's): random Gaussians, unnormalised and zero
    quaternions, tied and extreme scales, a centre at the camera, non-finite positions."""
    generator = torch.Generator().manual_seed(3)
    count = 4000
    means = torch.randn(count, 3, generator=generator) * 5.0
    quats = torch.randn(count, 4, generator=generator) * torch.rand(count, 1, generator=generator) * 3.0
    quats[:50] = 0.0
    log_scales = torch.randn(count, 3, generator=generator) * 4.0
    log_scales[50:100] = log_scales[50:100, :1]  # ties: the first smallest axis, as argmin
    log_scales[100:150, 2] = -80.0
    pose = torch.as_tensor(_camera(25.0).world_to_cam, dtype=torch.float32)
    centre = -(pose[:3, :3].T @ pose[:3, 3])
    means[150] = centre
    means[151, 0] = float("inf")
    means[152, 1] = float("nan")
    compiled = facing_cosines(means, quats, log_scales, pose)
    reference = _facing_cosines_torch(means, quats, log_scales, centre)
    assert compiled.dtype == means.dtype and compiled.shape == (count,)
    assert torch.isfinite(compiled).all() and bool(((compiled >= MIN_FACING) & (compiled <= 1.0)).all())
    assert torch.allclose(compiled, reference, atol=2e-6)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_facing_cosines_on_a_gpu_are_the_cpus():
    """A CUDA tensor takes the tensor formula on the GPU: the same cosines as the CPU's compiled pass, on the GPU."""
    generator = torch.Generator().manual_seed(4)
    means = torch.randn(5000, 3, generator=generator) * 5.0
    quats = torch.randn(5000, 4, generator=generator)
    quats[:20] = 0.0
    log_scales = torch.randn(5000, 3, generator=generator) * 3.0
    pose = torch.as_tensor(_camera(25.0).world_to_cam, dtype=torch.float32)
    on_gpu = facing_cosines(*(t.cuda() for t in (means, quats, log_scales, pose)))
    assert on_gpu.device.type == "cuda" and on_gpu.dtype == torch.float32
    assert torch.allclose(on_gpu.cpu(), facing_cosines(means, quats, log_scales, pose), atol=2e-6)


def test_a_model_without_exponent_renders_its_own_colours_and_one_with_it_darkens_the_flanks():
    plain, shaded = _half_cylinder(0.0), _half_cylinder(0.8)
    camera = _camera(0.0)
    with torch.no_grad():
        a = render_camera(plain, camera, near=0.1)
        b = render_camera(shaded, camera, near=0.1)
    covered = np.nonzero(a.alpha[48].numpy() > 0.99)[0]  # the middle row's columns the cylinder covers
    middle, flank = (slice(40, 56), slice(62, 66)), (slice(40, 56), slice(covered[1], covered[1] + 3))
    ratio = lambda image, region: float((image[region] / a.color[..., 0][region]).mean())  # noqa: E731
    assert ratio(b.color[..., 0], middle) > 0.97  # face on: as bright
    assert ratio(b.color[..., 0], flank) < 0.85  # at a slant: darker
    assert torch.equal(a.alpha, b.alpha) and torch.equal(a.depth, b.depth)  # shading never moves the surface


@pytest.mark.parametrize("exponent, gains", [(0.45, (0.0, -0.1, 0.08)), (0.0, (0.0, 0.05, 0.0)), (1.2, (0.0, 0.0, -0.2))])
def test_the_estimate_recovers_a_known_exponent_and_exposures(exponent, gains):
    cameras = [_camera(0.0), _camera(-40.0), _camera(40.0)]
    views, depths = _photos(_half_cylinder(exponent), cameras, gains)
    estimate = estimate_shading([v.image for v in views], [v.mask for v in views], cameras, depths, blur_px=2.0, stride=1)
    assert estimate.points > 500
    assert estimate.exponent == pytest.approx(exponent, abs=0.06 + 0.15 * exponent)  # blurred renders: a little low
    assert np.allclose(estimate.log_gains, gains, atol=0.04) and estimate.log_gains[0] == 0.0


def test_the_estimate_leaves_clipped_skin_out():
    cameras = [_camera(0.0), _camera(-40.0), _camera(40.0)]
    views, depths = _photos(_half_cylinder(0.45), cameras, (0.0, 0.0, 0.0))
    # the front photo overexposed 2.2x and clipped: its brightest skin reads 1 wherever it was brighter
    views[0] = View("v0", np.clip(2.2 * views[0].image, 0.0, 1.0), views[0].mask)
    assert (views[0].image[views[0].mask] >= 1.0).mean() > 0.3
    estimate = estimate_shading([v.image for v in views], [v.mask for v in views], cameras, depths, blur_px=2.0, stride=1)
    assert estimate.points > 500 and estimate.exponent == pytest.approx(0.45, abs=0.15)
    assert estimate.log_gains[1] == pytest.approx(-math.log(2.2), abs=0.06)


def test_the_estimate_needs_shared_skin():
    cameras = [_camera(0.0), _camera(40.0)]
    views, depths = _photos(_half_cylinder(0.5), cameras, (0.0, 0.0))
    one = estimate_shading([views[0].image], [views[0].mask], cameras[:1], depths[:1])
    assert one.exponent == 0.0 and one.log_gains == [0.0] and one.points == 0
    apart = [np.full_like(d, np.nan) for d in depths]  # no geometry: nothing two views see
    none = estimate_shading([v.image for v in views], [v.mask for v in views], cameras, apart)
    assert none.exponent == 0.0 and none.log_gains == [0.0, 0.0] and none.points == 0


def test_a_fit_with_the_estimated_shading_predicts_a_left_out_slanted_view_better():
    truth = _half_cylinder(0.6)
    train_cameras = [_camera(0.0), _camera(-45.0), _camera(45.0)]
    views, depths = _photos(truth, train_cameras, (0.0, 0.0, 0.0))
    held_out = _camera(25.0)
    target, _ = _photos(truth, [held_out], (0.0,))
    estimate = estimate_shading([v.image for v in views], [v.mask for v in views], train_cameras, depths, blur_px=2.0,
                                stride=1)
    start = truth.with_(sh_dc=torch.zeros_like(truth.sh_dc), facing_exponent=0.0)
    config = SplatConfig(iterations=90, refine_poses=False, densify_from=1000, lr_means=0.0, lr_means_final=0.0,
                         lr_scales=0.0, lr_quats=0.0, lr_opacity=0.0, lr_colors=0.05, lambda_depth=0.0, min_gaussians=1)
    errors = {}
    for exponent in (0.0, estimate.exponent):
        fit = fit_gaussians(start.with_(facing_exponent=exponent), views, train_cameras, config, device="cpu")
        assert all(math.isfinite(x) for x in fit.losses) and fit.gaussians.facing_exponent == exponent
        with torch.no_grad():
            render = render_camera(fit.gaussians, held_out, near=0.1).color[..., 0].numpy()
        errors[exponent] = float(np.abs(render - target[0].image)[target[0].mask].mean())
    assert errors[estimate.exponent] < 0.6 * errors[0.0]


def test_the_exponent_travels_with_the_model_and_its_ply(tmp_path):
    model = _half_cylinder(0.37)
    assert model.subset(torch.arange(5)).facing_exponent == 0.37
    assert model.detach().to("cpu", torch.float64).facing_exponent == 0.37
    assert Gaussians.concat([model.subset(torch.arange(3)), model.subset(torch.arange(3, 6))]).facing_exponent == 0.37
    with pytest.raises(ValueError, match="facing exponents differ"):
        Gaussians.concat([model, _half_cylinder(0.2)])
    for bad in (-0.1, math.nan, MAX_EXPONENT + 1, True, "0.3"):
        with pytest.raises(ValueError, match="facing_exponent"):
            model.with_(facing_exponent=bad)
    path = write_gaussians_ply(tmp_path / "g.ply", model)
    assert read_gaussians_ply(path).facing_exponent == 0.37
    assert read_gaussians_ply(path, channels=1).facing_exponent == 0.37
    # other tools' files carry no such comment: no shading; a broken one names the file
    plain = write_gaussians_ply(tmp_path / "plain.ply", model.with_(facing_exponent=0.0))
    text = plain.read_bytes()
    assert read_gaussians_ply(plain).facing_exponent == 0.0
    (tmp_path / "other.ply").write_bytes(text.replace(f"comment {EXPONENT_COMMENT} 0.0\n".encode(), b""))
    assert read_gaussians_ply(tmp_path / "other.ply").facing_exponent == 0.0
    (tmp_path / "bad.ply").write_bytes(text.replace(f"{EXPONENT_COMMENT} 0.0".encode(), f"{EXPONENT_COMMENT} abc".encode()))
    with pytest.raises(InputError, match="bad.ply.*facing_exponent"):
        read_gaussians_ply(tmp_path / "bad.ply")


def test_gains_are_against_the_geometric_mean_of_the_views_asked_for():
    estimate = ShadingEstimate(0.3, [0.0, math.log(0.8), math.log(1.1)], 1000)
    assert np.prod(estimate.gains()) == pytest.approx(1.0)
    gains = estimate.gains([0, 1])
    assert gains[0] * gains[1] == pytest.approx(1.0) and gains[2] / gains[0] == pytest.approx(1.1)
    assert np.allclose(ShadingEstimate.none(3).gains(), 1.0)


def test_the_splat_stage_fits_every_photo_at_the_views_mean_exposure():
    import open3d as o3d

    from fingersplat3d.splat.stage import run_splat_stage

    truth = _half_cylinder(0.4)
    # large enough for the stage's own estimate (every 4th pixel, blurred past the ridges)
    cameras = [Camera.from_focal(240.0, 280, 210, c.world_to_cam) for c in (_camera(0.0), _camera(-40.0), _camera(40.0))]
    log_gains = (0.0, math.log(0.75), 0.0)  # the left camera's photo a quarter darker
    views, depths = _photos(truth, cameras, log_gains)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(truth.means.double().numpy()))
    cloud.colors = o3d.utility.Vector3dVector(np.full((len(truth), 3), 0.5))
    config = SplatConfig(iterations=40, densify_from=1000, polish_fraction=0.0, lambda_depth=0.0, min_gaussians=1,
                         unseen_skin=False)
    matched = run_splat_stage(views, cameras, [0, 1, 2], cloud, config, depths=depths, device="cpu")
    plain = run_splat_stage(views, cameras, [0, 1, 2], cloud, replace(config, match_exposures=False), depths=depths,
                            device="cpu")
    shading = matched.report["shading"]
    assert shading["exposures_matched"] and not plain.report["shading"]["exposures_matched"]
    mean = math.exp(sum(log_gains) / 3)
    estimated = list(shading["exposure_estimate"].values())
    assert np.allclose(estimated, [math.exp(g) / mean for g in log_gains], atol=0.04)
    # each photo fitted at one exposure, so the renders multiplied by it reproduce all three better than one compromise
    assert min(matched.report["psnr_in_mask_db"].values()) > min(plain.report["psnr_in_mask_db"].values()) + 1.0
    for report in (matched.report, plain.report):
        assert all(math.isfinite(v) for v in report["psnr_in_mask_db"].values())
