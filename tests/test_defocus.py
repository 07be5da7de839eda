"""The defocus of a phone's close-up (experiments.defocus): sharp where it focuses, blurred toward the rims."""
import numpy as np
import pytest

from fingersplat3d.experiments.defocus import defocused
from fingersplat3d.synth import SynthConfig, synthesize


@pytest.fixture(scope="module")
def close_up():
    return synthesize(0, SynthConfig(rig="uwa", size=(320, 256), distance_mm=50.0)).capture


def _detail(image: np.ndarray, where: np.ndarray) -> float:
    """Mean absolute second difference along rows (ridge detail) over ``where``."""
    second = np.abs(image[:, 2:] - 2 * image[:, 1:-1] + image[:, :-2])
    return float(second[where[:, 1:-1]].mean())


def test_sharp_where_it_focuses_blurred_toward_the_rims(close_up):
    view = close_up["center"]
    assert defocused(view, 0.0) is view
    blurred = defocused(view, 6.0)
    depth = view.depth
    skin = np.isfinite(depth)
    near = skin & (depth <= np.quantile(depth[skin], 0.1))  # the pad's front, where the lens focuses
    far = skin & (depth >= np.quantile(depth[skin], 0.9))  # toward the rims
    kept_near = _detail(blurred.image, near) / _detail(view.image, near)
    kept_far = _detail(blurred.image, far) / _detail(view.image, far)
    assert kept_near > 0.5 and kept_far < 0.25 and kept_far < kept_near / 3
    assert blurred.image.shape == view.image.shape and np.isfinite(blurred.image).all()
    assert blurred.image.min() >= 0 and blurred.image.max() <= 1


def test_a_view_without_depth_is_refused(close_up):
    view = close_up["center"].with_(depth=np.full(close_up["center"].image.shape[:2], np.nan, np.float32))
    with pytest.raises(ValueError, match="no true depth"):
        defocused(view, 2.0)
