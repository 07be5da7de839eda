"""A finger photographed on other backgrounds, made from a view and its mask (``tools/bench_backgrounds.py``, tests).

A phone photo has no dark background: a bright desk, a room behind the hand. These composite a view's finger (its
mask softened by a 1-px Gaussian, as a lens draws an edge) onto a background, so that the true mask is known: the
view's own, or for real photos the dark-background segmentation's. Pure numpy/OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["on_background", "bright_desk", "lamp_lit_desk", "clutter", "BACKGROUNDS", "background"]

BACKGROUNDS = ("bright desk", "out-of-focus clutter", "in-focus clutter", "lamp-lit desk")
"""The backgrounds :func:`background` makes."""


def on_background(image: np.ndarray, mask: np.ndarray, scene: np.ndarray) -> np.ndarray:
    """``image``'s finger (``mask``, softened by 1 px) over ``scene`` (``[H, W, 3]``); ``[H, W, 3]`` float32 in [0, 1]."""
    soft = cv2.GaussianBlur(np.asarray(mask, np.float32), (0, 0), 1.0)[..., None]
    colour = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    return (soft * colour + (1.0 - soft) * scene).clip(0, 1).astype(np.float32)


def bright_desk(shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """A plain bright surface (0.82) with sensor noise (0.03)."""
    return (0.82 + 0.03 * rng.normal(size=tuple(shape[:2]) + (3,))).astype(np.float32)


def lamp_lit_desk(shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
    """A plain desk lit by a lamp beside the frame: a point source a quarter of the frame past one of its sides, at a
    random place along it, 0.4-1.0 of the frame's diagonal above the desk, its light falling as the cosine over the
    squared distance, scaled to run from 0.15-0.3 to 0.8-0.95 over the frame, warm (the blue channel at 0.85), with
    sensor noise (0.02). Its greys span a grey finger's."""
    height, width = shape[:2]
    diagonal = float(np.hypot(width, height))
    side = int(rng.integers(4))
    along = float(rng.uniform(0.0, 1.0))
    lamp_x, lamp_y = [(along * width, -0.25 * height), (along * width, 1.25 * height),
                      (-0.25 * width, along * height), (1.25 * width, along * height)][side]
    lamp_height = float(rng.uniform(0.4, 1.0)) * diagonal
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    light = lamp_height / ((x - lamp_x) ** 2 + (y - lamp_y) ** 2 + lamp_height ** 2) ** 1.5
    light = (light - light.min()) / max(float(light.max() - light.min()), 1e-12)
    low, high = rng.uniform(0.15, 0.3), rng.uniform(0.8, 0.95)
    level = low + (high - low) * light
    tint = np.array([1.0, 0.95, 0.85], np.float32)  # RGB
    return (level[..., None] * tint + 0.02 * rng.normal(size=(height, width, 3))).astype(np.float32)


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
    if kind == "lamp-lit desk":
        return lamp_lit_desk(shape, rng)
    raise ValueError(f"unknown background {kind!r}; expected one of {', '.join(BACKGROUNDS)}")
