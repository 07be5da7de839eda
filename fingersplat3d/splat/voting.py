"""Multi-view mask voting and boundary decomposition of Gaussians (SAGD-style post-processing).

A fitted splat keeps Gaussians that the photometric loss never punished: floaters over the dark
background and large Gaussians that straddle the finger's silhouette. The paper removes them with
SAGD (Hu et al. 2024): label voting against the per-view finger masks plus decomposition of
boundary Gaussians. Here:

1. **Vote.** Each Gaussian centre is projected into every view. It is *seen* by a view when it is
   in front of the camera (depth > ``near``, default 0) and inside the image; the view votes
   foreground when its mask is set at the centre's pixel, or within that view's ``margins_px`` of it (SAGD's rule
   is no margin). Occlusion is ignored on purpose: a point on the finger lies inside every view's silhouette whether
   or not it is hidden (the visual-hull rule). The margin is for the skin next to one view's silhouette: a view 90
   degrees away sees it squarely and this one edge-on, so its Gaussians' centres fall a pixel or few either side of
   this view's outline with any error of the surface or the mask; a vote at the centre alone took half of them out,
   and with two views (both must agree) that left holes along each view's outline in the skin between them, seen
   in every new view (measured, docs/measurements.md: every Gaussian voted out of a real two-view fit lay within
   5 px of a mask; none was a floater over the background). The fuse gives a margin of half of each view's
   ridge period (:attr:`CleanConfig.margin_periods`).
2. **Remove background.** A seen Gaussian is kept when its foreground fraction
   ``foreground / seen`` is at least ``min_foreground_fraction``. A Gaussian no view sees is kept:
   there is no evidence against it (it cannot show up in the input views either).
3. **Decompose the boundary.** For every kept Gaussian, points at ``mean +- k sigma_i a_i`` along
   its three principal axes (``k = sample_sigma``) are projected like the centres. A Gaussian
   whose samples along an axis get both labels in some view straddles a mask edge; it is split
   along the axis that does so in the most views (ties: the longer axis) into two children at
   ``mean +- sqrt(1 - r^2) sigma a`` with that scale times ``r = child_scale`` (``r = 1/2``: the
   pair keeps the parent's mean and variance along the axis); colour, opacity and the other axes
   are copied.
4. **Remove background children** by voting on them, and repeat 3-4 for ``rounds`` rounds.

Everything is vectorised in torch on the Gaussians' device (no per-Gaussian Python loop).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Sequence

import numpy as np
import torch

from ..errors import InputError
from ..scene import Camera
from ..segment.morphology import dilated
from .gaussians import Gaussians
from ..rotations import quaternion_to_matrix

__all__ = ["Votes", "CleanConfig", "CleanStats", "vote_labels", "straddle_axes", "split_gaussians",
           "clean_with_masks"]


class Votes(NamedTuple):
    """Per-Gaussian vote counts over the views."""

    foreground: torch.Tensor  # [N] int64: views whose mask is set at the projected centre
    seen: torch.Tensor  # [N] int64: views where the centre is in front of the camera and in the image

    @property
    def background(self) -> torch.Tensor:
        """``[N]`` views that see the centre outside their mask."""
        return self.seen - self.foreground

    def keep(self, min_foreground_fraction: float) -> torch.Tensor:
        """``[N]`` bool: foreground often enough, or never seen."""
        return (self.seen == 0) | (self.foreground >= min_foreground_fraction * self.seen - 1e-9)


@dataclass(frozen=True)
class CleanConfig:
    """Settings of :func:`clean_with_masks`."""

    min_foreground_fraction: float = 0.6
    """A seen Gaussian is kept when at least this fraction of the views that see it vote
    foreground. 0.6 is a strict majority for 2 to 5 views (2 views: both; 3 views: 2)."""
    sample_sigma: float = 1.5
    """Boundary test: footprint samples at ``mean +- sample_sigma * sigma`` along each axis."""
    margin_periods: float = 0.5
    """A view votes foreground within this many of its ridge periods of its mask (the margin the module docstring's
    step 1 describes), when :func:`clean_with_masks` is given the views' ridge periods; 0: at the mask alone.
    Measured on real two-view models (docs/measurements.md): holes in their new views 0.23 % of the finger at 0,
    0.04 % at 0.25, 0.01 % at 0.5; synthetic three-view models the same at all three."""
    rounds: int = 2
    """Decomposition rounds (each splits the Gaussians still straddling an edge, then re-votes)."""
    child_scale: float = 0.5
    """A child's scale along the split axis, as a fraction of the parent's (in (0, 1))."""
    near: float = 0.0
    """A point votes in a view only when its camera depth exceeds this (scene units). The default
    0 is scale-free (reconstructions may be in arbitrary units): anything in front of the camera
    counts, and points too close to the camera plane land outside the image anyway."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_foreground_fraction <= 1.0:
            raise ValueError(f"min_foreground_fraction must be in [0, 1], got {self.min_foreground_fraction}")
        if not self.sample_sigma > 0.0:
            raise ValueError(f"sample_sigma must be positive, got {self.sample_sigma}")
        if not self.margin_periods >= 0.0:
            raise ValueError(f"margin_periods must be >= 0, got {self.margin_periods}")
        if self.rounds < 0:
            raise ValueError(f"rounds must be >= 0, got {self.rounds}")
        if not 0.0 < self.child_scale < 1.0:
            raise ValueError(f"child_scale must be in (0, 1), got {self.child_scale}")


