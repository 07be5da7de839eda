"""Fit Gaussians to the input photos: the paper's section C (3DGS with SH degree 0).

``fit_gaussians(initial, views, cameras, config)`` optimises the Gaussians (and, optionally, the
camera poses, InstantSplat-style) with Adam, per-group learning rates, one view per step, the loss
``(1 - l) L1 + l (1 - SSIM)`` inside the finger mask, and adaptive density control under a budget
that follows the finger's area and ridge frequency (:func:`gaussian_budget`). No background
Gaussians; the one view-dependent term is the model's shading exponent (:mod:`.shading`), which the
fit keeps as it is given. ``fit_camera`` aligns one camera to a photo with the model frozen (used to
evaluate held-out views, as pose-free 3DGS methods do).

Runs on the device of ``device`` (default: CUDA when present, else CPU). No Open3D, no files.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch

from ..device import resolve_device
from ..scene import Camera, View
from .adam import Adam
from .config import SplatConfig
from .gaussians import Gaussians, sh_to_rgb
from .losses import PhotometricTarget, photometric_loss, photometric_target
from .pose import apply_pose_correction
from .rasterize import RenderOutput, rasterize
from .shading import facing_cosines, shade
from .strategy import (GAUSSIAN_GROUPS, DensifyStats, GradientStats, densify_and_prune, gaussians_of, hold_rows,
                       param_group)

__all__ = ["SplatFit", "FitTarget", "fit_gaussians", "fit_camera", "render_camera", "gaussian_budget", "halved",
           "ridge_periods", "MIN_COARSE_PERIOD_PX",
           "scene_extent", "near_plane", "rotation_step_scale", "LONG_FOCAL"]

LONG_FOCAL = 4.0
"""Focal length, in long image sides, up to which the pose corrections' rotation learning rates apply as they are
(every camera measured: 1.25x on the real rig, 3.3x on ``fs3d synth``'s). Beyond it (a telephoto, or another group's
near-orthographic renders: 139x) the rate falls as ``(LONG_FOCAL * side / focal) ** 2``: a turn of ``d`` radians
moves the image by ``d * focal`` pixels, and the perspective that tells a turn from a sideways shift (the other
correction) fades as ``side / focal``, so there the two drift together. Unscaled, ``fast`` fits of the IMPOSE renders
turned cameras by 0.16-0.25 degrees (300-500 px) and fitted the views to 12-31 dB; scaled by the first power only,
27-34 dB; by the square, 38-43 dB, as with the poses fixed (40-41 dB)."""


def rotation_step_scale(camera: Camera) -> float:
    """The factor on the pose correction's rotation rate for ``camera``: 1 up to a focal of :data:`LONG_FOCAL` long
    image sides, then falling with the square of the focal."""
    focal = float(max(camera.K[0, 0], camera.K[1, 1]))
    reach = LONG_FOCAL * max(camera.width, camera.height)
    return min(1.0, reach / focal) ** 2 if math.isfinite(focal) and focal > 0 else 1.0


@dataclass(frozen=True, eq=False)
class FitTarget:
    """One training view on the fitting device."""

    image: torch.Tensor  # [H, W, C] float in [0, 1]
    mask: torch.Tensor  # [H, W] bool, the finger
    K: torch.Tensor  # [3, 3]
    world_to_cam: torch.Tensor  # [4, 4]
    width: int
    height: int
    depth: torch.Tensor | None = None  # [H, W] prior depth, 0 where it has none
    depth_valid: torch.Tensor | None = None  # [H, W] bool: mask & finite prior depth
    outside_weight: torch.Tensor | None = None  # [H, W] float: 1 / (pixels off the finger) off it, 0 on it
    depth_weight: torch.Tensor | None = None  # [H, W] float: 1 / (valid pixels * the prior's median) where depth_valid
    inside_weight: torch.Tensor | None = None  # [H, W] float: 1 / (pixels on the finger) on it, 0 off it
    photometric: PhotometricTarget | None = None
    """The image and mask as :func:`~fingersplat3d.splat.losses.photometric_loss` reads them, prepared once."""

    @classmethod
    def from_view(cls, view: View, camera: Camera, device: torch.device, depth: np.ndarray | None = None) -> "FitTarget":
        image = view.image if view.image.ndim == 3 else view.image[..., None]
        mask = view.mask if view.mask is not None else np.ones(view.image.shape[:2], bool)
        as_tensor = lambda a, dtype=torch.float32: torch.as_tensor(np.ascontiguousarray(a), dtype=dtype, device=device)  # noqa: E731
        # Means over a mask as weighted sums: indexing by a boolean mask costs ~8 ms a step at 640x512 (its
        # nonzero and scatter), a product 0.5 ms.
        prior = valid = depth_weight = None
        if depth is not None and (valid_np := mask & np.isfinite(depth) & (depth > 0)).any():
            scale = float(np.median(depth[valid_np]))  # the depth error is relative to it
            prior, valid = as_tensor(np.where(valid_np, depth, 0.0)), as_tensor(valid_np, torch.bool)
            depth_weight = as_tensor(valid_np / (valid_np.sum() * scale))
        outside = ~np.asarray(mask, bool)
        inside = ~outside
        image, mask = as_tensor(image), as_tensor(mask, torch.bool)
        return cls(image, mask, as_tensor(camera.K), as_tensor(camera.world_to_cam), view.width, view.height, prior,
                   valid, as_tensor(outside / max(int(outside.sum()), 1)), depth_weight,
                   as_tensor(inside / max(int(inside.sum()), 1)), photometric_target(image, mask))


@dataclass(frozen=True, eq=False)
class SplatFit:
    """The fitted model, the (refined) cameras and what happened."""

    gaussians: Gaussians  # detached, on the fitting device
    cameras: list[Camera]  # input cameras with refined poses (unchanged when refine_poses is off)
    losses: list[float]  # loss per step
    densify: list[DensifyStats]
    initial_count: int
    budget: int
    seconds: float
    coarse_steps: int = 0
    """Steps at half resolution (``SplatConfig.coarse_fraction``; 0 where the ridges are too fine for it)."""


MIN_COARSE_PERIOD_PX = 8.0
"""The finest ridge period (photo pixels) at which the fit starts at half resolution (``SplatConfig.coarse_fraction``):
halved, such ridges keep 4 px a period, twice the 2 px the half-size grid can hold at all; finer ones would alias in
the half-size renders and be averaged away in the halved photos, so the fit then runs every step at full size."""


def ridge_periods(views: Sequence[View]) -> list[float]:
    """Each view's ridge period in pixels, measured inside its mask (the texture module's default where none shows)."""
    from ..align.correspond.texture import estimate_ridge_period

    return [estimate_ridge_period(view.image, view.mask if view.mask is not None else np.ones(view.image.shape[:2], bool))
            for view in views]


def gaussian_budget(views: Sequence[View], config: SplatConfig, periods: Sequence[float] | None = None) -> int:
    """Gaussians the finger needs: ``gaussians_per_cell`` per (ridge period / 4)^2 of finger area.

    Resolving a ridge (a bright and a dark band per period) takes about two Gaussians across each
    band, i.e. a spacing of a quarter period; the areas of the views' masks are summed and divided
    by ``view_overlap`` (how many views see an average skin point). ``periods``: each view's ridge
    period in pixels when already measured (else measured here).
    """
    periods = ridge_periods(views) if periods is None else periods
    cells = 0.0
    for view, period in zip(views, periods):
        mask = view.mask if view.mask is not None else np.ones(view.image.shape[:2], bool)
        cells += float(mask.sum()) / (float(period) / 4.0) ** 2
    budget = config.gaussians_per_cell * cells / max(config.view_overlap, 1.0)
    return int(np.clip(budget, config.min_gaussians, config.max_gaussians))


def scene_extent(means: torch.Tensor) -> float:
    """Size of the model: the diagonal of the 1-99 percentile box of the centres."""
    if len(means) == 0:
        return 1.0
    sample = means.detach()[:: max(1, len(means) // 50_000)].float()
    low, high = torch.quantile(sample, 0.01, dim=0), torch.quantile(sample, 0.99, dim=0)
    extent = float(torch.linalg.vector_norm(high - low))
    return extent if math.isfinite(extent) and extent > 0 else 1.0


def near_plane(means: torch.Tensor, camera: Camera, fraction: float) -> float:
    """``fraction`` of the distance from the camera to the model's median centre."""
    if len(means) == 0:
        return fraction
    centre = means.detach().median(dim=0).values.cpu().double().numpy()
    distance = float(np.linalg.norm(camera.world_to_camera(centre[None])[0]))
    return fraction * distance if math.isfinite(distance) and distance > 0 else fraction


