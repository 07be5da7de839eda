"""float64 gradcheck: analytic gradients of the rasterizer against finite differences."""
import pytest
import torch

from fingersplat3d.splat import project_gaussians, rasterize

F64 = torch.float64
WIDTH, HEIGHT = 9, 7


def small_scene(seed, n=5, channels=2):
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g, dtype=F64) - 0.5) * torch.tensor([1.2, 1.0, 0.5], dtype=F64)
    means[:, 2] += 2.5
    quats = torch.randn(n, 4, generator=g, dtype=F64)
    scales = 0.08 + 0.1 * torch.rand(n, 3, generator=g, dtype=F64)
    opacities = 0.2 + 0.7 * torch.rand(n, generator=g, dtype=F64)
    colors = torch.rand(n, channels, generator=g, dtype=F64)
    world_to_cam = torch.eye(4, dtype=F64)
    world_to_cam[:3, 3] = torch.tensor([0.02, -0.03, 0.1], dtype=F64)
    K = torch.tensor([[12.0, 0, 4.1], [0, 12.5, 2.9], [0, 0, 1]], dtype=F64)
    return [means, quats, scales, opacities, colors, world_to_cam, K]


@pytest.mark.gradcheck
@pytest.mark.parametrize("backend", ["numba", "torch"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rasterize_gradcheck(seed, backend):
    # The whole rasterizer (projection autograd + hand-written compositor backward) against finite
    # differences; fast mode (random projections of the Jacobian) keeps it to a second.
    inputs = [t.clone().requires_grad_() for t in small_scene(seed)]
    background = torch.tensor([0.2, 0.7], dtype=F64)

    def render(*args):
        out = rasterize(*args, WIDTH, HEIGHT, background=background, backend=backend)
        return out.color, out.alpha, out.depth, out.means2d

    assert torch.autograd.gradcheck(render, inputs, eps=1e-6, atol=1e-6, rtol=1e-4, fast_mode=True)


@pytest.mark.gradcheck
def test_projection_gradcheck():
    means, quats, scales, _, _, world_to_cam, K = [t.clone().requires_grad_() for t in small_scene(2, n=6)]

    def project(*args):
        proj = project_gaussians(*args, WIDTH, HEIGHT)
        return proj.means2d, proj.conics, proj.cov2d, proj.depths

    assert torch.autograd.gradcheck(project, (means, quats, scales, world_to_cam, K), eps=1e-6, atol=1e-6, rtol=1e-4,
                                    fast_mode=True)


@pytest.mark.gradcheck
@pytest.mark.parametrize("tile_size", [2, 4])
def test_composite_backward_gradcheck(tile_size):
    # The hand-written backward of the compositor alone, on fixed bins (float64).
    from fingersplat3d.splat.binning import bin_gaussians
    from fingersplat3d.splat.composite import composite_tiles
    from fingersplat3d.splat.project import _project

    means, quats, scales, opacities, colors, world_to_cam, K = small_scene(3, n=6, channels=1)
    proj, boxes = _project(means, quats, scales, world_to_cam, K, WIDTH, HEIGHT, 0.01, 0.3, opacities)
    bins = bin_gaussians(boxes, proj.valid, proj.depths, WIDTH, HEIGHT, tile_size)
    assert bins.num_pairs > 10
    feats = torch.cat([colors, torch.ones_like(colors), proj.depths[:, None]], 1)
    inputs = [t.detach().clone().requires_grad_() for t in (proj.means2d, proj.conics, opacities, feats)]

    def composite(means2d, conics, opacities, feats):
        return composite_tiles(bins, means2d, conics, opacities, feats, WIDTH, HEIGHT, block_pairs=40)

    assert torch.autograd.gradcheck(composite, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)


@pytest.mark.gradcheck
@pytest.mark.parametrize("seed", [2, 4])
def test_cpu_projection_gradcheck(seed):
    # The numba projection's hand-written backward, pose and K included; seed 4 puts Gaussians
    # beyond the frustum clamp (the Jacobian's limits depend on fx and cx).
    from fingersplat3d.splat.cpu_raster import project_cpu

    means, quats, scales, opacities, _, world_to_cam, K = small_scene(seed, n=6)
    if seed == 4:
        means[:2, 0] = torch.tensor([4.0, -4.0], dtype=F64)  # x / z far outside the clamped frustum
        means[:2, 1] = torch.tensor([0.1, -0.1], dtype=F64)
        scales[:2] = 1.5  # large enough for the footprint to reach the image
    world_to_cam[:3, :3] = torch.linalg.matrix_exp(torch.tensor([[0, -0.1, 0.05], [0.1, 0, -0.2], [-0.05, 0.2, 0]],
                                                                dtype=F64))
    inputs = [t.clone().requires_grad_() for t in (means, quats, scales, world_to_cam, K)]

    def project(means, quats, scales, world_to_cam, K):
        proj, _ = project_cpu(means, quats, scales, opacities, world_to_cam, K, WIDTH, HEIGHT, 0.01, 0.3)
        return proj.means2d, proj.conics, proj.depths

    assert project_cpu(*inputs[:3], opacities, *inputs[3:], WIDTH, HEIGHT, 0.01, 0.3)[0].valid.sum() >= 4
    assert torch.autograd.gradcheck(project, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)


@pytest.mark.gradcheck
@pytest.mark.parametrize("seed", [3, 5])
def test_cpu_composite_backward_gradcheck(seed):
    # The numba compositor's backward alone (exact mode), on a fixed projection.
    from fingersplat3d.splat.cpu_raster import composite_cpu
    from fingersplat3d.splat.project import _project

    means, quats, scales, opacities, colors, world_to_cam, K = small_scene(seed, n=6, channels=1)
    proj, boxes = _project(means, quats, scales, world_to_cam, K, WIDTH, HEIGHT, 0.01, 0.3, opacities)
    feats = torch.cat([colors, proj.depths[:, None]], 1)
    inputs = [t.detach().clone().requires_grad_() for t in (proj.means2d, proj.conics, opacities, feats)]

    def composite(means2d, conics, opacities, feats):  # image and alpha
        return composite_cpu(means2d, conics, opacities, feats, boxes, proj.valid, proj.depths, WIDTH, HEIGHT, 0.0)

    assert torch.autograd.gradcheck(composite, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)
