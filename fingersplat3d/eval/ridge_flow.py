"""What is left between two ridge textures that should coincide: a smooth flow, split by what could move it.

The warp check (:func:`fingersplat3d.experiments.register.warp_check`) carries photo A into view B through the
model and correlates the two ridge textures. A correlation under 1 can be two things: the ridges a little out of
place (the model's geometry), or the same skin looking different to the two cameras (light, gloss, focus). A
*smooth* optical flow between the two textures tells them apart: Farneback's, windows of ``window_periods`` ridge
periods, so that it follows the model's error over several ridges and cannot bend single ridges into place. The
correlation after it is an upper bound of what a better geometry could reach at that scale; the same flow between
two different fingers' textures (a control) shows how much the flow lifts a correlation by itself.

Only the flow *across* the ridges is measured (along them a ridge looks the same). Where the ridges cross the
epipolar lines, a change of B's depth moves the carried texture across them; where they run along the epipolar
lines, only the cameras (pose, focal, lens) can. The median shift in each kind of place says which one the
residual is. Pure numpy/OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..structure_tensor import ridge_direction

__all__ = ["smooth_flow", "resample", "across_ridges", "ncc", "flow_residual"]

WINDOW_PERIODS = 6.0
"""Farneback window in ridge periods: several ridges, so the flow is the geometry's error, not a ridge's shape."""
_ACROSS, _ALONG = 0.7, 0.3  # |cos| between the epipolar direction and the across-ridge one: "crossing", "running along"


def _as_bytes(texture: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A unit-RMS ridge texture as 8-bit for Farneback (which reads 8-bit images): 40 grey levels per unit, 0 at 128."""
    return np.clip(np.where(mask, texture, 0.0) * 40.0 + 128.0, 0, 255).astype(np.uint8)


def smooth_flow(texture_a: np.ndarray, texture_b: np.ndarray, mask: np.ndarray, period: float,
                window_periods: float = WINDOW_PERIODS) -> np.ndarray:
    """``[H, W, 2]`` flow such that B at ``x`` shows what A shows at ``x + flow(x)``."""
    window = int(round(window_periods * period)) | 1
    return cv2.calcOpticalFlowFarneback(_as_bytes(texture_b, mask), _as_bytes(texture_a, mask), None, 0.5, 3,
                                        window, 5, 7, 1.5, cv2.OPTFLOW_FARNEBACK_GAUSSIAN)


def resample(texture: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """``texture`` read at ``x + flow(x)``."""
    h, w = flow.shape[:2]
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(np.asarray(texture, np.float32), u + flow[..., 0], v + flow[..., 1], cv2.INTER_LINEAR)


def across_ridges(texture: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """``(direction [H, W, 2], coherence [H, W])``: the unit vector across the ridges (the structure tensor's main
    axis over 1.5 periods) and how one-directional the texture is there (0 to 1)."""
    return ridge_direction(np.asarray(texture, np.float64), 1.5 * period)


def ncc(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """Normalised correlation of two images over ``mask`` (NaN with fewer than three pixels)."""
    return float(np.corrcoef(a[mask], b[mask])[0, 1]) if mask.sum() > 2 else float("nan")


def flow_residual(texture_a: np.ndarray, texture_b: np.ndarray, mask: np.ndarray, period: float,
                  epipole: np.ndarray | None = None) -> dict:
    """The textures' correlation as they are and after :func:`smooth_flow`, and the flow's median shift across the
    ridges (px), over all coherent ridges and, given B's ``epipole`` (homogeneous ``[3]``: camera A's centre seen
    from B), split by what could move it: ``depth`` where the ridges cross the epipolar lines, ``pose`` where they
    run along them. NaN where there is not enough of a kind."""
    mask = np.asarray(mask, bool)
    flow = smooth_flow(texture_a, texture_b, mask, period)
    direction, coherence = across_ridges(texture_b, period)
    shift = np.abs((flow * direction).sum(-1))
    ridges = mask & (coherence > 0.5)
    out = {"ncc": ncc(texture_a, texture_b, mask), "ncc_flowed": ncc(resample(texture_a, flow), texture_b, mask),
           "shift_px": float(np.median(shift[ridges])) if ridges.any() else float("nan"),
           "shift_depth_px": float("nan"), "shift_pose_px": float("nan")}
    if epipole is not None:
        h, w = mask.shape
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        e = np.asarray(epipole, np.float64)
        epipolar = np.stack([e[2] * u - e[0], e[2] * v - e[1]], -1)  # along the epipolar line through each pixel
        epipolar /= np.maximum(np.linalg.norm(epipolar, axis=-1, keepdims=True), 1e-30)
        cosine = np.abs((epipolar * direction).sum(-1))
        for key, kind in (("shift_depth_px", ridges & (cosine > _ACROSS)), ("shift_pose_px", ridges & (cosine < _ALONG))):
            if kind.sum() >= 100:
                out[key] = float(np.median(shift[kind]))
    return out
