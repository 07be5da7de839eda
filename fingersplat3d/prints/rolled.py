"""The rolled-equivalent print of a reconstruction: the skin chart drawn at ~500 ppi, textured from the photos.

Given the chart (:mod:`fingersplat3d.prints.skin_chart`) and a scale in print pixels per model unit:

1. **Print pixels to the surface.** Each chart node sits at ``(x, y) = (b - b_min, a - a_min) * scale``
   (tip up, a frontal photo's handedness); the nodes' 3D points and normals are interpolated
   linearly (Delaunay over the nodes) to every print pixel within 1.5 node spacings of a node.
   That ``[H, W, 3]`` map carries anything found on the print back to the model and, through the
   cameras, to every photo.
2. **Texture from the views that see it most squarely.** Each pixel's point is projected into every
   view; a view counts where the point is on its finger's ridge area, in front (its depth map
   agrees within :func:`~fingersplat3d.align.transfer.surface_tolerance`) and facing it. Its
   band-passed ridge texture (:func:`~fingersplat3d.align.correspond.texture.ridge_texture`, unit
   local RMS, so exposure and shading drop out) is weighted by the facing ramp of the photometric
   refinement (none beyond ~75 degrees) times ``(cos / best cos)^VIEW_SHARPNESS``: the most frontal view
   dominates, neighbours blend over a band where they face the skin about equally (blending two
   views everywhere would average slightly misregistered ridges into grey).
3. **Enhanced, ridges dark.** The blend is filtered along its ridge flow at its own ridge period
   (:func:`~fingersplat3d.prints.enhance.gabor_enhance`: pores and the cross-hatch of two blended views
   go, ridges stay) and inked ``128 -+ 48 * texture`` like the photos' contact-like prints
   (:mod:`fingersplat3d.eval.contact`): ridges dark, 255 outside the skin.

Skin where the ridge flow is incoherent (noise, two blended views at odds, the crease) is left white
(:data:`COHERENCE_MIN`). The pad's coverage is the roll the textured skin spans: per station of the chart the azimuth
covered by some view, the median over the stations that have any. Pure numpy/scipy/OpenCV.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import ndimage
from scipy.interpolate import LinearNDInterpolator
from scipy.spatial import cKDTree

from ..align.correspond.texture import estimate_ridge_period
from ..align.solve.photometric import facing_weight
from ..align.transfer import surface_tolerance
from ..errors import InputError
from ..eval.contact import GRAY, MARGIN, SWING, TARGET_PERIOD_PX
from ..sampling import sample_bilinear, sample_nearest
from ..scene import Camera
from .skin_chart import PHI_STEP_DEG, SkinChart
from .enhance import gabor_enhance, ridge_coherence

__all__ = ["PrintView", "RolledEquivalent", "rolled_print", "default_px_per_unit", "VIEW_SHARPNESS"]

VIEW_SHARPNESS = 20.0
"""Exponent of the facing cosine, relative to the best view's, in the view weights: a view 20 degrees less
square to the skin than the best one weighs ~0.2 of it at 0 vs 20 degrees and ~0.01 at 25 vs 45; views blend
only over a narrow band where they face the skin about equally. Measured when the print was built
(tools/bench_print.py, seeds 0-2, docs/measurements.md "Prints"): true minutiae located within 8 px, median, 75 % with
plain ``cos^8`` weights, 77 % with this ratio at 20, no change at 40."""
COHERENCE_MIN = 0.3
"""Skin whose ridge flow is less coherent than this over three periods (:func:`~fingersplat3d.prints.enhance.ridge_coherence`)
is left white, holes (cores, deltas) filled: noise there only feeds mindtct false minutiae. Measured: real dev captures'
rolled prints against each other, bozorth3 EER 56 -> 49 % on the same 36 pairs; synthetic prints unchanged (located
minutiae 77 %, genuine score 140). 0 turns it off."""
MAX_SIDE_PX = 4000  # a print larger than this is a scale mistake, not a finger


@dataclass(frozen=True, eq=False)
class PrintView:
    """One view as the print needs it."""

    name: str
    camera: Camera
    depth: np.ndarray  # [H, W] camera-frame depth, NaN off the finger
    texture: np.ndarray  # [H, W] band-passed ridge texture (ridges positive), 0 outside the ridge area
    area: np.ndarray  # [H, W] bool, the ridge area


@dataclass(frozen=True, eq=False)
class RolledEquivalent:
    """A rolled-equivalent print and what it is made of."""

    image: np.ndarray  # [H, W] uint8, ridges dark, 255 outside the skin
    mask: np.ndarray  # [H, W] bool, the textured skin
    points: np.ndarray  # [H, W, 3] float32 model points of the print's pixels, NaN outside
    px_per_unit: float  # print pixels per model unit
    coverage_deg: float  # roll spanned by the textured skin (module docstring)
    view_share: dict  # view name -> share of the print's pixels it dominates
    period_px: float  # the print's ridge period
    origin_px: tuple[float, float]  # print pixel (x, y) of the chart's origin: the pad's centre line (b = 0) at a = 0
    centred_on: str = "cameras"  # where the pad's centre line came from: "mirror line" | "cameras" (skin_chart step 3)

    @property
    def area_px(self) -> int:
        return int(self.mask.sum())


def rolled_print(chart: SkinChart, views: Sequence[PrintView], px_per_unit: float, *, ridges: str = "bright",
                 enhancer: str = "gabor") -> RolledEquivalent:
    """The rolled-equivalent print of ``chart`` textured from ``views`` (module docstring)."""
    if ridges not in ("bright", "dark"):
        raise InputError(f"ridges={ridges!r}: use 'bright' (crests are the bright lines) or 'dark'")
    if not (np.isfinite(px_per_unit) and px_per_unit > 0):
        raise InputError(f"the print scale must be a positive number of pixels per model unit, got {px_per_unit!r}")
    valid = chart.valid
    if valid.sum() < 16:
        raise InputError("the model's surface could not be unrolled: too few chart nodes")
    node_xy = np.stack([chart.b[valid], chart.a[valid]], 1) * px_per_unit
    low = node_xy.min(0) - MARGIN
    node_xy -= low
    width, height = (np.ceil(node_xy.max(0)).astype(int) + MARGIN + 1)
    if max(width, height) > MAX_SIDE_PX:
        raise InputError(f"the print would be {width}x{height} px: the scale ({px_per_unit:.3g} px per model unit) is wrong")
    rows, cols = np.mgrid[0:height, 0:width]
    pixels = np.stack([cols.ravel(), rows.ravel()], 1).astype(np.float64)
    distance, _ = cKDTree(node_xy).query(pixels, distance_upper_bound=1.5 * chart.node_spacing * px_per_unit + 1.0)
    near = np.isfinite(distance)
    values = np.concatenate([chart.points[valid], chart.normals[valid]], 1)
    sampled = np.full((len(pixels), 6), np.nan)
    sampled[near] = LinearNDInterpolator(node_xy, values)(pixels[near])
    points, normals = sampled[:, :3], sampled[:, 3:]
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    blend, weights = _blend(points, normals, views)
    total = weights.sum(0)
    inked = total > 0
    mask = inked.reshape(height, width)
    if mask.sum() < 64:
        raise InputError("no view sees the model's skin squarely enough to texture a print")
    texture = np.zeros(len(pixels))
    texture[inked] = blend[inked] / total[inked]
    texture = texture.reshape(height, width).astype(np.float32)
    period = estimate_ridge_period(0.5 + 0.25 * texture, mask)
    if enhancer == "gabor":
        enhanced = gabor_enhance(texture, mask, period)
    else:  # pyfing's (prints/learned.py), measured against the Gabor filter in docs/measurements.md
        from .learned import pyfing_enhance

        enhanced = pyfing_enhance(texture, mask, period, enhancer)
    if COHERENCE_MIN > 0:
        flowing = ndimage.binary_fill_holes(ridge_coherence(texture, mask, period) >= COHERENCE_MIN)
        flowing = ndimage.binary_opening(flowing, iterations=int(period))
        labels, count = ndimage.label(mask & flowing)
        if count:  # the pad in one piece: specks of coherent noise off it go
            sizes = ndimage.sum_labels(np.ones_like(labels), labels, index=np.arange(1, count + 1))
            mask = ndimage.binary_fill_holes(labels == 1 + int(np.argmax(sizes))) & mask
        else:
            mask = mask & flowing
    sign = -1.0 if ridges == "bright" else 1.0
    image = np.where(mask, np.clip(np.rint(GRAY + sign * SWING * enhanced), 0, 254), 255).astype(np.uint8)
    dominant = np.argmax(weights, 0)
    share = {view.name: float(np.mean(dominant[inked] == k)) for k, view in enumerate(views)}
    point_map = np.where(mask[..., None], points.reshape(height, width, 3), np.nan).astype(np.float32)
    keep = _print_window(mask)
    return RolledEquivalent(image[keep], mask[keep], point_map[keep], float(px_per_unit), _coverage(chart, views), share,
                            float(period), (float(-low[0] - (keep[1].start or 0)), float(-low[1] - (keep[0].start or 0))),
                            chart.frame.pad_from)


def _print_window(mask: np.ndarray) -> tuple[slice, slice]:
    """The rows and columns of the print's inked skin and :data:`~fingersplat3d.eval.contact.MARGIN` white pixels
    round it. The chart spans the whole finger in view, the print the ridge area only (up to the crease, and
    none of the skin no view faces): uncropped, a third of a real capture's print was white."""
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    if not rows.size:  # nothing inked kept: the blank canvas, which the print's callers refuse as too small
        return slice(None), slice(None)
    return (slice(max(int(rows[0]) - MARGIN, 0), min(int(rows[-1]) + MARGIN + 1, mask.shape[0])),
            slice(max(int(cols[0]) - MARGIN, 0), min(int(cols[-1]) + MARGIN + 1, mask.shape[1])))


