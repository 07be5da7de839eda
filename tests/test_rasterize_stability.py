"""Numerical extremes: outputs and gradients of the fast rasterizer stay finite."""
import math

import pytest
import torch

from fingersplat3d.splat import rasterize, reference_rasterize

_rasterize = rasterize

WIDTH, HEIGHT = 20, 16


def base_scene(n=12, dtype=torch.float32, seed=0):
    """A unit-sized scene 3 units in front of the camera, seen with a 20-px focal length."""
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g) - 0.5) * torch.tensor([2.0, 1.6, 1.0]) + torch.tensor([0, 0, 3.0])
    quats = torch.randn(n, 4, generator=g)
    scales = torch.full((n, 3), 0.1)
    opacities = torch.rand(n, generator=g) * 0.9 + 0.05
    colors = torch.rand(n, 3, generator=g)
    K = torch.tensor([[20.0, 0, (WIDTH - 1) / 2], [0, 20.0, (HEIGHT - 1) / 2], [0, 0, 1]])
    return {"means": means.to(dtype), "quats": quats.to(dtype), "scales": scales.to(dtype),
            "opacities": opacities.to(dtype), "colors": colors.to(dtype), "world_to_cam": torch.eye(4, dtype=dtype),
            "K": K.to(dtype)}


@pytest.fixture(params=["numba", "torch"], autouse=True)
def backend(request, monkeypatch):
    """Every extreme on both backends: ``rasterize`` below is the module's, rebound per backend."""
    import functools

    monkeypatch.setitem(globals(), "rasterize", functools.partial(_rasterize, backend=request.param))
    return request.param


def render_and_check(scene, renderer=None, **kwargs):
    renderer = renderer or rasterize
    leaves = {k: v.clone().requires_grad_() for k, v in scene.items()}
    out = renderer(**leaves, width=WIDTH, height=HEIGHT, **kwargs)
    for name in ("color", "alpha", "depth", "means2d", "depths"):
        assert torch.isfinite(getattr(out, name)).all(), name
    assert (out.alpha >= 0).all() and (out.alpha < 1).all() and (out.radii >= 0).all()
    loss = out.color.sum() + out.alpha.sum() + out.depth.sum() + out.means2d.sum()
    loss.backward()
    for name, leaf in leaves.items():
        assert leaf.grad is not None and torch.isfinite(leaf.grad).all(), name
    return out, leaves


@pytest.mark.parametrize("scale", [1e-6, 1e-3, 1.0, 1e2, 1e3])
def test_scales_from_tiny_to_huge(scale):
    scene = base_scene()
    scene["scales"] = torch.full_like(scene["scales"], scale)
    out, _ = render_and_check(scene)
    if scale >= 1e2:
        assert out.alpha.min() > 0.5  # every pixel is covered
    if scale <= 1e-3:  # the low-pass filter keeps sub-pixel Gaussians visible
        assert out.alpha.max() > 0.05


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_near_singular_covariances(dtype):
    scene = base_scene(dtype=dtype)
    scene["scales"][:, 1] = 1e-9
    scene["scales"][:4, 0] = 1e3  # long needles as well as flat disks
    render_and_check(scene)


def test_behind_the_camera_and_on_the_near_plane():
    scene = base_scene()
    near = 0.01
    scene["means"][0] = torch.tensor([0.0, 0.0, near])  # exactly on the near plane: kept
    scene["means"][1] = torch.tensor([0.0, 0.0, 0.0])  # at the camera centre
    scene["means"][2] = torch.tensor([0.1, 0.0, -1.0])  # behind
    scene["means"][3] = torch.tensor([0.001, 0.0, near * 0.999])  # just behind the near plane
    out, leaves = render_and_check(scene, near=near)
    assert out.radii[0] > 0 and out.radii[1:4].tolist() == [0, 0, 0]
    assert torch.all(leaves["means"].grad[1:4] == 0)


def test_world_points_with_zero_camera_z_when_everything_is_culled():
    scene = base_scene()
    scene["means"][:, 2] = 0.0
    out, _ = render_and_check(scene)
    assert out.alpha.max() == 0 and (out.radii == 0).all()


@pytest.mark.parametrize("opacity", [0.0, 1.0 / 255.0, 1.0])
def test_opacity_zero_threshold_and_one(opacity):
    scene = base_scene()
    scene["opacities"] = torch.full_like(scene["opacities"], opacity)
    out, _ = render_and_check(scene)
    if opacity == 1.0:
        assert out.alpha.max().item() == pytest.approx(1 - 0.01 ** 2, abs=0.02)
    else:
        assert out.alpha.max() <= 1.0 / 255.0 + 1e-7


def test_zero_quaternion_is_the_identity():
    scene = base_scene()
    zero = dict(scene, quats=torch.zeros_like(scene["quats"]))
    identity = dict(scene, quats=torch.tensor([1.0, 0, 0, 0]).expand(len(scene["quats"]), 4).contiguous())
    out_zero, _ = render_and_check(zero)
    out_identity = rasterize(**identity, width=WIDTH, height=HEIGHT)
    torch.testing.assert_close(out_zero.color, out_identity.color)


@pytest.mark.parametrize("focal", [1e-3, 1.0, 1e3, 1e5, 1e7])
def test_extreme_focal_lengths(focal):
    scene = base_scene()
    scene["K"][0, 0] = scene["K"][1, 1] = focal
    out, _ = render_and_check(scene)
    if focal <= 1.0:  # the whole scene projects onto the principal point
        assert out.alpha[HEIGHT // 2, WIDTH // 2] > 0.5


@pytest.mark.parametrize("n", [0, 1])
def test_empty_and_single_gaussian_scenes(n):
    scene = {k: (v[:n] if k not in ("K", "world_to_cam") else v) for k, v in base_scene().items()}
    out, _ = render_and_check(scene)
    assert out.color.shape == (HEIGHT, WIDTH, 3) and out.means2d.shape == (n, 2) and out.radii.shape == (n,)
    if n == 0:
        assert out.alpha.max() == 0


def test_everything_at_once_matches_the_reference():
    # Mixed extremes in one scene, in float64: the fast path still agrees with the dense reference.
    scene = base_scene(n=24, dtype=torch.float64, seed=3)
    scene["scales"][0:3] = torch.tensor([1e-6, 1e-6, 1e-6], dtype=torch.float64)
    scene["scales"][3:6, 1] = 1e-8
    scene["scales"][6] = 30.0
    scene["opacities"][7], scene["opacities"][8] = 0.0, 1.0
    scene["quats"][9] = 0.0
    scene["means"][10, 2] = -0.5
    scene["means"][11] = torch.tensor([40.0, 0.0, 3.0], dtype=torch.float64)  # far off-screen, on the clamp
    fast, _ = render_and_check(scene)
    ref, _ = render_and_check(scene, reference_rasterize)
    torch.testing.assert_close(fast.color, ref.color, rtol=1e-8, atol=1e-10)
    torch.testing.assert_close(fast.depth, ref.depth, rtol=1e-8, atol=1e-10)
    assert torch.equal(fast.radii, ref.radii)
    assert math.isfinite(float(fast.depth.detach().sum()))
