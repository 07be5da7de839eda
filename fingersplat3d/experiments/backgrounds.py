"""A finger photographed on other backgrounds, made from a view and its mask (``tools/bench_backgrounds.py``, tests).

A phone photo has no dark background: a bright desk, a room behind the hand. These composite a view's finger (its
mask softened by a 1-px Gaussian, as a lens draws an edge) onto a background, so that the true mask is known: the
view's own, or for real photos the dark-background segmentation's. Pure numpy/OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["on_background", "bright_desk", "clutter", "BACKGROUNDS", "background"]

BACKGROUNDS = ("bright desk", "out-of-focus clutter", "in-focus clutter")
"""The backgrounds :func:`background` makes."""


def on_background(image: np.ndarray, mask: np.ndarray, scene: np.ndarray) -> np.ndarray:
    """``image``'s finger (``mask``, softened by 1 px) over ``scene`` (``[H, W, 3]``); ``[H, W, 3]`` float32 in [0, 1]."""
    soft = cv2.GaussianBlur(np.asarray(mask, np.float32), (0, 0), 1.0)[..., None]
    colour = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    return (soft * colour + (1.0 - soft) * scene).clip(0, 1).astype(np.float32)


def bright_desk(shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """A plain bright surface (0.82) with sensor noise (0.03)."""
    return (0.82 + 0.03 * rng.normal(size=tuple(shape[:2]) + (3,))).astype(np.float32)


def clutter(shape: tuple[int, ...], rng: np.random.Generator, blur_px: float = 6.0) -> np.ndarray:
    """Plain-coloured things (25 ellipses) and lines (15) of random colours, blurred by ``blur_px`` (out of focus
    behind a finger close-up at 6, in focus at 1)."""
    height, width = shape[:2]
    image = np.zeros((height, width, 3), np.float32) + rng.uniform(0.2, 0.8, 3).astype(np.float32)
    for _ in range(25):
        centre = tuple(int(x) for x in rng.uniform(0, [width, height]))
        axes = tuple(int(x) for x in rng.uniform(10, [width / 3, height / 3]))
        cv2.ellipse(image, centre, axes, float(rng.uniform(0, 180)), 0, 360, tuple(float(c) for c in rng.uniform(0, 1, 3)), -1)
    for _ in range(15):
        ends = [tuple(int(x) for x in rng.uniform(0, [width, height])) for _ in range(2)]
        cv2.line(image, ends[0], ends[1], tuple(float(c) for c in rng.uniform(0, 1, 3)), int(rng.integers(1, 6)))
    return cv2.GaussianBlur(image, (0, 0), blur_px)


def background(kind: str, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """One of :data:`BACKGROUNDS` at ``shape``."""
    if kind == "bright desk":
        return bright_desk(shape, rng)
    if kind in ("out-of-focus clutter", "in-focus clutter"):
        return clutter(shape, rng, 6.0 if kind.startswith("out") else 1.0)
    raise ValueError(f"unknown background {kind!r}; expected one of {', '.join(BACKGROUNDS)}")
