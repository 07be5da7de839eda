"""The splatting stage of ``fs3d fuse``: fused cloud -> initial Gaussians -> fit -> mask cleaning.

Glue between the Open3D cloud, the torch fit (:mod:`.fit`) and the multi-view segmentation
post-processing (:mod:`fingersplat3d.splat.voting`); returns a typed result with what the
report needs. Imports Open3D (through :mod:`.init`).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace
from typing import Sequence

import numpy as np
import torch

from ..device import resolve_device
from ..eval.poses import rotation_angle_deg
from ..scene import Camera, View
from .config import SplatConfig, differences_from_preset
from .fit import fit_gaussians, gaussian_budget, near_plane, render_camera, ridge_periods
from .gaussians import Gaussians

__all__ = ["SplatStage", "run_splat_stage", "UNSEEN_OPACITY", "UNSEEN_NEIGHBOURS"]

UNSEEN_OPACITY = 0.95  # the unseen skin's Gaussians (run_splat_stage's ``unseen``): as opaque as fitted skin
UNSEEN_NEIGHBOURS = 16  # fitted Gaussians whose median colour an unseen skin's Gaussian takes
UNSEEN_START_CELLS = 3  # a run of the unseen skin's cells is kept when it starts this close to its seen arc (cells)
UNSEEN_MASK_SLACK = 0.01  # how far outside a view's outline the unseen skin may lie (of its mask area's square root)


@dataclass(frozen=True, eq=False)
class SplatStage:
    gaussians: Gaussians  # cleaned, on the CPU
    cameras: list[Camera]  # refined poses for the fitted views, the others unchanged
    depths: list[np.ndarray]  # [H, W] float32 expected depth of the fitted model per view, NaN off the finger
    report: dict

    @property
    def unseen(self) -> torch.Tensor:
        """``[N]`` bool: the Gaussians that complete the skin no fitted view sees (:func:`_unseen_gaussians`, a guess:
        no photo shows it), the model's last ``report["unseen_skin_gaussians"]`` rows; the others were fitted."""
        count = len(self.gaussians)
        return torch.arange(count) >= count - int(self.report.get("unseen_skin_gaussians", 0))


def _initial_gaussians(cloud, channels: int, budget: int, config: SplatConfig, seed: int) -> Gaussians:
    from .init import gaussians_from_cloud

    if len(cloud.points) > budget:
        rng = np.random.default_rng(seed)
        keep = np.sort(rng.choice(len(cloud.points), budget, replace=False))
        cloud = cloud.select_by_index(keep.tolist())
    return gaussians_from_cloud(cloud, channels, opacity=config.init_opacity, scale_factor=config.init_scale_factor,
                                flatten=config.flatten)