def render_camera(gaussians: Gaussians, camera: Camera, near: float, world_to_cam: torch.Tensor | None = None,
                  background: torch.Tensor | None = None) -> RenderOutput:
    """Render the model from a :class:`Camera` (optionally with an explicit, differentiable pose)."""
    device, dtype = gaussians.means.device, gaussians.means.dtype
    K = torch.as_tensor(camera.K, dtype=dtype, device=device)
    if world_to_cam is None:
        world_to_cam = torch.as_tensor(camera.world_to_cam, dtype=dtype, device=device)
    return _render(gaussians, world_to_cam, K, camera.width, camera.height, near, background)


def _render(model: Gaussians, world_to_cam: torch.Tensor, K: torch.Tensor, width: int, height: int, near: float,
            background: torch.Tensor | None = None, backend: str = "auto") -> RenderOutput:
    """Rasterize raw parameters: activated scales and opacities, SH DC colour clamped at 0 (as 3DGS), darkened by
    the cosine at which this camera sees each Gaussian to the power of the model's ``facing_exponent``
    (:mod:`.shading`; at 0 the colours are the SH DC ones exactly)."""
    colors = sh_to_rgb(model.sh_dc).clamp_min(0.0)
    if model.facing_exponent != 0:
        cosines = facing_cosines(model.means, model.quats, model.log_scales, world_to_cam)
        colors = shade(colors, cosines, model.facing_exponent)
    return rasterize(model.means, model.quats, model.scales, model.opacities, colors,
                     world_to_cam, K, width, height, near=near, background=background, backend=backend)


