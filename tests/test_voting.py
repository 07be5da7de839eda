"""Multi-view mask voting and boundary decomposition (SAGD-style clean-up of a fitted splat)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fingersplat3d.errors import InputError
from fingersplat3d.eval.image import fraction_alpha_outside
from fingersplat3d.scene import Camera, look_at
from fingersplat3d.splat.voting import (
    CleanConfig,
    clean_with_masks,
    split_gaussians,
    straddle_axes,
    vote_labels,
)
from fingersplat3d.splat.gaussians import Gaussians, rgb_to_sh
from fingersplat3d.splat.gaussians import covariance_3d
from fingersplat3d.synth.rigs import rotation_about

FOCAL, WIDTH, HEIGHT, DISTANCE = 400.0, 64, 48, 100.0  # 4 px per unit at the target


def rig(angles=(-30.0, 0.0, 30.0)) -> list[Camera]:
    """Cameras on a ring about the world x axis, all looking at the origin, image right = +x."""
    cameras = []
    for angle in angles:
        rotation = rotation_about([1.0, 0.0, 0.0], angle)
        eye = rotation @ np.array([0.0, 0.0, -DISTANCE])
        cameras.append(Camera.from_focal(FOCAL, WIDTH, HEIGHT, look_at(eye, np.zeros(3), rotation @ [0.0, -1.0, 0.0])))
    return cameras


def half_masks(cameras) -> list[np.ndarray]:
    """Foreground = world x < 0: the plane x = 0 contains every camera centre, so it images to u = cx."""
    masks = []
    for camera in cameras:
        mask = np.zeros((camera.height, camera.width), bool)
        mask[:, :int(np.floor(camera.K[0, 2] + 0.5))] = True  # pixel centres u < cx
        masks.append(mask)
    return masks


def make_gaussians(means, scales, channels: int = 1, dtype=torch.float32) -> Gaussians:
    means = torch.as_tensor(np.asarray(means, np.float64), dtype=dtype).reshape(-1, 3)
    count = len(means)
    scales = torch.as_tensor(np.broadcast_to(np.asarray(scales, np.float64), (count, 3)).copy(), dtype=dtype)
    quats = torch.zeros(count, 4, dtype=dtype)
    quats[:, 0] = 1.0
    colours = torch.linspace(0.2, 0.8, count, dtype=dtype)[:, None].repeat(1, channels)
    return Gaussians(means, quats, scales.log(), torch.full((count,), 2.0, dtype=dtype), rgb_to_sh(colours))


def test_votes_inside_and_outside():
    cameras = rig()
    means = torch.tensor([[-1.0, 0.0, 0.0], [-2.0, 1.0, 0.5], [1.0, 0.0, 0.0], [2.5, -1.0, 0.0]])
    votes = vote_labels(means, cameras, half_masks(cameras))
    assert votes.seen.tolist() == [3, 3, 3, 3]
    assert votes.foreground.tolist() == [3, 3, 0, 0]
    assert votes.background.tolist() == [0, 0, 3, 3]


def test_behind_the_camera_or_outside_the_image_does_not_vote():
    camera = rig((0.0,))[0]  # at z = -100 looking along +z
    mask = np.ones((HEIGHT, WIDTH), bool)
    mask[:, 40:] = False
    # (5, 0, -200) is 100 behind the camera; dividing by its negative depth would land at u = 11.5,
    # inside the mask: it must not vote. (100, 0, 0) projects far right of the image.
    means = torch.tensor([[5.0, 0.0, -200.0], [100.0, 0.0, 0.0], [0.0, 0.0, -99.995], [-1.0, 0.0, 0.0]])
    votes = vote_labels(means, [camera], [mask], near=0.01)
    assert votes.seen.tolist() == [0, 0, 0, 1]  # the third is closer than `near`
    assert vote_labels(means, [camera], [mask]).seen.tolist() == [0, 0, 1, 1]  # default near = 0
    assert votes.foreground.tolist() == [0, 0, 0, 1]


def test_clean_keeps_inside_removes_outside_keeps_unseen():
    cameras = rig()
    means = [[-2.0, 0.0, 0.0], [-1.0, 1.0, 0.0], [2.0, 0.0, 0.0], [1.5, -1.0, 1.0], [500.0, 0.0, 0.0]]
    gaussians = make_gaussians(means, 0.05, channels=3)
    cleaned, stats = clean_with_masks(gaussians, cameras, half_masks(cameras))
    kept = sorted(cleaned.means[:, 0].tolist())
    assert kept == [-2.0, -1.0, 500.0]  # the unseen one is kept: no view has evidence against it
    assert (stats.input_count, stats.removed_background, stats.unseen, stats.split, stats.output_count) == (5, 2, 1, 0, 3)
    assert cleaned.channels == 3


def test_minority_vote_is_removed():
    """A floater inside the silhouette in one view only is background (1 of 3 < 0.6)."""
    cameras = rig()
    masks = half_masks(cameras)
    masks[2] = ~masks[2]  # the third view disagrees about everything
    gaussians = make_gaussians([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], 0.05)
    votes = vote_labels(gaussians.means, cameras, masks)
    assert votes.foreground.tolist() == [2, 1]
    cleaned, _ = clean_with_masks(gaussians, cameras, masks)
    assert cleaned.means[:, 0].tolist() == [-1.0]


def test_a_margin_of_the_ridge_period_keeps_skin_just_off_an_outline_and_not_floaters():
    """Given the views' ridge periods, a view votes foreground within ``margin_periods`` of them of its mask: a
    Gaussian 2 px off the outline (the skin next to a silhouette, placed a little off it) stays, one 12 px off (a
    floater over the background) goes, as without a margin; without periods the vote is SAGD's, at the mask alone."""
    cameras = rig()
    masks = half_masks(cameras)  # 4 px per unit at the target: x = 0.5 is 2 px off every mask, x = 3 is 12 px
    gaussians = make_gaussians([[-1.0, 0.0, 0.0], [0.5, 0.0, 0.0], [3.0, 0.0, 0.0]], 0.05)
    kept, stats = clean_with_masks(gaussians, cameras, masks, CleanConfig(rounds=0), periods=[16.0] * 3)
    assert kept.means[:, 0].tolist() == [-1.0, 0.5] and stats.removed_background == 1
    assert clean_with_masks(gaussians, cameras, masks, CleanConfig(rounds=0))[0].means[:, 0].tolist() == [-1.0]
    tight = CleanConfig(rounds=0, margin_periods=0.1)  # 1.6 px: the one 2 px off goes too
    assert clean_with_masks(gaussians, cameras, masks, tight, periods=[16.0] * 3)[0].means[:, 0].tolist() == [-1.0]
    with pytest.raises(ValueError, match="margins"):
        clean_with_masks(gaussians, cameras, masks, periods=[16.0] * 2)