def run_splat_stage(views: Sequence[View], cameras: Sequence[Camera], fitted_views: Sequence[int], cloud,
                    config: SplatConfig, clean_config=None, *, depths: Sequence[np.ndarray] | None = None,
                    device: torch.device | None = None, progress: bool = False,
                    periods: Sequence[float] | None = None, unseen=None) -> SplatStage:
    """Fit Gaussians to ``views[fitted_views]`` starting from ``cloud``, then clean them with the masks (``periods``:
    every view's ridge period in pixels, when already measured; ``unseen``: the skin next to ``cloud`` that no fitted
    view sees, an :class:`~fingersplat3d.unseen_skin.UnseenSkin` (points, normals, chain, steps), completed after the
    fit with Gaussians of the nearest fitted skin's tone, :func:`_unseen_gaussians`, the model's last rows:
    :attr:`SplatStage.unseen`)."""
    from ..eval.image import fraction_alpha_outside, masked_psnr
    from .voting import CleanConfig, clean_with_masks

    device = resolve_device(device)
    clean_config = CleanConfig() if clean_config is None else clean_config
    train_views = [views[v] for v in fitted_views]
    train_cameras = [cameras[v] for v in fitted_views]
    train_periods = ridge_periods(train_views) if periods is None else [periods[v] for v in fitted_views]
    budget = gaussian_budget(train_views, config, train_periods)
    initial = _initial_gaussians(cloud, train_views[0].channels, budget, config, config.seed)
    train_depths = [depths[v] for v in fitted_views] if depths is not None else None
    shading = _shading(train_views, train_cameras, train_depths, config)
    gains = shading.gains() if config.match_exposures else np.ones(len(train_views))
    train_views = [view if gain == 1.0 else view.with_(image=(view.image / gain).astype(np.float32))
                   for view, gain in zip(train_views, gains)]  # each photo at the views' mean exposure
    gain_of = dict(zip(fitted_views, gains))
    fit = fit_gaussians(initial.with_(facing_exponent=shading.exponent), train_views, train_cameras, config,
                        budget=budget, device=device, depths=train_depths, progress=progress, periods=train_periods)
    masks = [view.mask for view in train_views]
    model = fit.gaussians
    outside_before = _alpha_outside(model, fit.cameras, masks, config)
    started = time.perf_counter()
    cleaned, clean_stats = clean_with_masks(model, fit.cameras, masks, clean_config, periods=train_periods)
    clean_seconds = time.perf_counter() - started
    completed = 0
    if unseen is not None and len(cleaned):
        extra = _unseen_gaussians(unseen, cleaned, fit.cameras, masks, config)
        completed = len(extra)
        if completed:
            cleaned = Gaussians.concat([cleaned, extra.to(cleaned.means.device)])
    polish_seconds = 0.0
    if config.polish_iterations > 0 and len(cleaned):
        steps = config.polish_iterations
        polish = replace(config, iterations=steps, polish_fraction=0.0, coarse_fraction=0.0, refine_poses=False,
                         densify_from=steps + 1,
                         lr_means=0.1 * config.lr_means, lr_means_final=0.1 * config.lr_means_final, seed=config.seed + 1)
        # the unseen skin held still: the fitted skin in front of it becomes opaque over it, as a solid finger is
        frozen = torch.arange(len(cleaned)) >= len(cleaned) - completed
        polished = fit_gaussians(cleaned, train_views, fit.cameras, polish, budget=len(cleaned), device=device,
                                 depths=train_depths, frozen=frozen if completed else None)
        cleaned, polish_seconds = polished.gaussians, polished.seconds
    refined = list(cameras)
    for k, v in enumerate(fitted_views):
        refined[v] = fit.cameras[k]
    depths, psnrs, outside_after = [], {}, []
    with torch.no_grad():
        for v, (view, camera) in enumerate(zip(views, refined)):
            out = render_camera(cleaned, camera, near_plane(cleaned.means, camera, config.near_fraction))
            alpha, color = out.alpha.cpu().numpy(), out.color.cpu().numpy()
            depths.append(np.where((alpha > 0.5) & view.mask, out.depth.cpu().numpy(), np.nan).astype(np.float32))
            gain = gain_of.get(v, 1.0)  # a fitted photo's own exposure; 1 for the others
            psnrs[view.name] = round(masked_psnr(np.clip(gain * (color[..., 0] if color.shape[-1] == 1 else color), 0, 1),
                                                 view.image, view.mask), 2)
            if v in fitted_views:
                outside_after.append(fraction_alpha_outside(alpha, view.mask))
    corrections = {views[v].name: round(float(rotation_angle_deg(refined[v].rotation, cameras[v].rotation)), 3) for v in fitted_views}
    report = {"preset": config.preset or None, "differs_from_preset": differences_from_preset(config),
              "config": asdict(config), "device": str(device), "budget": fit.budget,
              "initial_gaussians": fit.initial_count, "fitted_gaussians": len(fit.gaussians),
              "gaussians": len(cleaned), "unseen_skin_gaussians": completed, "fit_seconds": round(fit.seconds, 2),
              "half_resolution_steps": fit.coarse_steps,
              "clean_seconds": round(clean_seconds, 2),
              "polish_seconds": round(polish_seconds, 2),
              "loss_first": fit.losses[0] if fit.losses else None, "loss_last": fit.losses[-1] if fit.losses else None,
              "shading": {"facing_exponent": round(shading.exponent, 4), "points": shading.points,
                          "exposure_estimate": {train_views[k].name: round(float(g), 4)
                                                for k, g in enumerate(shading.gains())},
                          "exposures_matched": bool(config.match_exposures and shading.points > 0)},
              "densify": [asdict(d) for d in fit.densify], "psnr_in_mask_db": psnrs,
              "pose_correction_deg": corrections, "clean": asdict(clean_stats), "alpha_outside_mask": {"before": outside_before, "after": round(float(np.mean(outside_after)), 5)}}
    return SplatStage(cleaned.to("cpu"), refined, depths, report)


