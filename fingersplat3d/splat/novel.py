"""Novel views of a fitted model: images, alpha and depth from any camera (the paper's generation step).

Cameras come from :mod:`.camera_path` (the arc between the leftmost and rightmost input cameras,
or given angles about the rig's axis). Pure torch + numpy; no files.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch

from ..scene import Camera
from .camera_path import arc_cameras
from .fit import near_plane, render_camera
from .gaussians import Gaussians

__all__ = ["NovelView", "render_views", "arc_views", "arc_views_at", "opacity_share"]


@dataclass(frozen=True, eq=False)
class NovelView:
    name: str
    camera: Camera
    image: np.ndarray  # [H, W] (grayscale model) or [H, W, 3] float32 in [0, 1], black background
    alpha: np.ndarray  # [H, W] float32 accumulated opacity
    depth: np.ndarray  # [H, W] float32 camera-frame z, NaN where alpha < min_alpha


def render_views(gaussians: Gaussians, cameras: Sequence[tuple[str, Camera]], *, near_fraction: float = 0.01,
                 min_alpha: float = 0.5) -> list[NovelView]:
    """Render each ``(name, camera)``; depth is kept where the model is at least ``min_alpha`` opaque."""
    views = []
    with torch.no_grad():
        for name, camera in cameras:
            out = render_camera(gaussians, camera, near_plane(gaussians.means, camera, near_fraction))
            image = out.color.clamp(0.0, 1.0).cpu().numpy().astype(np.float32)
            alpha = out.alpha.cpu().numpy().astype(np.float32)
            depth = np.where(alpha >= min_alpha, out.depth.cpu().numpy(), np.nan).astype(np.float32)
            views.append(NovelView(name, camera, image[..., 0] if image.shape[-1] == 1 else image, alpha, depth))
    return views


def opacity_share(gaussians: Gaussians, selected: torch.Tensor, camera: Camera, *, near_fraction: float = 0.01) -> np.ndarray:
    """``[H, W]`` float32 in [0, 1]: the share of each pixel's accumulated opacity that the ``selected`` Gaussians
    (``[N]`` bool) make, seen from ``camera`` (0 where nothing is opaque). The model rendered once with each
    Gaussian's colour 1 when selected and 0 when not, unshaded, and divided by its opacity: where a pixel is the
    blend of several Gaussians, each counts by its own weight in the blend."""
    from .gaussians import rgb_to_sh

    selected = torch.as_tensor(selected, dtype=torch.bool, device=gaussians.means.device)
    if tuple(selected.shape) != (len(gaussians),):
        raise ValueError(f"opacity_share: selected must be one bool per Gaussian ({len(gaussians)}), got {tuple(selected.shape)}")
    colour = selected.to(gaussians.sh_dc.dtype)[:, None].expand(-1, gaussians.sh_dc.shape[1])
    marked = gaussians.with_(sh_dc=rgb_to_sh(colour).contiguous(), facing_exponent=0.0)
    with torch.no_grad():
        out = render_camera(marked, camera, near_plane(marked.means, camera, near_fraction))
        marked_alpha, alpha = out.color.mean(-1).cpu().numpy(), out.alpha.cpu().numpy()
    share = np.divide(marked_alpha, alpha, out=np.zeros_like(alpha), where=alpha > 1e-6)
    return np.clip(share, 0.0, 1.0).astype(np.float32)


def arc_views(gaussians: Gaussians, cameras: Sequence[Camera], count: int) -> list[NovelView]:
    """``count`` views ``arc_00``, ``arc_01``, ... on the arc from the leftmost to the rightmost of ``cameras``
    (:func:`~fingersplat3d.splat.camera_path.arc_cameras`; ``ValueError`` when they do not span one)."""
    return render_views(gaussians, [(f"arc_{k:02d}", camera) for k, camera in enumerate(arc_cameras(cameras, count))])


def arc_views_at(gaussians: Gaussians, cameras: Sequence[Camera], count: int, longest_side: float) -> list[NovelView]:
    """:func:`arc_views` with every camera scaled by one factor, the longest side of any of them to ``longest_side``
    pixels: a camera stored portrait among landscape ones (UWA's 1_1_4_1_0.jpg) keeps its twins' scale, so the arc
    can turn it back (the arc needs one image size)."""
    factor = longest_side / max(max(camera.size) for camera in cameras)
    return arc_views(gaussians, [camera.scaled(factor) for camera in cameras], count)