@dataclass(frozen=True)
class CleanStats:
    """What :func:`clean_with_masks` did."""

    input_count: int
    removed_background: int  # Gaussians removed by the first vote
    split: int  # parents decomposed, over all rounds
    removed_children: int  # children voted background, over all rounds
    unseen: int  # Gaussians kept because no view sees them (first vote)
    output_count: int


def vote_labels(means: torch.Tensor, cameras: Sequence[Camera], masks: Sequence[np.ndarray], *,
                near: float = 0.0) -> Votes:
    """Foreground and seen counts ``[N]`` of ``means [N, 3]`` against per-view ``masks [H, W]``."""
    views = _ViewStack.build(cameras, masks, means.device, means.dtype)
    labels = views.labels(means, near)  # [V, N] 1 fg, 0 bg, -1 unseen
    return Votes((labels == 1).sum(0), (labels >= 0).sum(0))


def straddle_axes(gaussians: Gaussians, cameras: Sequence[Camera], masks: Sequence[np.ndarray], *,
                  sample_sigma: float = 1.5, near: float = 0.0) -> torch.Tensor:
    """``[N]`` int64: the axis (0-2) along which each Gaussian straddles a mask edge, -1 for none."""
    views = _ViewStack.build(cameras, masks, gaussians.means.device, gaussians.means.dtype)
    return _straddle_axes(gaussians, views, sample_sigma, near)


def split_gaussians(gaussians: Gaussians, axes: torch.Tensor, child_scale: float = 0.5) -> Gaussians:
    """Split ``gaussians`` along ``axes [N]`` (0-2; the rows to split): two children per row.

    Children ``2i`` and ``2i + 1`` sit at ``mean -+ sqrt(1 - r^2) sigma a``; their scale along the
    axis is ``r sigma`` (``r = child_scale``); everything else is copied.
    """
    count = len(gaussians)
    if count == 0:
        return gaussians
    rows = torch.arange(count, device=axes.device)
    rotation = quaternion_to_matrix(gaussians.quats)  # [N, 3, 3], columns = principal axes
    direction = rotation[rows, :, axes]  # [N, 3]
    sigma = gaussians.scales[rows, axes]  # [N]
    offset = (math.sqrt(1.0 - child_scale ** 2) * sigma)[:, None] * direction  # [N, 3]
    means = torch.stack([gaussians.means - offset, gaussians.means + offset], 1).reshape(-1, 3)
    log_scales = gaussians.log_scales.clone()
    log_scales[rows, axes] += math.log(child_scale)

    def twice(tensor: torch.Tensor) -> torch.Tensor:
        return tensor.repeat_interleave(2, dim=0)

    return Gaussians(means, twice(gaussians.quats), twice(log_scales), twice(gaussians.opacity_logits),
                     twice(gaussians.sh_dc), gaussians.facing_exponent)