def _unseen_gaussians(unseen, fitted: Gaussians, cameras: Sequence[Camera], masks, config: SplatConfig) -> Gaussians:
    """Gaussians on the ``unseen`` skin's points (module :mod:`fingersplat3d.unseen_skin`): discs tangent to it, as the
    fit starts them, opaque (:data:`UNSEEN_OPACITY`), each in the median colour of the :data:`UNSEEN_NEIGHBOURS`
    nearest opaque fitted Gaussians. Dropped: those any fitted view sees outside its finger, widened by
    :data:`UNSEEN_MASK_SLACK` (the visual hull's rule; not the fit's vote, which keeps a Gaussian two views of three
    put on the finger: a guess has no photo of its own to outvote; nothing split: no photo says where its edge is), and
    every cell beyond such a one along its ring (:func:`_joined`). Dropping those a fitted view sees in front of its
    fitted surface as well (by 1 % of the camera's distance) left a band next to the seen skin uncovered and changed
    no training view (measured on two real captures, each with a view left out: placed PSNR 18.5 / 18.8 dB with that
    test, 19.5 / 20.6 dB without)."""
    import open3d as o3d
    from scipy.spatial import cKDTree

    from .init import gaussians_from_cloud
    from .voting import vote_labels

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(unseen.points, np.float64)))
    cloud.normals = o3d.utility.Vector3dVector(np.asarray(unseen.normals, np.float64))
    extra = gaussians_from_cloud(cloud, fitted.channels, opacity=UNSEEN_OPACITY, scale_factor=1.0,
                                 flatten=config.flatten).with_(facing_exponent=fitted.facing_exponent)
    source = fitted.detach().to("cpu")
    opaque = source.opacities > 0.5
    if int(opaque.sum()) >= UNSEEN_NEIGHBOURS:
        source = source.subset(opaque)
    _, nearest = cKDTree(source.means.numpy()).query(extra.means.numpy(), k=min(UNSEEN_NEIGHBOURS, len(source)))
    tone = np.median(source.sh_dc.numpy()[nearest.reshape(len(extra), -1)], axis=1)
    extra = extra.with_(sh_dc=torch.as_tensor(tone, dtype=extra.sh_dc.dtype))
    votes = vote_labels(extra.means, cameras, [_widened(mask) for mask in masks])
    return extra.subset(torch.as_tensor(_joined((votes.foreground == votes.seen).numpy(), unseen.chain, unseen.steps)))


def _joined(on_finger: np.ndarray, chain: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """``[N]`` bool: the unseen skin's cells kept, each run of cells past a ring's seen arc (``chain``, in ``steps``
    from it) up to its first cell a view saw off the finger, and only a run that starts within
    :data:`UNSEEN_START_CELLS` of the arc: a piece cut off from the seen skin floated beside the finger in views turned
    past the cameras."""
    keep = np.zeros(len(on_finger), bool)
    order = np.lexsort((steps, chain))
    bounds = np.flatnonzero(np.diff(chain[order])) + 1
    for run in np.split(order, bounds):
        if not len(run) or steps[run[0]] > UNSEEN_START_CELLS:
            continue
        broken = np.flatnonzero(~on_finger[run])
        keep[run[:broken[0]] if len(broken) else run] = True
    return keep


def _widened(mask: np.ndarray) -> np.ndarray:
    """``mask`` dilated by :data:`UNSEEN_MASK_SLACK` of its finger's size: the unseen skin next to a view's rim is seen
    edge-on there, and its section, drawn from the seen arc, lands a few pixels either side of the outline."""
    from ..segment.morphology import dilated

    return dilated(mask, max(1, int(round(UNSEEN_MASK_SLACK * np.sqrt(max(int(mask.sum()), 1))))))


def _shading(views: Sequence[View], cameras: Sequence[Camera], depths, config: SplatConfig):
    """The capture's shading exponent and the photos' exposures, estimated from the registered geometry
    (:mod:`.shading_estimate`) when either is asked for and there is any geometry; else none (the exponent 0 when
    only the exposures are asked for)."""
    from .shading_estimate import ShadingEstimate, estimate_shading

    if not (config.facing_shading or config.match_exposures) or depths is None:
        return ShadingEstimate.none(len(views))
    estimate = estimate_shading([view.image for view in views], [view.mask for view in views], cameras, depths)
    return estimate if config.facing_shading else replace(estimate, exponent=0.0)


def _alpha_outside(model: Gaussians, cameras: Sequence[Camera], masks, config: SplatConfig) -> float:
    from ..eval.image import fraction_alpha_outside

    values = []
    with torch.no_grad():
        for camera, mask in zip(cameras, masks):
            out = render_camera(model, camera, near_plane(model.means, camera, config.near_fraction))
            values.append(fraction_alpha_outside(out.alpha.cpu().numpy(), mask))
    return round(float(np.mean(values)), 5)
