"""pyfing's enhancers as the print's alternative to the built-in Gabor filter (prints/learned.py)."""
import sys

import numpy as np
import pytest

from fingersplat3d.errors import InputError
from fingersplat3d.prints.learned import as_fingerprint, pyfing_enhance


def _stripes(period=9.0, size=160, noise=0.6, seed=0):
    """A ridge texture (ridges positive) whose ridges bend, with noise, inside a disc."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    phase = 2 * np.pi * (x + 8 * np.sin(y / 40.0)) / period
    clean = np.cos(phase)
    mask = (x - size / 2) ** 2 + (y - size / 2) ** 2 < (0.45 * size) ** 2
    return clean, (clean + noise * rng.normal(size=clean.shape)).astype(np.float32), mask


def test_as_fingerprint_has_dark_ridges_and_white_ground():
    clean, texture, mask = _stripes(noise=0.0)
    image = as_fingerprint(texture, mask)
    assert image.dtype == np.uint8 and (image[~mask] == 255).all()
    assert image[mask & (clean > 0.9)].mean() < 128 - 25 and image[mask & (clean < -0.9)].mean() > 128 + 25


@pytest.mark.parametrize("method", ["snfen", "gbfen"])
def test_pyfing_enhancement_keeps_the_contract_and_the_ridges(method):
    """Same contract as gabor_enhance: finite, 0 off the mask, unit RMS on it, ridges positive; and it cleans noise."""
    clean, texture, mask = _stripes()
    enhanced = pyfing_enhance(texture, mask, 9.0, method)
    assert enhanced.shape == texture.shape and np.isfinite(enhanced).all() and (enhanced[~mask] == 0).all()
    assert np.sqrt(np.mean(enhanced[mask] ** 2)) == pytest.approx(1.0, rel=1e-3)
    inner = mask & (np.hypot(*np.mgrid[0:160, 0:160] - 80.0) < 50)  # away from the disc's rim
    before = np.corrcoef(texture[inner], clean[inner])[0, 1]
    after = np.corrcoef(enhanced[inner], clean[inner])[0, 1]
    assert after > before and after > 0.6
    assert (pyfing_enhance(texture, np.zeros_like(mask), 9.0, method) == 0).all()  # no skin: nothing to enhance


def test_a_missing_pyfing_is_one_sentence(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyfing", None)  # import pyfing -> ImportError
    _, texture, mask = _stripes()
    with pytest.raises(InputError, match="pip install 'fingersplat3d\\[learned\\]'"):
        pyfing_enhance(texture, mask, 9.0, "snfen")
    with pytest.raises(InputError, match="unknown learned enhancer"):
        pyfing_enhance(texture, mask, 9.0, "nope")
