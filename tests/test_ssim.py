"""The one SSIM (fingersplat3d.ssim) against a published implementation and known values."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from fingersplat3d.ssim import SSIM_C1, ssim_map


def ridge_pair(seed: int, shape=(64, 72)) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    clean = 0.5 + 0.3 * np.sin(0.4 * cols + 0.15 * rows)
    return clean, np.clip(clean + rng.normal(0, 0.08, shape), 0, 1)


@pytest.mark.parametrize("seed", [0, 1])
def test_matches_scikit_image_with_wang_settings(seed):
    """scikit-image's structural_similarity with Wang et al.'s settings (Gaussian window sigma 1.5,
    population covariance, data range 1) gives the same map away from the border."""
    metrics = pytest.importorskip("skimage.metrics")
    x, y = ridge_pair(seed)
    _, reference = metrics.structural_similarity(x, y, data_range=1.0, gaussian_weights=True, sigma=1.5,
                                                 use_sample_covariance=False, full=True)
    for padding in ("zeros", "reflect"):
        ours = ssim_map(torch.from_numpy(x), torch.from_numpy(y), padding=padding).numpy()[..., 0]
        assert np.allclose(ours[5:-5, 5:-5], reference[5:-5, 5:-5], atol=1e-6)


def test_reflect_padding_counts_nothing_outside_the_image():
    a, b = 0.3, 0.6
    expected = (2 * a * b + SSIM_C1) / (a * a + b * b + SSIM_C1)
    x, y = torch.full((12, 14, 1), a, dtype=torch.float64), torch.full((12, 14, 1), b, dtype=torch.float64)
    assert torch.allclose(ssim_map(x, y, padding="reflect"), torch.full_like(x, expected), atol=1e-12)
    zeros = ssim_map(x, y, padding="zeros")
    assert not torch.allclose(zeros[0, 0], torch.tensor([expected], dtype=torch.float64))  # the zero border counts


def test_rejects_bad_arguments():
    image = torch.zeros(8, 8)
    with pytest.raises(ValueError):
        ssim_map(image, torch.zeros(8, 9))
    with pytest.raises(ValueError):
        ssim_map(image, image, padding="circular")
    with pytest.raises(ValueError):
        ssim_map(torch.zeros(2, 8, 8, 1), torch.zeros(2, 8, 8, 1))


@pytest.mark.gradcheck
@pytest.mark.parametrize("padding", ["zeros", "reflect"])
def test_ssim_gradcheck(padding):
    # The blur's hand-written adjoint against finite differences (float64, both borders).
    g = torch.Generator().manual_seed(0)
    render = torch.rand(14, 17, 2, generator=g, dtype=torch.float64, requires_grad=True)
    target = torch.rand(14, 17, 2, generator=g, dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda r: ssim_map(r, target, padding=padding), (render,), eps=1e-6, atol=1e-7)