def _view_weights(points: np.ndarray, normals: np.ndarray, view: PrintView) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per point: the view's facing ramp (0 where it does not see the point, module docstring step 2), its facing
    cosine, and where the point lands in the view ``[N, 2]``."""
    ramp = np.zeros(len(points))
    finite = np.isfinite(points).all(1) & np.isfinite(normals).all(1)
    uv, z = view.camera.project(np.where(finite[:, None], points, 0.0))
    uv[~finite] = np.nan
    seen_depth = sample_bilinear(view.depth, uv)
    in_front = np.abs(seen_depth - z) <= surface_tolerance(view.depth)
    on_area = sample_nearest(view.area.astype(np.float64), uv) > 0.5
    toward = view.camera.center - points
    with np.errstate(invalid="ignore", divide="ignore"):
        facing = (normals * toward).sum(1) / np.linalg.norm(toward, axis=1)
    ok = finite & in_front & on_area & np.isfinite(facing)
    ramp[ok] = facing_weight(facing[ok])
    return ramp, np.where(ok, facing, 0.0), uv


def _blend(points: np.ndarray, normals: np.ndarray, views: Sequence[PrintView]) -> tuple[np.ndarray, np.ndarray]:
    """Weighted sum of the views' textures at ``points`` and the weights ``[V, N]``: each view's facing ramp times
    ``(cos / best cos) ** VIEW_SHARPNESS`` (the most frontal view of each point weighs its ramp)."""
    looks = [_view_weights(points, normals, view) for view in views]
    best = np.max([facing for _, facing, _ in looks], axis=0)
    weights = np.zeros((len(views), len(points)))
    blend = np.zeros(len(points))
    for k, (view, (ramp, facing, uv)) in enumerate(zip(views, looks)):
        use = np.flatnonzero(ramp > 0)
        if use.size:
            values = sample_bilinear(view.texture, uv[use])
            good = np.isfinite(values)
            index = use[good]
            weights[k, index] = ramp[index] * (facing[index] / best[index]) ** VIEW_SHARPNESS
            blend[index] += weights[k, index] * values[good]
    return blend, weights


def _coverage(chart: SkinChart, views: Sequence[PrintView]) -> float:
    """Degrees of roll the textured skin spans (module docstring)."""
    shape = chart.points.shape[:2]
    points, normals = chart.points.reshape(-1, 3), chart.normals.reshape(-1, 3)
    covered = np.zeros(len(points), bool)
    for view in views:
        covered |= _view_weights(points, normals, view)[0] > 0
    per_station = covered.reshape(shape).sum(1) * PHI_STEP_DEG
    per_station = per_station[per_station > 0]
    return float(np.median(per_station)) if per_station.size else 0.0


def default_px_per_unit(views: Sequence[PrintView], periods_px: Sequence[float]) -> float:
    """Print pixels per model unit from the photos' ridge periods: the median period, in model units, becomes
    :data:`~fingersplat3d.eval.contact.TARGET_PERIOD_PX` (9 px: the ~0.46 mm of adult fingers at 500 ppi)."""
    periods = []
    for view, period in zip(views, periods_px):
        finite = view.depth[np.isfinite(view.depth)]
        if finite.size and np.isfinite(period) and period > 0:
            periods.append(period * float(np.median(finite)) / float(view.camera.K[0, 0]))
    if not periods:
        raise InputError("no view gave a ridge period to scale the print by (give --px-per-mm)")
    return TARGET_PERIOD_PX / float(np.median(periods))
