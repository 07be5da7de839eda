import numpy as np
import pytest

from fingersplat3d.eval.ridge_flow import across_ridges, flow_residual

PERIOD = 10.0


def _ridges(shift: float = 0.0, size: int = 240) -> np.ndarray:
    """Unit-RMS ridges running along y (across them: x), gently curved; ``shift`` px across them."""
    v, u = np.mgrid[0:size, 0:size].astype(np.float64)
    texture = np.sin(2 * np.pi * (u - shift + 6.0 * np.sin(v / 60.0)) / PERIOD)
    return (texture * np.sqrt(2)).astype(np.float32)


def test_a_smooth_shift_across_the_ridges_is_measured_and_undone():
    b, a = _ridges(), _ridges(shift=-2.0)  # B at x shows what A shows at x - 2 (a flow of -2 px)
    mask = np.zeros(b.shape, bool)
    mask[30:-30, 30:-30] = True
    left = flow_residual(a, b, mask, PERIOD)
    assert left["ncc"] < 0.75 and left["ncc_flowed"] > 0.95
    assert left["shift_px"] == pytest.approx(2.0, abs=0.4)
    assert np.isnan(left["shift_depth_px"]) and np.isnan(left["shift_pose_px"])  # no epipole given


def test_the_shift_is_split_by_the_epipolar_direction():
    b, a = _ridges(), _ridges(shift=-2.0)
    mask = np.ones(b.shape, bool)
    mask[:30] = mask[-30:] = False
    crossing = flow_residual(a, b, mask, PERIOD, epipole=np.array([1.0, 0.0, 0.0]))  # epipolar lines along x
    assert crossing["shift_depth_px"] == pytest.approx(2.0, abs=0.4) and np.isnan(crossing["shift_pose_px"])
    running = flow_residual(a, b, mask, PERIOD, epipole=np.array([0.0, 1.0, 0.0]))  # along y: the ridges' own way
    assert running["shift_pose_px"] == pytest.approx(2.0, abs=0.4) and np.isnan(running["shift_depth_px"])


def _skin(seed: int, size: int = 240) -> np.ndarray:
    """Texture at the ridge period in every direction (band-passed noise, unit RMS): no two seeds share a pattern."""
    import cv2

    noise = np.random.default_rng(seed).standard_normal((size, size))
    band = cv2.GaussianBlur(noise, (0, 0), PERIOD / 6) - cv2.GaussianBlur(noise, (0, 0), PERIOD / 3)
    return (band / band.std()).astype(np.float32)


def test_the_flow_does_not_make_another_finger_agree():
    b = _skin(1)
    mask = np.ones(b.shape, bool)
    same = flow_residual(np.roll(b, 2, axis=1), b, mask, PERIOD)
    other = flow_residual(_skin(2), b, mask, PERIOD)
    assert same["ncc_flowed"] > 0.9
    assert abs(other["ncc"]) < 0.1 and other["ncc_flowed"] < 0.3


def test_across_ridges_points_across_them():
    direction, coherence = across_ridges(_ridges(), PERIOD)
    inner = (slice(40, -40), slice(40, -40))
    assert np.median(np.abs(direction[inner][..., 0])) > 0.95 and np.median(coherence[inner]) > 0.8