def test_straddling_gaussian_is_split_and_the_outside_child_removed():
    cameras = rig()
    masks = half_masks(cameras)
    gaussians = make_gaussians([[-0.5, 0.0, 0.0], [-3.0, 0.0, 0.0]], [1.0, 0.3, 0.3])  # first crosses x = 0
    assert straddle_axes(gaussians, cameras, masks).tolist() == [0, -1]
    cleaned, stats = clean_with_masks(gaussians, cameras, masks, CleanConfig(rounds=1))
    assert stats.split == 1 and stats.removed_children == 1 and len(cleaned) == 2
    child = cleaned.subset(cleaned.means[:, 0] > -2.5)
    offset = math.sqrt(1 - 0.25)
    assert child.means[0].tolist() == pytest.approx([-0.5 - offset, 0.0, 0.0], abs=1e-6)
    assert child.scales[0].tolist() == pytest.approx([0.5, 0.3, 0.3], rel=1e-6)
    assert torch.equal(child.sh_dc, gaussians.sh_dc[:1]) and torch.equal(child.opacity_logits, gaussians.opacity_logits[:1])
    # its footprint (mean +- 1.5 sigma along every axis) now lies inside every mask
    assert straddle_axes(child, cameras, masks).tolist() == [-1]
    assert child.means[0, 0] + 1.5 * child.scales[0, 0] < 0


def test_split_preserves_mean_and_variance_along_the_axis():
    """Child scale 1/2 at +-sqrt(3)/2 sigma: the pair has the parent's mean and covariance."""
    gaussians = Gaussians(torch.tensor([[1.0, 2.0, 3.0]], dtype=torch.float64),
                          torch.tensor([[0.9, 0.1, -0.3, 0.2]], dtype=torch.float64),
                          torch.tensor([[0.2, 0.5, 1.0]], dtype=torch.float64).log(),
                          torch.zeros(1, dtype=torch.float64), torch.zeros(1, 1, dtype=torch.float64))
    parent = covariance_3d(gaussians.quats, gaussians.scales)[0]
    for axis in range(3):
        children = split_gaussians(gaussians, torch.tensor([axis]))
        assert len(children) == 2
        assert torch.allclose(children.means.mean(0), gaussians.means[0])
        spread = children.means - children.means.mean(0)
        mixture = covariance_3d(children.quats, children.scales).mean(0) + spread.T @ spread / 2
        assert torch.allclose(mixture, parent, atol=1e-12)


