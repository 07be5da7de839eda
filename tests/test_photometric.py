"""Dense photometric refinement: the differentiable sampler, and the refinement on a synthetic capture."""
import numpy as np
import pytest
import torch

from fingersplat3d.sampling import sample_bilinear, sample_bilinear_torch


def test_the_torch_sampler_equals_the_numpy_one_inside_and_is_zero_outside():
    rng = np.random.default_rng(0)
    image = rng.random((30, 40))
    inside = rng.random((200, 2)) * [39, 29]
    got = sample_bilinear_torch(torch.tensor(image), torch.tensor(inside)).numpy()
    assert np.allclose(got, sample_bilinear(image, inside), atol=1e-12)
    outside = torch.tensor([[-3.0, 5.0], [45.0, 5.0], [5.0, 40.0]], dtype=torch.float64)
    assert np.all(sample_bilinear_torch(torch.tensor(image), outside).numpy() == 0)


def test_the_torch_sampler_gradient_in_image_and_position_is_exact():
    rng = np.random.default_rng(1)
    image = torch.tensor(rng.random((12, 15)), requires_grad=True)
    uv = torch.tensor(rng.random((20, 2)) * [13, 10] + 0.3, requires_grad=True)  # away from the pixel grid's kinks
    assert torch.autograd.gradcheck(sample_bilinear_torch, (image, uv), eps=1e-6, atol=1e-8)


@pytest.fixture(scope="module")
def unrefined(uwa640):
    from fingersplat3d.align.register import RegistrationConfig, _prepare, register_views
    from fingersplat3d.align.solve.photometric import PhotometricConfig
    from fingersplat3d.pointmaps import get_backend
    from fingersplat3d.segment.masks import finger_mask

    views = [view.with_(mask=finger_mask(view.image), camera=None, depth=None) for view in uwa640.views]
    pointmaps = get_backend("prior").predict_views(views)
    config = RegistrationConfig(photometric=PhotometricConfig(iterations=0))
    result = register_views(views, pointmaps, config)
    assert not result.photometric  # off: no record
    return views, pointmaps, config, result, _prepare(views)


def _depth_mae(depths, capture) -> float:
    from fingersplat3d.eval.depth import depth_errors

    return float(np.mean([depth_errors(d, view.depth, np.isfinite(view.depth)).mae
                          for d, view in zip(depths, capture.views)]))


def test_the_refinement_brings_the_ridges_into_phase_without_moving_the_turns(uwa640, unrefined):
    from fingersplat3d.align.solve.photometric import PhotometricConfig, refine_alignment
    from fingersplat3d.eval import relative_rotation_errors

    views, pointmaps, config, result, prepared = unrefined
    refined, record = refine_alignment(result.alignment, [p.depth for p in pointmaps], [p.focal for p in pointmaps],
                                       result.correspondences, config.global_align, prepared.textures, prepared.masks,
                                       prepared.period, PhotometricConfig())
    assert record["samples"] > 1000 and record["agreement_after"] >= record["agreement_before"]
    truth = [view.camera.world_to_cam for view in uwa640.views]
    before = relative_rotation_errors(result.alignment.world_to_cam, truth)
    after = relative_rotation_errors(refined.world_to_cam, truth)
    assert np.max(after) < 3.0 and np.max(np.abs(np.asarray(after) - np.asarray(before))) < 0.5
    # The surface stays the finger's: whole-view depth error no worse than a tenth above the unrefined one.
    assert _depth_mae(refined.depths, uwa640) <= 1.1 * _depth_mae(result.alignment.depths, uwa640)
    assert all(np.isfinite(d[np.isfinite(a)]).all() for d, a in zip(refined.depths, result.alignment.depths))


def test_facing_weight_ramps_from_grazing_to_square_and_stays_finite():
    from fingersplat3d.align.solve.photometric import FACING_HIGH, FACING_LOW, facing_weight

    cosine = np.array([np.nan, -1.0, 0.0, FACING_LOW, 0.5 * (FACING_LOW + FACING_HIGH), FACING_HIGH, 1.0, np.inf])
    weight = facing_weight(cosine)
    assert np.all(np.isfinite(weight)) and np.all((weight >= 0) & (weight <= 1))
    assert np.allclose(weight[:7], [0, 0, 0, 0, 0.5, 1, 1])


def test_surface_normals_of_a_tilted_plane_are_its_normal():
    from fingersplat3d.align.solve.photometric import _surface_normals

    focal, centre = 500.0, np.array([31.5, 23.5])
    normal = np.array([0.3, -0.2, -1.0]) / np.linalg.norm([0.3, -0.2, -1.0])
    v, u = np.mgrid[0:48, 0:64].astype(np.float64)
    rays = np.stack([(u - centre[0]) / focal, (v - centre[1]) / focal, np.ones_like(u)], -1)
    depth = -100.0 / (rays @ normal)  # the plane n.X = 100 (toward the camera: n_z < 0)
    depth[:, -1] = np.nan  # one edge without depth: the normal there is taken backwards
    uv = np.array([[10.0, 10.0], [62.0, 20.0], [63.0, 5.0]])
    got, points = _surface_normals(depth, uv, focal, centre)
    assert np.allclose(np.abs(got[:2] @ normal), 1.0, atol=1e-9)
    assert np.allclose(points[0], rays[10, 10] * depth[10, 10])
    assert not np.isfinite(got[2]).all()  # no depth at the sample itself: no normal


@pytest.mark.slow
def test_fuse_with_photometric_reports_the_ridge_agreement(tmp_path):
    import json
    from pathlib import Path

    from fingersplat3d.cli.main import main

    sample = Path(__file__).resolve().parents[1] / "data_samples" / "uwa_seed0"
    assert main(["fuse", str(sample), "-o", str(tmp_path / "out"), "--no-splat", "--photometric"]) == 0
    record = json.loads((tmp_path / "out" / "report.json").read_text())["registration"]["photometric"]
    assert record["samples"] > 1000 and record["agreement_after"] >= record["agreement_before"] - 0.01
    assert record["seconds"] > 0
