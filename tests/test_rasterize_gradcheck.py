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
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rasterize_gradcheck(seed):
    # The whole rasterizer (projection autograd + hand-written compositor backward) against finite
    # differences; fast mode (random projections of the Jacobian) keeps it to a second.
    inputs = [t.clone().requires_grad_() for t in small_scene(seed)]
    background = torch.tensor([0.2, 0.7], dtype=F64)

    def render(*args):
        out = rasterize(*args, WIDTH, HEIGHT, background=background)
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
