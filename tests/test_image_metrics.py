"""Evaluation image metrics: masked PSNR against known noise, masked SSIM, alpha off the mask."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from fingersplat3d.eval.image import (
    ImageScores,
    fraction_alpha_outside,
    image_scores,
    masked_psnr,
    masked_ssim,
    ssim_map,
)


def smooth_image(shape=(96, 128), seed: int = 0) -> np.ndarray:
    """A ridge-like test pattern in [0.2, 0.8] (leaves room for noise without clipping)."""
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    return 0.5 + 0.3 * np.sin(0.35 * cols + 0.1 * rows + phase)


@pytest.mark.parametrize("sigma", [0.01, 0.03, 0.1])
def test_psnr_of_additive_noise(sigma):
    clean = smooth_image()
    noise = np.random.default_rng(1).normal(0.0, sigma, clean.shape)
    expected = 20 * np.log10(1 / sigma)
    assert masked_psnr(clean + noise, clean) == pytest.approx(expected, abs=0.1)


def test_psnr_only_counts_the_mask():
    clean = smooth_image()
    noisy = clean.copy()
    mask = np.zeros(clean.shape, bool)
    mask[:, :64] = True
    noisy[:, :64] += np.random.default_rng(2).normal(0, 0.05, (96, 64))
    noisy[:, 64:] = 0.0  # garbage outside the mask is ignored
    assert masked_psnr(noisy, clean, mask) == pytest.approx(20 * np.log10(1 / 0.05), abs=0.15)
    assert masked_psnr(noisy, clean) < 15
    assert masked_psnr(clean, clean, mask) == float("inf")
    # a known constant error e gives exactly 20 log10(1 / e); channels count like pixels
    rgb = np.repeat(clean[..., None], 3, axis=2)
    assert masked_psnr(rgb + 0.1, rgb, mask) == pytest.approx(20.0, abs=1e-9)


def test_ssim_values():
    clean = smooth_image()
    assert masked_ssim(clean, clean) == pytest.approx(1.0, abs=1e-12)
    values = [masked_ssim(clean + np.random.default_rng(3).normal(0, s, clean.shape), clean) for s in (0.01, 0.05, 0.2)]
    assert 1.0 > values[0] > values[1] > values[2] > 0.0
    # constant images a, b: SSIM = (2ab + C1) / (a^2 + b^2 + C1) everywhere (reflected borders)
    a, b = 0.3, 0.6
    expected = (2 * a * b + 1e-4) / (a * a + b * b + 1e-4)
    value = masked_ssim(np.full((20, 20), a), np.full((20, 20), b))
    assert value == pytest.approx(expected, abs=1e-9)


def test_ssim_matches_training_ssim_away_from_the_border():
    from fingersplat3d.splat.losses import ssim_map as torch_ssim_map

    rng = np.random.default_rng(4)
    x, y = rng.random((40, 36, 3)), rng.random((40, 36, 3))
    ours = ssim_map(x, y)[5:-5, 5:-5]
    theirs = torch_ssim_map(torch.from_numpy(x), torch.from_numpy(y)).numpy()[5:-5, 5:-5]
    assert np.allclose(ours, theirs, atol=1e-9)


def test_masked_ssim_averages_the_full_image_map_inside_the_mask():
    clean = smooth_image()
    noisy = clean + np.random.default_rng(5).normal(0, 0.05, clean.shape)
    mask = np.zeros(clean.shape, bool)
    mask[20:70, 30:90] = True
    full_map = ssim_map(noisy[..., None], clean[..., None])[..., 0]
    assert masked_ssim(noisy, clean, mask) == pytest.approx(full_map[mask].mean(), abs=1e-12)
    scores = image_scores(noisy, clean, mask)
    assert isinstance(scores, ImageScores) and scores.pixels == mask.sum()
    assert scores.ssim == pytest.approx(full_map[mask].mean())
    assert scores.psnr == pytest.approx(masked_psnr(noisy, clean, mask))


def test_fraction_alpha_outside():
    alpha = np.zeros((10, 10))
    mask = np.zeros((10, 10), bool)
    mask[:, :5] = True
    assert fraction_alpha_outside(alpha, mask) == 0.0
    alpha[:, :5] = 1.0
    alpha[:, 5:] = 0.25
    assert fraction_alpha_outside(alpha, mask) == pytest.approx(0.2)


def test_bad_input():
    clean = smooth_image((16, 16))
    with pytest.raises(ValueError):
        masked_psnr(clean, clean[:-1])
    with pytest.raises(ValueError, match="empty"):
        masked_psnr(clean, clean, np.zeros((16, 16), bool))
    with pytest.raises(ValueError):
        masked_ssim(clean, clean, np.ones((4, 4), bool))
    with pytest.raises(ValueError, match="NaN"):
        masked_psnr(np.full((16, 16), np.nan), clean)
    with pytest.raises(ValueError):
        fraction_alpha_outside(np.zeros((3, 3)), np.zeros((3, 4), bool))
