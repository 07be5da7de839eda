"""The shipped samples load, are consistent, and are what tools/make_samples.py generates today."""
import importlib.util
from pathlib import Path

import cv2
import numpy as np
import pytest

from fingersplat3d.io import read_capture, read_minutiae
from fingersplat3d.synth import synthesize

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("make_samples", ROOT / "tools" / "make_samples.py")
make_samples = importlib.util.module_from_spec(spec)
spec.loader.exec_module(make_samples)


@pytest.mark.parametrize("name", sorted(make_samples.SAMPLES))
def test_sample_loads_with_ground_truth(name):
    folder = ROOT / "data_samples" / name
    capture = read_capture(folder)
    assert capture.has_cameras and all(v.depth is not None and v.mask is not None for v in capture.views)
    minutiae = read_minutiae(folder / "minutiae.json")
    assert len(minutiae["minutiae_3d"]) > 20
    assert (folder / "mesh.ply").stat().st_size > 0


@pytest.mark.parametrize("name", sorted(make_samples.SAMPLES))
def test_sample_matches_the_generator(name):
    seed, config = make_samples.SAMPLES[name]
    fresh = synthesize(seed, config)
    shipped = read_capture(ROOT / "data_samples" / name)
    for ours, theirs in zip(fresh.capture.views, shipped.views):
        np.testing.assert_array_equal(ours.mask, theirs.mask)
        np.testing.assert_allclose(ours.depth, theirs.depth, atol=1e-4, equal_nan=True)
        assert np.mean(np.abs(ours.image - theirs.image)) < 2e-3  # 8-bit quantisation only
    # The true rolled print, written as it was made (8-bit), and its minutiae as minutiae.json describes them.
    shipped_print = cv2.imread(str(ROOT / "data_samples" / name / "rolled_print.png"), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(shipped_print, fresh.rolled.image)
    described = read_minutiae(ROOT / "data_samples" / name / "minutiae.json")["rolled_print"]
    assert described["size"] == [shipped_print.shape[1], shipped_print.shape[0]] and described["ppi"] == 500.0
