"""The fast rasterizer against the dense reference (outputs and gradients), and its semantics."""
import math
import subprocess
import sys

import pytest
import torch

from fingersplat3d.splat import Gaussians, project_gaussians, rasterize, reference_rasterize
from fingersplat3d.splat.gaussians import covariance_3d

F64 = torch.float64


def random_scene(seed, n=40, channels=3, dtype=F64, width=24, height=20):
    """Gaussians in front of a slightly rotated camera, some partly off-screen, a few behind it."""
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=dtype) * torch.tensor([0.6, 0.5, 0.8], dtype=dtype)
    means[:, 2] += 3.0
    means[: max(1, n // 20), 2] = -1.0  # behind the camera
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=dtype) * 0.5 - 2.5)
    opacities = torch.rand(n, generator=g, dtype=dtype) * 0.98 + 0.01
    colors = torch.rand(n, channels, generator=g, dtype=dtype)
    angle = 0.1
    world_to_cam = torch.eye(4, dtype=dtype)
    world_to_cam[:3, :3] = torch.tensor([[math.cos(angle), 0, math.sin(angle)], [0, 1, 0],
                                         [-math.sin(angle), 0, math.cos(angle)]], dtype=dtype)
    world_to_cam[:3, 3] = torch.tensor([0.05, -0.1, 0.2], dtype=dtype)
    K = torch.tensor([[30.0, 0, (width - 1) / 2 + 0.3], [0, 32.0, (height - 1) / 2 - 0.2], [0, 0, 1]], dtype=dtype)
    return [means, quats, scales, opacities, colors, world_to_cam, K], width, height


def weighted_loss(out, seed=123):
    g = torch.Generator().manual_seed(seed)
    weights = [torch.randn(t.shape, generator=g, dtype=t.dtype) for t in (out.color, out.alpha, out.depth)]
    return sum((t * w).sum() for t, w in zip((out.color, out.alpha, out.depth), weights))


@pytest.mark.parametrize("backend", ["numba", "torch"])
@pytest.mark.parametrize("seed,channels,background", [(0, 3, False), (1, 1, True), (2, 3, True), (3, 2, False)])
def test_matches_reference_outputs_and_gradients(seed, channels, background, backend):
    # min_transmittance 0: the numba backend's exact mode (early termination is tested on its own).
    args, width, height = random_scene(seed, channels=channels)
    args = [t.clone().requires_grad_() for t in args]
    kwargs = {"background": torch.rand(channels, dtype=F64) if background else None}
    fast = rasterize(*args, width, height, backend=backend, min_transmittance=0.0, **kwargs)
    ref = reference_rasterize(*args, width, height, **kwargs)
    assert fast.alpha.max() > 0.5 and (fast.radii > 0).sum() > 10  # a scene worth comparing
    for name in ("color", "alpha", "depth", "means2d", "depths"):
        torch.testing.assert_close(getattr(fast, name), getattr(ref, name), rtol=1e-9, atol=1e-9, msg=name)
    assert torch.equal(fast.radii, ref.radii)
    grads_fast = torch.autograd.grad(weighted_loss(fast), args)
    grads_ref = torch.autograd.grad(weighted_loss(ref), args)
    names = ["means", "quats", "scales", "opacities", "colors", "world_to_cam", "K"]
    for name, a, b in zip(names, grads_fast, grads_ref):
        assert b.abs().max() > 0, name
        torch.testing.assert_close(a, b, rtol=1e-7, atol=1e-9 * b.abs().max().item(), msg=name)


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_float32_matches_float64_reference(backend):
    args, width, height = random_scene(5, n=60)
    ref = reference_rasterize(*args, width, height)
    fast = rasterize(*[t.float() for t in args], width, height, backend=backend)
    assert fast.color.dtype == torch.float32
    torch.testing.assert_close(fast.color.double(), ref.color, atol=2e-5, rtol=0)
    torch.testing.assert_close(fast.alpha.double(), ref.alpha, atol=2e-5, rtol=0)


