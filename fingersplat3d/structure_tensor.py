"""The ridges' local direction: the structure tensor of a texture, and the masked blur it is averaged with.

One home for the segmentation (which tells ridges from the edges of other things by their repetition across their
own direction), guided matching's information matrices, the warp check's direction across the ridges, the shading
estimate and the prints' Gabor orientations. Pure numpy/OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["masked_blur", "structure_products", "ridge_direction"]


def masked_blur(values: np.ndarray, weight: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur of ``values`` over ``weight`` (a mask as float), normalised by the blurred weight: the mean of
    what lies inside, so the outside does not darken the rim."""
    return cv2.GaussianBlur(values * weight, (0, 0), sigma) / np.maximum(cv2.GaussianBlur(weight, (0, 0), sigma), 1e-3)


def structure_products(texture: np.ndarray, sigma: float, weight: np.ndarray | None = None) -> np.ndarray:
    """``[H, W, 3]`` the structure tensor of ``texture`` (in its own float type): the products ``(uu, uv, vv)`` of its
    central-difference gradients, each averaged by a Gaussian of ``sigma`` pixels, over ``weight`` (a mask as float:
    :func:`masked_blur`) where given."""
    grad_v, grad_u = np.gradient(texture)
    products = (grad_u * grad_u, grad_u * grad_v, grad_v * grad_v)
    if weight is None:
        return np.stack([cv2.GaussianBlur(product, (0, 0), sigma) for product in products], -1)
    return np.stack([masked_blur(product, weight, sigma) for product in products], -1)


def ridge_direction(texture: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """``(across [H, W, 2], coherence [H, W])``: the unit vector across the ridges (the structure tensor's main axis,
    averaged over ``sigma`` pixels) and how one-directional the texture is there (0 to 1), in the texture's float
    type."""
    uu, uv, vv = np.moveaxis(structure_products(texture, sigma), -1, 0)
    angle = 0.5 * np.arctan2(2.0 * uv, uu - vv)
    coherence = np.hypot(uu - vv, 2.0 * uv) / np.maximum(uu + vv, 1e-30)
    return np.stack([np.cos(angle), np.sin(angle)], -1).astype(texture.dtype), coherence.astype(texture.dtype)