def clean_with_masks(gaussians: Gaussians, cameras: Sequence[Camera], masks: Sequence[np.ndarray],
                     config: CleanConfig = CleanConfig(), periods: Sequence[float] | None = None
                     ) -> tuple[Gaussians, CleanStats]:
    """Vote, remove background, decompose boundary Gaussians for ``config.rounds`` rounds. ``periods``: each view's
    ridge period in pixels, for the votes' margin (``config.margin_periods`` of it; None: no margin).

    The result is detached, on the input's device. See the module docstring for the rules.
    """
    device, dtype = gaussians.means.device, gaussians.means.dtype
    margins = None if periods is None else [config.margin_periods * float(period) for period in periods]
    views = _ViewStack.build(cameras, masks, device, dtype, margins)
    gaussians = gaussians.detach()
    input_count = len(gaussians)
    labels = views.labels(gaussians.means, config.near)
    votes = Votes((labels == 1).sum(0), (labels >= 0).sum(0))
    keep = votes.keep(config.min_foreground_fraction)
    unseen = int((votes.seen == 0).sum())
    gaussians = gaussians.subset(keep)
    removed_background = input_count - len(gaussians)
    split_total = removed_children = 0
    for _ in range(config.rounds):
        axes = _straddle_axes(gaussians, views, config.sample_sigma, config.near)
        straddling = axes >= 0
        count = int(straddling.sum())
        if count == 0:
            break
        children = split_gaussians(gaussians.subset(straddling), axes[straddling], config.child_scale)
        labels = views.labels(children.means, config.near)
        child_keep = Votes((labels == 1).sum(0), (labels >= 0).sum(0)).keep(config.min_foreground_fraction)
        split_total += count
        removed_children += int((~child_keep).sum())
        gaussians = Gaussians.concat([gaussians.subset(~straddling), children.subset(child_keep)])
    stats = CleanStats(input_count, removed_background, split_total, removed_children, unseen, len(gaussians))
    return gaussians, stats


