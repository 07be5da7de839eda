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


def _both_paths(render, target, padding):
    """The banded map and the graph's (its reference) of ``render`` against ``target``, ``[1, C, H, W]`` each."""
    from fingersplat3d import ssim

    reference = ssim.ssim_reference(target, padding=padding)
    x = render.permute(2, 0, 1)[None]
    return (ssim._banded(x, reference.image, reference.mean, reference.square, padding),
            ssim._graph(x, reference.image, reference.mean, reference.square, padding))


@pytest.mark.parametrize("padding", ["zeros", "reflect"])
@pytest.mark.parametrize("shape, band", [((37, 23, 3), 4), ((12, 9, 1), 64), ((40, 31, 2), 8), ((6, 30, 1), 2)])
def test_banded_map_and_gradient_are_the_graphs(monkeypatch, padding, shape, band):
    """Band by band with the gradient written out, or as autograd's graph of whole images: the same map and gradient
    (float64), whether the image is one band or many, its rows a multiple of the band or not, thinner than the
    window."""
    from fingersplat3d import ssim

    monkeypatch.setattr(ssim, "BAND_ROWS", band)
    g = torch.Generator().manual_seed(len(shape) + band)
    render = torch.rand(*shape, generator=g, dtype=torch.float64, requires_grad=True)
    target = torch.rand(*shape, generator=g, dtype=torch.float64)
    banded, graph = _both_paths(render, target, padding)
    assert torch.allclose(banded, graph, atol=1e-12, rtol=0)
    weights = torch.rand(graph.shape, generator=g, dtype=torch.float64)
    (from_bands,) = torch.autograd.grad((banded * weights).sum(), render)
    (from_graph,) = torch.autograd.grad((graph * weights).sum(), render)
    assert torch.allclose(from_bands, from_graph, atol=1e-12, rtol=0)
    assert from_graph.abs().max() > 1e-3  # a gradient that says something


@pytest.mark.gradcheck
@pytest.mark.parametrize("padding", ["zeros", "reflect"])
def test_banded_gradcheck(monkeypatch, padding):
    # The hand-written gradient of the banded path against finite differences (float64, bands of 3 rows).
    from fingersplat3d import ssim

    monkeypatch.setattr(ssim, "BAND_ROWS", 3)
    g = torch.Generator().manual_seed(1)
    render = torch.rand(13, 16, 2, generator=g, dtype=torch.float64, requires_grad=True)
    reference = ssim.ssim_reference(torch.rand(13, 16, 2, generator=g, dtype=torch.float64), padding=padding)
    assert torch.autograd.gradcheck(
        lambda r: ssim._banded(r.permute(2, 0, 1)[None], reference.image, reference.mean, reference.square, padding),
        (render,), eps=1e-6, atol=1e-7)


def test_large_windows_take_the_banded_path(monkeypatch):
    """``ssim_map`` routes a window of BANDED_MIN_PIXELS or more through the bands: the same map either way (float32,
    as a fit runs), and the graph's intermediates are not made."""
    from fingersplat3d import ssim

    g = torch.Generator().manual_seed(2)
    render = torch.rand(70, 90, 3, generator=g, requires_grad=True)
    target = torch.rand(70, 90, 3, generator=g)
    small = ssim_map(render, target)
    monkeypatch.setattr(ssim, "BANDED_MIN_PIXELS", 70 * 90)
    monkeypatch.setattr(ssim, "_graph", lambda *args: pytest.fail("the graph path was taken"))
    large = ssim_map(render, target)
    assert torch.allclose(large, small, atol=1e-6)
    (1.0 - large).mean().backward()
    assert torch.isfinite(render.grad).all()


@pytest.mark.parametrize("level", [0.0, 1.0, 0.5])
def test_banded_extremes_stay_finite(monkeypatch, level):
    """Flat images (no variance: SSIM's C2 alone below the fraction), black and white, and a render of the other
    extreme: a finite map in [-1, 1] and a finite gradient on the banded path."""
    from fingersplat3d import ssim

    monkeypatch.setattr(ssim, "BANDED_MIN_PIXELS", 1)
    monkeypatch.setattr(ssim, "BAND_ROWS", 5)
    for other in (level, 1.0 - level):
        render = torch.full((17, 19, 3), level, requires_grad=True)
        value = ssim_map(render, torch.full((17, 19, 3), other))
        value.sum().backward()
        assert torch.isfinite(value).all() and value.abs().max() <= 1.0 + 1e-6
        assert torch.isfinite(render.grad).all()
