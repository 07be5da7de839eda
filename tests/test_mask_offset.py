"""The masks grown or shrunk for bench_real's --mask-offset (experiments/mask_offset.py)."""
from pathlib import Path

import numpy as np
import pytest

from fingersplat3d.experiments.mask_offset import with_offset_masks
from fingersplat3d.io.datasets import load_any
from fingersplat3d.scene import View
from fingersplat3d.segment.masks import finger_mask

SAMPLE = Path(__file__).resolve().parents[1] / "data_samples" / "uwa_seed0"


def _ellipse_view() -> View:
    v, u = np.mgrid[0:120, 0:160]
    mask = ((u - 80) / 50.0) ** 2 + ((v - 60) / 30.0) ** 2 <= 1.0
    return View("e", np.where(mask, 0.6, 0.05).astype(np.float32), mask)


@pytest.mark.parametrize("px", [1, 3, 6])
def test_grown_and_shrunk_by_the_offset(px):
    view = _ellipse_view()
    grown, = with_offset_masks([view], px)
    shrunk, = with_offset_masks([view], -px)
    assert grown.mask.dtype == bool and grown.mask.shape == view.mask.shape
    assert np.all(grown.mask >= view.mask) and np.all(shrunk.mask <= view.mask)
    # an ellipse of half-axes 50 and 30 moved out or in by px: the area follows the outline (perimeter ~255 px)
    perimeter = np.pi * (3 * (50 + 30) - np.sqrt((3 * 50 + 30) * (50 + 3 * 30)))
    assert grown.mask.sum() - view.mask.sum() == pytest.approx(perimeter * px, rel=0.15)
    assert view.mask.sum() - shrunk.mask.sum() == pytest.approx(perimeter * px, rel=0.15)
    assert grown.image is view.image and grown.name == view.name


def test_zero_keeps_a_given_mask_and_finds_a_missing_one():
    view = _ellipse_view()
    same, = with_offset_masks([view], 0)
    assert np.array_equal(same.mask, view.mask)
    photo = load_any([SAMPLE])[0].views[0]
    bare = View(photo.name, photo.image)
    found, = with_offset_masks([bare], 0)
    assert np.array_equal(found.mask, finger_mask(photo.image, name=photo.name))


def test_bench_real_refuses_it_beside_runs_that_find_their_own_masks():
    import subprocess
    import sys

    tool = Path(__file__).resolve().parents[1] / "tools" / "bench_real.py"
    for other in (["--orders"], ["--crop-tip"]):
        done = subprocess.run([sys.executable, str(tool), "--mask-offset", "2", *other], capture_output=True, text=True)
        assert done.returncode == 2 and "--mask-offset" in done.stderr and "Traceback" not in done.stderr