@pytest.mark.parametrize("tile_size", [1, 3, 16])
def test_tile_size_does_not_change_the_result(tile_size):
    args, width, height = random_scene(7)
    base = rasterize(*args, width, height)
    other = rasterize(*args, width, height, tile_size=tile_size)
    torch.testing.assert_close(other.color, base.color, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(other.depth, base.depth, rtol=1e-12, atol=1e-12)


def test_means2d_is_in_the_graph_for_densification_statistics():
    args, width, height = random_scene(8)
    args[0].requires_grad_()
    out = rasterize(*args, width, height)
    out.means2d.retain_grad()
    out.color.sum().backward()
    shown = out.radii > 0
    assert out.means2d.grad is not None and out.means2d.grad[shown].abs().sum(1).gt(0).float().mean() > 0.8
    assert torch.all(out.means2d.grad[~shown] == 0)


def test_gradients_reach_raw_gaussian_parameters():
    args, width, height = random_scene(9, channels=1)
    model = Gaussians(args[0], args[1], torch.log(args[2]), torch.logit(args[3]),
                      (args[4] - 0.5) / 0.28209479177387814)
    raw = [t.requires_grad_() for t in model.tensors()]
    out = rasterize(model.means, model.quats, model.scales, model.opacities, model.colors, args[5], args[6],
                    width, height)
    out.color.sum().backward()
    for t in raw:
        assert t.grad is not None and torch.isfinite(t.grad).all() and t.grad.abs().sum() > 0


def test_single_gaussian_at_a_pixel_centre():
    # A Gaussian centred on pixel (5, 4): alpha there is its opacity, colour is opacity x colour.
    f, z = 20.0, 2.0
    means = torch.tensor([[0.0, 0.0, z]], dtype=F64)
    K = torch.tensor([[f, 0, 5.0], [0, f, 4.0], [0, 0, 1]], dtype=F64)
    out = rasterize(means, torch.tensor([[1.0, 0, 0, 0]], dtype=F64), torch.full((1, 3), 0.05, dtype=F64),
                    torch.tensor([0.6], dtype=F64), torch.tensor([[0.5, 1.0, 0.25]], dtype=F64), torch.eye(4, dtype=F64),
                    K, 12, 8, background=torch.tensor([0.0, 0.0, 1.0], dtype=F64))
    torch.testing.assert_close(out.means2d, torch.tensor([[5.0, 4.0]], dtype=F64))
    assert out.alpha[4, 5] == pytest.approx(0.6)
    torch.testing.assert_close(out.color[4, 5], torch.tensor([0.3, 0.6, 0.15 + 0.4], dtype=F64))
    assert out.depth[4, 5] == pytest.approx(z)
    sigma2 = (f * 0.05 / z) ** 2 + 0.3  # EWA footprint of an isotropic Gaussian seen head-on, plus low-pass
    assert out.alpha[4, 6] == pytest.approx(0.6 * math.exp(-0.5 / sigma2))
    assert out.radii.item() == math.ceil(3 * math.sqrt(sigma2))
    assert out.alpha[0, 0] == 0 and out.depth[0, 0] == 0  # alpha < 1/255 there: skipped


def test_front_gaussian_occludes_and_opacity_clamps_at_0_99():
    K = torch.tensor([[10.0, 0, 2.0], [0, 10.0, 2.0], [0, 0, 1]], dtype=F64)
    means = torch.tensor([[0.0, 0.0, 2.0], [0.0, 0.0, 1.0]], dtype=F64)  # index 1 is in front
    out = rasterize(means, torch.zeros(2, 4, dtype=F64), torch.full((2, 3), 0.5, dtype=F64),
                    torch.tensor([1.0, 1.0], dtype=F64), torch.tensor([[1.0], [0.0]], dtype=F64),
                    torch.eye(4, dtype=F64), K, 5, 5)
    assert out.alpha[2, 2] == pytest.approx(1 - 0.01 * 0.01)
    assert out.color[2, 2, 0] == pytest.approx(0.01 * 0.99)  # the back one seen through the front one's 1 %
    assert out.depth[2, 2] == pytest.approx((0.99 * 1.0 + 0.0099 * 2.0) / (1 - 1e-4))


def test_projection_is_the_linearised_pinhole_projection():
    # Away from the frustum clamp, cov2d = J Sigma J^T + 0.3 I with J the Jacobian of the pixel
    # projection w.r.t. the world point, computed here by autograd.
    args, width, height = random_scene(11, n=10)
    means, quats, scales, _, _, world_to_cam, K = args
    means[:, 2] = 3.0 + torch.rand(10, dtype=F64)
    means[:, :2] = means[:, :2].clamp(-0.3, 0.3)
    proj = project_gaussians(means, quats, scales, world_to_cam, K, width, height)

    def pixel(point):
        p = world_to_cam[:3, :3] @ point + world_to_cam[:3, 3]
        return (K @ (p / p[2]))[:2]

    sigma = covariance_3d(quats, scales)
    for i in range(10):
        jacobian = torch.autograd.functional.jacobian(pixel, means[i])
        expected = jacobian @ sigma[i] @ jacobian.T + 0.3 * torch.eye(2, dtype=F64)
        torch.testing.assert_close(proj.means2d[i], pixel(means[i]))
        torch.testing.assert_close(proj.cov2d[i], expected[[0, 0, 1], [0, 1, 1]])
        conic = torch.linalg.inv(expected)
        torch.testing.assert_close(proj.conics[i], conic[[0, 0, 1], [0, 1, 1]])
    assert proj.valid.all() and (proj.radii > 0).all()


def test_projection_culls_behind_near_plane_and_off_screen():
    K = torch.tensor([[50.0, 0, 16], [0, 50.0, 16], [0, 0, 1]])
    means = torch.tensor([[0, 0, 0.005], [0, 0, -2.0], [100.0, 0, 1.0], [0, 0, 2.0], [0, 0, 0.01]])
    proj = project_gaussians(means, torch.zeros(5, 4), torch.full((5, 3), 0.01), torch.eye(4), K, 32, 32)
    assert proj.valid.tolist() == [False, False, False, True, True]
    assert proj.radii.tolist()[:3] == [0, 0, 0] and (proj.radii[3:] > 0).all()
    assert torch.all(proj.means2d[:3] == 0) and torch.isfinite(proj.conics).all()


@pytest.mark.parametrize("bad", ["means", "colors", "opacities", "K", "world_to_cam", "background", "dtype", "size"])
def test_wrong_inputs_are_refused_with_a_clear_message(bad):
    args, width, height = random_scene(0, n=5)
    kwargs = {}
    if bad == "means":
        args[0] = args[0][:, :2]
    elif bad == "colors":
        args[4] = args[4][:4]
    elif bad == "opacities":
        args[3] = args[3][:, None]
    elif bad == "K":
        args[6] = args[6][:2]
    elif bad == "world_to_cam":
        args[5] = args[5][:3]
    elif bad == "background":
        kwargs["background"] = torch.zeros(2, dtype=F64)
    elif bad == "dtype":
        args[4] = args[4].float()
    else:
        width = 0
    with pytest.raises(ValueError, match="must"):
        rasterize(*args, width, height, **kwargs)


def test_importing_the_rasterizer_does_not_load_open3d():
    code = ("import sys, fingersplat3d.splat.rasterize, fingersplat3d.splat.reference, fingersplat3d.splat.project; "
            "assert 'open3d' not in sys.modules, 'open3d was imported'")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_splat_package_loads_its_names_on_first_use_and_rasterize_stays_the_function():
    """Its settings are read without torch (the parsers' defaults); importing the rasterizer's module first does not turn
    the package's ``rasterize`` into that module."""
    code = ("import sys, types, fingersplat3d.splat.config\n"
            "assert 'torch' not in sys.modules, 'the settings loaded torch'\n"
            "import fingersplat3d.splat.rasterize\n"
            "from fingersplat3d.splat import rasterize, Gaussians, ssim\n"
            "assert callable(rasterize) and not isinstance(rasterize, types.ModuleType)\n"
            "assert rasterize is sys.modules['fingersplat3d.splat.rasterize'].rasterize")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.slow
def test_compiled_path_matches_the_eager_path():
    # torch.compile kernels (first call compiles for tens of seconds): same outputs and gradients.
    args, width, height = random_scene(12, n=300, channels=3, dtype=torch.float32, width=64, height=48)
    args[2] = args[2] * 2.0
    results = []
    for compiled in (False, True):
        leaves = [t.clone().requires_grad_() for t in args]
        out = rasterize(*leaves, width, height, compiled=compiled, background=torch.tensor([0.1, 0.2, 0.3]))
        grads = torch.autograd.grad(weighted_loss(out), leaves)
        results.append((out, grads))
    (eager, eager_grads), (fast, fast_grads) = results
    assert eager.alpha.max() > 0.5
    for name in ("color", "alpha", "depth", "means2d"):
        torch.testing.assert_close(getattr(fast, name), getattr(eager, name), rtol=1e-4, atol=1e-5, msg=name)
    assert torch.equal(fast.radii, eager.radii)
    for a, b in zip(fast_grads, eager_grads):
        torch.testing.assert_close(a, b, rtol=1e-3, atol=1e-4 * b.abs().max().item())