# --- helpers -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class _ViewStack:
    """Cameras and masks as tensors on one device (validated once)."""

    world_to_cam: torch.Tensor  # [V, 4, 4]
    K: torch.Tensor  # [V, 3, 3]
    masks: torch.Tensor  # [V, H, W] bool, padded to the largest size
    sizes: torch.Tensor  # [V, 2] (width, height) int64

    @staticmethod
    def build(cameras: Sequence[Camera], masks: Sequence[np.ndarray], device: torch.device,
              dtype: torch.dtype, margins_px: Sequence[float] | None = None) -> "_ViewStack":
        """``margins_px``: per view, the pixels off its mask that still vote foreground (the mask grown by the
        project's disc of that radius, whole pixels; None or under 1: the mask as it is)."""
        cameras, masks = list(cameras), [np.asarray(mask) for mask in masks]
        if margins_px is not None:
            if len(margins_px) != len(masks):
                raise ValueError(f"got {len(masks)} masks but {len(margins_px)} margins")
            masks = [dilated(mask, int(margin)) if margin >= 1 else mask for mask, margin in zip(masks, margins_px)]
        if not cameras:
            raise ValueError("mask voting needs at least one camera")
        if len(cameras) != len(masks):
            raise ValueError(f"got {len(cameras)} cameras but {len(masks)} masks")
        for index, (camera, mask) in enumerate(zip(cameras, masks)):
            if mask.shape != (camera.height, camera.width):
                raise InputError(f"mask {index} has shape {mask.shape}, but its camera is "
                                 f"{camera.width}x{camera.height} (expects ({camera.height}, {camera.width}))")
            if not mask.any():
                raise InputError(f"mask {index} is empty: every Gaussian it sees would be voted background")
        height = max(camera.height for camera in cameras)
        width = max(camera.width for camera in cameras)
        stacked = np.zeros((len(cameras), height, width), bool)
        for index, mask in enumerate(masks):
            stacked[index, :mask.shape[0], :mask.shape[1]] = mask.astype(bool)
        compute = torch.float64 if dtype == torch.float64 else torch.float32
        return _ViewStack(
            torch.as_tensor(np.stack([camera.world_to_cam for camera in cameras]), dtype=compute, device=device),
            torch.as_tensor(np.stack([camera.K for camera in cameras]), dtype=compute, device=device),
            torch.as_tensor(stacked, device=device),
            torch.as_tensor([[camera.width, camera.height] for camera in cameras], device=device))

    def labels(self, points: torch.Tensor, near: float) -> torch.Tensor:
        """``[V, ...]`` int8 per view for ``points [..., 3]``: 1 inside the mask, 0 outside, -1 unseen."""
        shape = points.shape[:-1]
        views = len(self.K)
        flat = points.reshape(-1, 3).to(self.K.dtype)  # [M, 3]
        # One GEMM for every view: rows of P = K [R | t] give (u z, v z, z).
        projection = self.K @ self.world_to_cam[:, :3, :]  # [V, 3, 4]
        homogeneous = flat @ projection[:, :, :3].reshape(-1, 3).T + projection[:, :, 3].reshape(-1)  # [M, V*3]
        homogeneous = homogeneous.reshape(-1, views, 3)
        depth = homogeneous[..., 2]  # [M, V]
        in_front = depth > near
        safe_depth = torch.where(in_front, depth, torch.ones_like(depth))
        column = torch.floor(homogeneous[..., 0] / safe_depth + 0.5)  # pixel centres are at integers
        row = torch.floor(homogeneous[..., 1] / safe_depth + 0.5)
        inside = in_front & (column >= 0) & (column < self.sizes[:, 0]) & (row >= 0) & (row < self.sizes[:, 1])
        # NaN/Inf fail every comparison above, so they are never inside.
        width = self.masks.shape[2]
        zero = torch.zeros_like(row)
        index = torch.where(inside, row, zero).long() * width + torch.where(inside, column, zero).long()  # [M, V]
        label = torch.gather(self.masks.reshape(views, -1), 1, index.T).to(torch.int8)  # [V, M]
        label = torch.where(inside.T, label, torch.full_like(label, -1))
        return label.reshape(views, *shape)


def _straddle_axes(gaussians: Gaussians, views: _ViewStack, sample_sigma: float, near: float) -> torch.Tensor:
    count = len(gaussians)
    if count == 0:
        return torch.zeros(0, dtype=torch.long, device=gaussians.means.device)
    rotation = quaternion_to_matrix(gaussians.quats)  # [N, 3, 3]
    scales = gaussians.scales  # [N, 3]
    step = (sample_sigma * scales)[:, :, None] * rotation.transpose(1, 2)  # [N, axis, 3]
    samples = torch.stack([gaussians.means[:, None] - step, gaussians.means[:, None] + step], 2)  # [N, 3, 2, 3]
    centre = views.labels(gaussians.means, near)  # [V, N]
    ends = views.labels(samples, near)  # [V, N, 3, 2]
    labels = torch.cat([ends, centre[:, :, None, None].expand(-1, -1, 3, 1)], -1)  # [V, N, 3, 3]
    seen = labels >= 0
    has_fg = ((labels == 1) & seen).any(-1)
    has_bg = ((labels == 0) & seen).any(-1)
    mixed = (has_fg & has_bg).sum(0)  # [N, 3] views in which the axis crosses an edge
    # Most views first, then the longer axis: the scale term is < 1, so it only breaks ties.
    scale_rank = scales / (scales.max(1, keepdim=True).values * (1.0 + 1e-6) + 1e-30)  # [N, 3] in [0, 1)
    score = mixed.to(scales.dtype) + scale_rank
    axis = score.argmax(1)
    crosses = mixed.max(1).values > 0
    return torch.where(crosses, axis, torch.full_like(axis, -1))
