"""Photos with the finger's sides out of focus, as a phone's close-up takes them (``tools/bench_defocus.py``).

A phone focused on the pad from 5-10 cm has a depth of field of a few millimetres: the skin falling away toward the
rims, which the other views see squarely and which the registration matches on, is blurred. The thin lens blurs a
point at depth z by a circle of confusion proportional to |z - z_focus| / z; over a finger's few millimetres of relief
at 50 mm that is close to linear in |z - z_focus|. So each view is blurred per pixel with a Gaussian whose sigma
grows linearly from 0 at its nearest skin (where the autofocus locks) to ``rim_sigma_px`` at its farthest, the
background as the farthest. Pure numpy/OpenCV on ``fs3d synth`` views (their true depth gives z).
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["defocused"]

_LEVELS = 9  # blur levels the per-pixel sigma is interpolated between


def defocused(view, rim_sigma_px: float):
    """``view`` (with its true ``depth``) blurred as a lens focused on its nearest skin would: sigma 0 there,
    ``rim_sigma_px`` at its farthest skin and over the background, linear in depth between."""
    if rim_sigma_px <= 0:
        return view
    image = np.asarray(view.image, np.float32)
    depth = np.asarray(view.depth, np.float64)
    skin = np.isfinite(depth)
    if not skin.any():
        raise ValueError(f"view {view.name!r} has no true depth to blur by")
    near, far = float(depth[skin].min()), float(depth[skin].max())
    share = np.ones(depth.shape)
    share[skin] = (depth[skin] - near) / max(far - near, 1e-12)
    sigma = share * rim_sigma_px
    levels = np.linspace(0.0, rim_sigma_px, _LEVELS)
    stack = [image] + [cv2.GaussianBlur(image, (0, 0), float(s)) for s in levels[1:]]
    position = sigma / levels[1]  # in units of the level spacing
    low = np.clip(np.floor(position).astype(int), 0, _LEVELS - 2)
    weight = np.clip(position - low, 0.0, 1.0)
    blurred = np.zeros_like(image)
    for level in range(_LEVELS - 1):
        here = low == level
        if not here.any():
            continue
        w = weight[here] if image.ndim == 2 else weight[here][:, None]
        blurred[here] = (1 - w) * stack[level][here] + w * stack[level + 1][here]
    return view.with_(image=np.clip(blurred, 0.0, 1.0))