def _blur(image: torch.Tensor, sigma: float) -> torch.Tensor:
    """``[H, W, C]`` blurred by a Gaussian of ``sigma`` pixels (separable, reflected borders)."""
    if sigma <= 0:
        return image
    radius = max(1, int(math.ceil(3.0 * sigma)))
    taps = torch.exp(-0.5 * (torch.arange(-radius, radius + 1, device=image.device, dtype=image.dtype) / sigma) ** 2)
    taps = taps / taps.sum()
    planes = image.permute(2, 0, 1)[:, None]  # [C, 1, H, W]
    planes = torch.nn.functional.pad(planes, (radius, radius, 0, 0), mode="reflect")
    planes = torch.nn.functional.conv2d(planes, taps.view(1, 1, 1, -1))
    planes = torch.nn.functional.pad(planes, (0, 0, radius, radius), mode="reflect")
    planes = torch.nn.functional.conv2d(planes, taps.view(1, 1, -1, 1))
    return planes[:, 0].permute(1, 2, 0)


def halved(view: View, camera: Camera, depth: np.ndarray | None = None) -> tuple[View, Camera, np.ndarray | None]:
    """``view``, ``camera`` and the prior ``depth`` at half the resolution (each side halved, rounded down, at least
    one pixel): the image area averaged, the mask by its coverage, the depth over its finite pixels only."""
    from ..sampling import map_on_grid, resized_image, resized_mask

    size = (max(1, view.width // 2), max(1, view.height // 2))
    mask = resized_mask(view.mask, size) if view.mask is not None else None
    small = View(view.name, resized_image(view.image, size), mask)
    return small, camera.resized(size), None if depth is None else map_on_grid(depth, size, mask)


def _optimizer(model: Gaussians, config: SplatConfig, extent: float, n_views: int, device) -> tuple:
    parameters = [torch.nn.Parameter(t.detach().clone().contiguous()) for t in model.tensors()]
    rates = [config.lr_means * extent, config.lr_quats, config.lr_scales, config.lr_opacity, config.lr_colors]
    rotation = torch.nn.Parameter(torch.zeros(n_views, 3, device=device))
    translation = torch.nn.Parameter(torch.zeros(n_views, 3, device=device))
    groups = [{"params": [p], "lr": lr, "name": name}
              for p, lr, name in zip(parameters, rates, GAUSSIAN_GROUPS)]
    groups += [{"params": [rotation], "lr": config.lr_pose_rotation if config.refine_poses else 0.0, "name": "pose_rotation"},
               {"params": [translation], "lr": config.lr_pose_translation * extent if config.refine_poses else 0.0,
                "name": "pose_translation"}]
    return Adam(groups, eps=1e-15), rotation, translation


def fit_gaussians(initial: Gaussians, views: Sequence[View], cameras: Sequence[Camera],
                  config: SplatConfig = SplatConfig(), *, budget: int | None = None, device: torch.device | None = None,
                  depths: Sequence[np.ndarray] | None = None, progress: bool = False,
                  periods: Sequence[float] | None = None, frozen: torch.Tensor | None = None) -> SplatFit:
    """Optimise ``initial`` (and the poses) so the renders match the photos inside the finger.

    ``depths``: optional ``[H, W]`` prior depth per view (the geometry stage's, NaN = none); with
    ``lambda_depth > 0`` the rendered depth is kept near it (relative L1 inside the mask). The renders are shaded
    with ``initial.facing_exponent``, which the fitted model keeps. ``periods``: each view's ridge period in pixels
    when already measured (else measured here when ``config.coarse_fraction`` asks for a half-resolution start, which
    runs only with every period at least :data:`MIN_COARSE_PERIOD_PX`). ``frozen``: ``[N]`` bool, the rows of
    ``initial`` kept as they are (their gradients zeroed, so Adam never moves them); only in a fit that adds and
    removes no Gaussians (``densify_from`` past the last step).
    """
    from tqdm import tqdm

    if len(views) != len(cameras) or not views:
        raise ValueError("fit_gaussians needs one camera per view and at least one view")
    if frozen is not None and (tuple(frozen.shape) != (len(initial),) or config.densify_from <= config.iterations):
        raise ValueError("fit_gaussians: frozen must be one bool per Gaussian, in a fit without densification")
    device = resolve_device(device)
    started = time.perf_counter()
    model = initial.detach().to(device, torch.float32)
    priors = depths if depths is not None and config.lambda_depth > 0 else [None] * len(views)
    targets = [FitTarget.from_view(view, camera, device, prior) for view, camera, prior in zip(views, cameras, priors)]
    coarse_steps = int(config.iterations * config.coarse_fraction)
    if periods is None and (coarse_steps > 0 or budget is None):
        periods = ridge_periods(views)
    if coarse_steps > 0 and min(periods) < MIN_COARSE_PERIOD_PX:
        coarse_steps = 0
    coarse = targets
    if coarse_steps > 0:
        coarse = [FitTarget.from_view(small, small_camera, device, small_depth)
                  for small, small_camera, small_depth in (halved(*args) for args in zip(views, cameras, priors))]
    if model.channels != targets[0].image.shape[-1]:
        raise ValueError(f"the model has {model.channels} colour channel(s) but the images have {targets[0].image.shape[-1]}")
    budget = gaussian_budget(views, config, periods) if budget is None else int(budget)
    extent = scene_extent(model.means)
    nears = [near_plane(model.means, camera, config.near_fraction) for camera in cameras]
    optimizer, rotation, translation = _optimizer(model, config, extent, len(views), device)
    turn_scales = [rotation_step_scale(camera) for camera in cameras]  # the rotation parameter, in image steps
    generator = torch.Generator(device=device).manual_seed(config.seed)
    order_rng = np.random.default_rng(config.seed)
    stats = GradientStats.zeros(len(model), device)
    losses: list[float] = []
    densify_records: list[DensifyStats] = []
    decays = config.lr_means > 0 and config.lr_means_final > 0
    means_decay = (config.lr_means_final / config.lr_means) ** (1.0 / max(config.iterations, 1)) if decays else 1.0
    order: list[int] = []
    bar = tqdm(range(config.iterations), desc="fs3d splat", unit="step", disable=not progress)
    for step in bar:
        if not order:
            order = list(order_rng.permutation(len(views)))
        v = order.pop()
        target = (coarse if step < coarse_steps else targets)[v]
        current = gaussians_of(optimizer).with_(facing_exponent=model.facing_exponent)
        pose = target.world_to_cam
        if config.refine_poses and v != 0:
            pose = apply_pose_correction(pose, rotation[v] * turn_scales[v], translation[v])
        out = _render(current, pose, target.K, target.width, target.height, nears[v], backend=config.rasterizer)
        out.means2d.retain_grad()
        loss = photometric_loss(out.color, target.photometric, None, config.lambda_dssim)
        if config.lambda_silhouette > 0:  # no opacity off the finger: the model holds no background
            loss = loss + config.lambda_silhouette * (out.alpha * target.outside_weight).sum()
        if config.lambda_solid > 0:  # a solid finger: nothing behind its skin shows through it
            loss = loss + config.lambda_solid * ((1.0 - out.alpha) * target.inside_weight).sum()
        if target.depth is not None:  # stay near the aligned geometry: photos alone under-constrain depth
            error = torch.where(target.depth_valid, (out.depth - target.depth).abs(), 0.0)  # relative L1, mean over valid
            loss = loss + config.lambda_depth * (error * target.depth_weight).sum()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if frozen is not None:
            hold_rows(optimizer, frozen.to(device))
        optimizer.step()
        losses.append(float(loss.detach()))
        if out.means2d.grad is not None:
            stats.add(out.means2d.grad, out.radii, target.width, target.height)
        param_group(optimizer, "means")["lr"] *= means_decay
        if (step + 1) % config.densify_every == 0 and config.densify_from <= step + 1 <= max(config.densify_until, config.densify_from):
            densify_records.append(densify_and_prune(optimizer, stats, config, extent, budget, generator))
        if step % 10 == 0:
            bar.set_postfix(loss=f"{losses[-1]:.4f}", gaussians=len(current))
    bar.close()
    fitted = gaussians_of(optimizer).detach().with_(facing_exponent=model.facing_exponent)
    refined = list(cameras)
    if config.refine_poses:
        with torch.no_grad():
            for v in range(1, len(cameras)):
                pose = apply_pose_correction(targets[v].world_to_cam.double(), rotation[v].double() * turn_scales[v],
                                             translation[v].double())
                refined[v] = Camera(cameras[v].K, pose.cpu().numpy(), cameras[v].width, cameras[v].height)
    return SplatFit(fitted, refined, losses, densify_records, len(initial), budget, time.perf_counter() - started,
                    coarse_steps)


def fit_camera(gaussians: Gaussians, camera: Camera, image: np.ndarray, mask: np.ndarray, *, iterations: int = 80,
               lr_rotation: float = 2e-3, lr_translation: float = 2e-3, lambda_dssim: float = 0.2,
               near_fraction: float = 0.01, blur_px: float | None = None) -> Camera:
    """Refine one camera's pose so the frozen model's render matches ``image`` inside ``mask``.

    Meant for small corrections (a held-out camera placed from the rig, off by a degree or two).
    Ridges repeat every few pixels, so the loss of the sharp images has a minimum every ridge
    period: the first half of the iterations compares both images blurred by ``blur_px`` (default:
    ``width / 160``, about a ridge period), the second half the sharp ones. The pose with the lowest
    sharp loss seen, the starting one included, is returned: the result never matches worse than
    the camera it was given. Translations are relative to the scene extent; turns, to the focal
    (:func:`rotation_step_scale`).
    """
    device = gaussians.means.device
    turn_scale = rotation_step_scale(camera)
    model = gaussians.detach()
    target = FitTarget.from_view(View("target", image, mask), camera, device)
    extent = scene_extent(model.means)
    near = near_plane(model.means, camera, near_fraction)
    sigma = camera.width / 160.0 if blur_px is None else blur_px
    blurred_target = photometric_target(_blur(target.image, sigma), target.mask)
    rotation = torch.zeros(3, device=device, requires_grad=True)
    translation = torch.zeros(3, device=device, requires_grad=True)
    optimizer = Adam([{"params": [rotation], "lr": lr_rotation, "name": "pose_rotation"},
                                  {"params": [translation], "lr": lr_translation * extent, "name": "pose_translation"}])
    best_loss, best = float("inf"), (torch.zeros(3, device=device), torch.zeros(3, device=device))
    for step in range(iterations + 1):
        pose = apply_pose_correction(target.world_to_cam, rotation * turn_scale, translation)
        out = render_camera(model, camera, near, world_to_cam=pose)
        coarse = step < iterations // 2 and sigma > 0
        sharp = photometric_loss(out.color, target.photometric, None, lambda_dssim) if not coarse or step == 0 else None
        if sharp is not None and float(sharp.detach()) < best_loss:  # the start, then every sharp step: keep the best
            best_loss, best = float(sharp.detach()), (rotation.detach().clone(), translation.detach().clone())
        if step == iterations:
            break
        loss = photometric_loss(_blur(out.color, sigma), blurred_target, None, lambda_dssim) if coarse else sharp
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    with torch.no_grad():
        pose = apply_pose_correction(target.world_to_cam.double(), best[0].double() * turn_scale, best[1].double())
    return Camera(camera.K, pose.cpu().numpy(), camera.width, camera.height)
