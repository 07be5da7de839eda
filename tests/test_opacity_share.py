"""`opacity_share`: which Gaussians a rendered pixel comes from (the left-out views' split into seen and unseen skin)."""
import numpy as np
import pytest
import torch

from fingersplat3d.scene import Camera, look_at
from fingersplat3d.splat.gaussians import Gaussians, rgb_to_sh
from fingersplat3d.splat.novel import opacity_share

SIZE = (96, 64)
FOCAL = 120.0


def _camera() -> Camera:
    return Camera.from_focal(FOCAL, SIZE[0], SIZE[1], look_at([0.0, 0.0, -10.0], [0.0, 0.0, 0.0], [0.0, -1.0, 0.0]))


def _discs(means, scale=0.6, opacity=0.99, colours=None) -> Gaussians:
    """Round opaque discs facing the camera (thin along z) at ``means``; ``colours``: their grey levels."""
    means = torch.tensor(means, dtype=torch.float32)
    count = len(means)
    quats = torch.zeros(count, 4)
    quats[:, 0] = 1.0
    log_scales = torch.log(torch.tensor([[scale, scale, 0.01]] * count))
    logits = torch.full((count,), float(np.log(opacity / (1.0 - opacity))))
    grey = torch.full((count, 1), 0.5) if colours is None else torch.tensor(colours, dtype=torch.float32)[:, None]
    return Gaussians(means, quats, log_scales, logits, rgb_to_sh(grey), facing_exponent=0.5)


def _pixel(camera: Camera, point) -> tuple[int, int]:
    uv = camera.project(np.asarray([point], np.float64))[0][0]  # (uv, depth) of the one point
    return int(round(uv[1])), int(round(uv[0]))


def test_each_pixel_counts_the_gaussians_it_is_made_of():
    camera = _camera()
    left, right = [-2.0, 0.0, 0.0], [2.0, 0.0, 0.0]
    model = _discs([left, right], colours=[0.1, 0.9])  # colours and shading play no part
    share = opacity_share(model, torch.tensor([True, False]), camera)
    assert share.shape == (SIZE[1], SIZE[0]) and share.dtype == np.float32
    assert np.isfinite(share).all() and share.min() >= 0.0 and share.max() <= 1.0
    assert share[_pixel(camera, left)] > 0.99 and share[_pixel(camera, right)] < 0.01
    assert share[0, 0] == 0.0  # nothing opaque there: no share, not NaN
    everything = opacity_share(model, torch.tensor([True, True]), camera)
    nothing = opacity_share(model, torch.tensor([False, False]), camera)
    seen = everything > 0
    assert np.allclose(everything[seen], 1.0, atol=1e-4) and not nothing.any()


def test_a_gaussian_behind_an_opaque_one_makes_little_of_the_pixel():
    camera = _camera()
    model = _discs([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]])  # the first nearer the camera
    centre = _pixel(camera, [0.0, 0.0, 0.0])
    assert opacity_share(model, torch.tensor([True, False]), camera)[centre] > 0.95
    assert opacity_share(model, torch.tensor([False, True]), camera)[centre] < 0.05


def test_one_flag_per_gaussian():
    with pytest.raises(ValueError, match="one bool per Gaussian"):
        opacity_share(_discs([[0.0, 0.0, 0.0]]), torch.tensor([True, False]), _camera())
