"""Photometric losses: masked L1, SSIM (3DGS formulation) and the 0.8 L1 + 0.2 D-SSIM mix."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from fingersplat3d.splat.losses import (
    SSIM_C1,
    SSIM_C2,
    masked_l1,
    photometric_loss,
    ssim,
    ssim_map,
)


def random_image(seed: int, shape=(24, 20, 3), dtype=torch.float64) -> torch.Tensor:
    return torch.from_numpy(np.random.default_rng(seed).random(shape)).to(dtype)


def interior_mask(height: int, width: int, border: int = 5) -> torch.Tensor:
    mask = torch.zeros(height, width, dtype=torch.bool)
    mask[border:height - border, border:width - border] = True
    return mask


@pytest.mark.parametrize("shape", [(16, 18, 3), (16, 18, 1), (16, 18)])
def test_identical_images_give_zero_loss_and_ssim_one(shape):
    image = random_image(0, shape)
    assert ssim(image, image).item() == pytest.approx(1.0, abs=1e-9)
    assert masked_l1(image, image).item() == 0.0
    assert photometric_loss(image, image).item() == pytest.approx(0.0, abs=1e-9)


def test_known_values_for_constant_images():
    """Away from the zero-padded border, constant images a, b have SSIM (2ab + C1) / (a^2 + b^2 + C1)."""
    a, b = 0.3, 0.7
    render = torch.full((20, 22, 1), a, dtype=torch.float64)
    target = torch.full((20, 22, 1), b, dtype=torch.float64)
    expected_ssim = (2 * a * b + SSIM_C1) / (a * a + b * b + SSIM_C1)
    interior = ssim_map(render, target)[5:-5, 5:-5]
    assert torch.allclose(interior, torch.full_like(interior, expected_ssim), atol=1e-12)
    mask = interior_mask(20, 22)
    assert ssim(render, target, mask).item() == pytest.approx(expected_ssim, abs=1e-12)
    assert masked_l1(render, target, mask).item() == pytest.approx(0.4, abs=1e-12)
    loss = photometric_loss(render, target, mask)
    assert loss.item() == pytest.approx(0.8 * 0.4 + 0.2 * (1 - expected_ssim), abs=1e-12)


def test_known_value_contrast_term():
    """Patterns mirrored about their mean (cov = -var) give SSIM = (-2 var + C2) / (2 var + C2)."""
    height, width = 40, 40
    checker = (torch.arange(height)[:, None] + torch.arange(width)[None, :]) % 2
    x = (0.5 + 0.2 * (2 * checker - 1)).to(torch.float64)[..., None]
    y = 1.0 - x  # mirrored around 0.5: same local mean, covariance = -variance
    value = ssim_map(x, y)[20, 20, 0].item()
    taps = np.exp(-(np.arange(11) - 5.0) ** 2 / (2 * 1.5 ** 2))
    window = torch.from_numpy(np.outer(taps, taps) / taps.sum() ** 2)
    local = x[15:26, 15:26, 0]
    mean = (window * local).sum().item()
    variance = (window * local * local).sum().item() - mean ** 2
    luminance = (2 * mean * mean + SSIM_C1) / (2 * mean * mean + SSIM_C1)
    expected = luminance * (-2 * variance + SSIM_C2) / (2 * variance + SSIM_C2)
    assert value == pytest.approx(expected, abs=1e-12)
    assert value < -0.9


def test_masked_and_unmasked_l1():
    render = torch.zeros(10, 10, 1, dtype=torch.float64)
    target = torch.zeros(10, 10, 1, dtype=torch.float64)
    target[:, 5:] = 1.0  # right half differs by 1
    left = torch.zeros(10, 10, dtype=torch.bool)
    left[:, :5] = True
    assert masked_l1(render, target).item() == pytest.approx(0.5)
    assert masked_l1(render, target, left).item() == 0.0
    assert masked_l1(render, target, ~left).item() == pytest.approx(1.0)
    # SSIM sees 5 px beyond the mask (its window); an error farther out changes nothing
    wide = torch.zeros(10, 16, 1, dtype=torch.float64)
    far = wide.clone()
    far[:, 10:] = 1.0
    left_wide = torch.zeros(10, 16, dtype=torch.bool)
    left_wide[:, :5] = True
    assert photometric_loss(wide, far, left_wide).item() == pytest.approx(0.0, abs=1e-12)
    assert photometric_loss(wide, far).item() > 0.3
    assert photometric_loss(render, target, ~left) > photometric_loss(render, target, left)


def test_mask_restricts_gradient():
    render = random_image(1, (16, 16, 1)).requires_grad_(True)
    target = random_image(2, (16, 16, 1))
    mask = torch.zeros(16, 16, dtype=torch.bool)
    mask[4:8, 4:8] = True
    masked_l1(render, target, mask).backward()
    gradient = render.grad[..., 0]
    assert torch.all(gradient[~mask] == 0) and torch.all(gradient[mask] != 0)


def test_empty_mask_gives_finite_zero():
    render = random_image(3, (12, 12, 3)).requires_grad_(True)
    target = random_image(4, (12, 12, 3))
    empty = torch.zeros(12, 12, dtype=torch.bool)
    loss = photometric_loss(render, target, empty)
    loss.backward()
    assert loss.item() == 0.0
    assert torch.isfinite(render.grad).all() and torch.all(render.grad == 0)


@pytest.mark.parametrize("value", [0.0, 0.5, 1.0])
def test_gradient_finite_for_constant_images(value):
    render = torch.full((14, 14, 1), value, dtype=torch.float32, requires_grad=True)
    target = torch.full((14, 14, 1), value, dtype=torch.float32)
    loss = photometric_loss(render, target, torch.ones(14, 14, dtype=torch.bool))
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(render.grad).all()
    other = torch.full((14, 14, 1), 1.0 - value if value != 0.5 else 0.2)
    render.grad = None
    photometric_loss(render, other).backward()
    assert torch.isfinite(render.grad).all()


def test_ssim_gradcheck_float64():
    render = random_image(5, (12, 12, 1)).requires_grad_(True)
    target = random_image(6, (12, 12, 1))
    mask = interior_mask(12, 12, 2)
    assert torch.autograd.gradcheck(lambda r: photometric_loss(r, target, mask), (render,))


def test_dssim_decreases_with_noise_level_and_bad_input():
    clean = random_image(7, (32, 32, 1))
    noise = torch.from_numpy(np.random.default_rng(8).normal(size=(32, 32, 1)))
    values = [ssim(clean, clean + sigma * noise).item() for sigma in (0.0, 0.05, 0.2)]
    assert values[0] > values[1] > values[2]
    with pytest.raises(ValueError):
        masked_l1(clean, clean[:-1])
    with pytest.raises(ValueError):
        masked_l1(clean, clean, torch.ones(3, 3, dtype=torch.bool))
    with pytest.raises(ValueError):
        photometric_loss(clean, clean, lambda_dssim=1.5)


@pytest.mark.parametrize("masked", [True, False])
def test_prepared_target_gives_the_same_loss_and_gradient_to_the_bit(masked):
    """A target prepared once (what a fit does for each view) changes nothing: loss and gradient are identical."""
    from fingersplat3d.splat.losses import photometric_target

    target = random_image(1, (30, 26, 1), torch.float32)
    mask = interior_mask(30, 26, 7) if masked else None
    grads = []
    for prepared in (False, True):
        render = random_image(2, (30, 26, 1), torch.float32).requires_grad_(True)
        loss = (photometric_loss(render, photometric_target(target, mask)) if prepared
                else photometric_loss(render, target, mask))
        loss.backward()
        grads.append((loss.detach(), render.grad))
    assert torch.equal(grads[0][0], grads[1][0]) and torch.equal(grads[0][1], grads[1][1])
    with pytest.raises(ValueError, match="holds its own mask"):
        photometric_loss(render, photometric_target(target, mask), interior_mask(30, 26))
    with pytest.raises(ValueError, match="differ in shape"):
        photometric_loss(random_image(3, (30, 25, 1)), photometric_target(target, mask))


def test_ssim_reference_keeps_its_padding():
    from fingersplat3d.ssim import ssim_reference

    x, y = random_image(4, (20, 20, 1)), random_image(5, (20, 20, 1))
    for padding in ("zeros", "reflect"):
        assert torch.equal(ssim_map(x, ssim_reference(y, padding=padding)), ssim_map(x, y, padding=padding))
    with pytest.raises(ValueError, match="asked of a reference"):
        ssim_map(x, ssim_reference(y, padding="reflect"), padding="zeros")