def test_rounds_converge_to_a_clean_edge_and_keep_device_and_dtype():
    cameras = rig()
    masks = half_masks(cameras)
    rng = np.random.default_rng(0)
    means = np.column_stack([rng.uniform(-4, 1, 200), rng.uniform(-3, 3, 200), rng.uniform(-1, 1, 200)])
    gaussians = make_gaussians(means, rng.uniform(0.1, 1.0, (200, 3)), dtype=torch.float64)
    cleaned, stats = clean_with_masks(gaussians, cameras, masks, CleanConfig(rounds=4))
    assert cleaned.means.dtype == torch.float64 and cleaned.means.device == gaussians.means.device
    assert stats.split > 0 and stats.output_count == len(cleaned)
    once, _ = clean_with_masks(gaussians, cameras, masks, CleanConfig(rounds=1))
    def straddling(model: Gaussians) -> int:
        return int((straddle_axes(model, cameras, masks) >= 0).sum())

    assert straddling(cleaned) < straddling(once)
    assert (cleaned.means[:, 0] < 0).all()


def test_bad_input():
    cameras = rig()
    masks = half_masks(cameras)
    gaussians = make_gaussians([[0.0, 0.0, 0.0]], 0.1)
    with pytest.raises(ValueError):
        clean_with_masks(gaussians, cameras, masks[:2])
    with pytest.raises(InputError, match="empty"):
        clean_with_masks(gaussians, cameras, [masks[0], masks[1], np.zeros_like(masks[2])])
    with pytest.raises(InputError, match="mask 1"):
        vote_labels(gaussians.means, cameras, [masks[0], masks[1][:-1], masks[2]])
    with pytest.raises(ValueError):
        CleanConfig(child_scale=1.0)
    with pytest.raises(ValueError, match="margin_periods"):
        CleanConfig(margin_periods=float("nan"))
    empty = gaussians.subset(torch.zeros(1, dtype=torch.bool))
    cleaned, stats = clean_with_masks(empty, cameras, masks)
    assert len(cleaned) == 0 and stats.output_count == 0


def test_render_leaks_less_alpha_after_cleaning():
    """Rendered with the rasterizer: the share of alpha off the mask drops after cleaning."""
    rasterize = pytest.importorskip("fingersplat3d.splat.rasterize").rasterize
    cameras = rig()
    masks = half_masks(cameras)
    rng = np.random.default_rng(1)
    count = 300
    means = np.column_stack([rng.uniform(-5, 3, count), rng.uniform(-4, 4, count), rng.uniform(-0.3, 0.3, count)])
    gaussians = make_gaussians(means, rng.uniform(0.2, 0.8, (count, 3)))

    def leak(model: Gaussians) -> float:
        camera = cameras[1]
        out = rasterize(model.means, model.rotations, model.scales, model.opacities, model.colors,
                        torch.as_tensor(camera.world_to_cam, dtype=torch.float32),
                        torch.as_tensor(camera.K, dtype=torch.float32), camera.width, camera.height)
        return fraction_alpha_outside(out.alpha.detach().numpy(), masks[1])

    cleaned, stats = clean_with_masks(gaussians, cameras, masks, CleanConfig(rounds=3))
    before, after = leak(gaussians), leak(cleaned)
    print(f"alpha outside the mask: before {before:.3f}, after {after:.3f}; {stats}")
    assert before > 0.25
    assert after < 0.05 and after < before / 5
    # With a margin (a quarter of a 4 px ridge period: 1 px), what is left outside is within it.
    margined, _ = clean_with_masks(gaussians, cameras, masks, CleanConfig(rounds=3, margin_periods=0.25),
                                   periods=[4.0] * 3)
    assert after <= leak(margined) < 0.08


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_runs_on_the_gaussians_device():
    cameras = rig()
    gaussians = make_gaussians([[-0.5, 0.0, 0.0], [2.0, 0.0, 0.0]], [1.0, 0.3, 0.3]).to("cuda")
    cleaned, stats = clean_with_masks(gaussians, cameras, half_masks(cameras), CleanConfig(rounds=1))
    assert cleaned.means.is_cuda and stats.split == 1 and len(cleaned) == 1
