"""Skin that no view sees, next to the skin they see: the finger's section carried round past where the views stop.

A left-out view, or a new view turned past the cameras, looks at skin beyond every fitted view's rim. Fitted only
to what the views see, the Gaussians leave a hole there, rendered as background: on the real dev captures the
band beyond the front view's rim was 7-17 % of a left-out side view's finger and a third of its squared error
(docs/measurements.md). Most of the finger's section is seen (each view's cloud stops short of its rim, where its
depth is the prior's: two views of a real capture leave ~180 degrees of it, three ~230), and the rest of the ring
is close to the circle the seen arc draws.

Per ring of the skin chart (:func:`~fingersplat3d.prints.skin_chart.skin_chart`: stations along the finger's
axis, 2-degree cells round it), a ring seen over at least :data:`MIN_SEEN_DEG` degrees is fitted with a circle
(Kasa), its centre and radius smoothed along the finger. The cells within :data:`EXTEND_DEG` degrees of the ring's
seen arc, and unseen, get a point on that circle, moved off it by the seen surface's own offset from the circle at
the arc's nearest end (fading to none over the extension, so the surface continues without a step), and its
outward normal. A circle, not a richer section: a second-order Fourier radius fitted to the ~180 degrees two views
leave doubled the section's size past the arc on a real capture.

The splat stage adds Gaussians there after its fit (:func:`fingersplat3d.splat.stage.run_splat_stage`, ``unseen``),
in the tone of the nearest fitted skin and without ridges, as no photo saw any: started before the fit, the
training views, which see that skin only edge-on at their rims, made them transparent. These points never enter
``fused.ply``, the registration's depth maps or the prints, which stay what the photos measured.

Pure numpy; the chart, its frame from the views' silhouettes and each ring's circle are the rolled print's
(:mod:`fingersplat3d.prints.skin_chart`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import ndimage

from .errors import InputError
from .scene import Camera

__all__ = ["UnseenSkin", "unseen_skin", "unseen_skin_of_cloud", "EXTEND_DEG", "MIN_SEEN_DEG"]

EXTEND_DEG = 50.0
"""How far round each ring past its seen arc the section is carried (degrees, each side)."""
MIN_SEEN_DEG = 120.0
"""A ring seen over less than this (degrees) is not completed: too short an arc to draw its section from."""
SEEN_WITHIN_DEG = 75.0
"""Skin a fitted view sees within this angle of square-on is left to the fit, whether or not the cloud has it."""
SMOOTH_RINGS = 2.0  # Gaussian smoothing of the section's coefficients along the finger, in rings
MAX_POINTS = 200_000  # the chart's points the frame and chart are made from (a thinned cloud draws the same rings)


@dataclass(frozen=True)
class UnseenSkin:
    """World points ``[N, 3]`` and unit outward normals ``[N, 3]`` of skin no view saw; ``chain [N]``: the run of cells
    each continues (one per ring and side of its seen arc), ``steps [N]``: how many cells past the arc's end it lies."""

    points: np.ndarray
    normals: np.ndarray
    chain: np.ndarray
    steps: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


def unseen_skin(points: np.ndarray, cameras: Sequence[Camera], masks: Sequence[np.ndarray], *,
                extend_deg: float = EXTEND_DEG, min_seen_deg: float = MIN_SEEN_DEG) -> UnseenSkin:
    """The unseen skin next to the surface sampled by ``points [N, 3]``, the views' ``cameras`` and ``masks`` giving
    the finger's axis (module docstring). Empty where the points draw no chart."""
    from .prints.skin_chart import PHI_STEP_DEG, finger_frame, kasa_circle, skin_chart
    from .segment.silhouette import orient_frames

    points = np.asarray(points, np.float64)
    empty = UnseenSkin(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int), np.zeros(0, int))
    points = points[np.isfinite(points).all(1)]
    if len(points) > MAX_POINTS:
        points = points[np.linspace(0, len(points) - 1, MAX_POINTS).astype(int)]
    try:
        frames = orient_frames([np.asarray(mask, bool) for mask in masks])
        frame = finger_frame(points, cameras, [(f.origin, f.axis) for f in frames])
        chart = skin_chart(points, frame, mirror=False)
    except (InputError, ValueError, np.linalg.LinAlgError):
        return empty
    local = chart.frame.local(chart.points)  # [X, P, 3]: x, u, w
    seen = np.isfinite(local).all(-1)
    rings, cells = seen.shape
    min_cells = int(np.ceil(min_seen_deg / PHI_STEP_DEG))
    reach = int(round(extend_deg / PHI_STEP_DEG))
    circles = np.full((rings, 3), np.nan)
    for ring in range(rings):
        if seen[ring].sum() >= min_cells:
            circle = kasa_circle(local[ring, seen[ring], 1], local[ring, seen[ring], 2])
            if circle is not None:
                circles[ring] = circle
    fitted = np.isfinite(circles).all(1)
    if not fitted.any():
        return empty
    weight = ndimage.gaussian_filter1d(fitted.astype(np.float64), SMOOTH_RINGS, mode="nearest")
    smooth = ndimage.gaussian_filter1d(np.where(fitted[:, None], circles, 0.0), SMOOTH_RINGS, axis=0, mode="nearest")
    circles = np.where(fitted[:, None], smooth / np.maximum(weight[:, None], 1e-12), np.nan)
    # each cell's circular distance (in cells) to the ring's nearest seen one, and which one that is
    tiled = np.tile(~seen, (1, 3))
    distance, (_, nearest) = ndimage.distance_transform_edt(tiled, sampling=(1e6, 1.0), return_indices=True)
    beyond = nearest[:, cells:2 * cells] > np.arange(cells, 2 * cells)[None, :]  # the arc's end lies past the cell
    distance, nearest = distance[:, cells:2 * cells], nearest[:, cells:2 * cells] % cells
    fill = fitted[:, None] & ~seen & (distance <= reach)
    if not fill.any():
        return empty
    ring_of, cell_of = np.nonzero(fill)
    circle = circles[ring_of]
    # the seen surface's offset from the circle at the arc's nearest end, faded out over the extension
    end = local[ring_of, nearest[ring_of, cell_of]]
    offset = np.hypot(end[:, 1] - circle[:, 0], end[:, 2] - circle[:, 1]) - circle[:, 2]
    radius = circle[:, 2] + offset * np.clip(1.0 - distance[ring_of, cell_of] / max(reach, 1), 0.0, 1.0)
    # the cell's azimuth about the chart's centre line, taken about the ring's circle (within a fraction of the
    # radius of each other)
    theta = chart.phi[cell_of]
    u = circle[:, 0] + radius * np.cos(theta)
    w = circle[:, 1] + radius * np.sin(theta)
    x = chart.x[ring_of]
    world = chart.frame.world(np.column_stack([x, u, w]))
    normals = np.cos(theta)[:, None] * chart.frame.pad + np.sin(theta)[:, None] * chart.frame.side
    ok = np.isfinite(world).all(1) & (radius > 0)
    for camera in cameras:  # skin a view sees squarely enough is its own to show, unseen or not in the cloud
        toward = camera.center - world
        facing = np.einsum("nk,nk->n", normals, toward) / np.maximum(np.linalg.norm(toward, axis=1), 1e-12)
        ok &= ~(facing > np.cos(np.radians(SEEN_WITHIN_DEG)))
    chain = 2 * ring_of + beyond[ring_of, cell_of]
    steps = np.round(distance[ring_of, cell_of]).astype(int)
    return UnseenSkin(world[ok], normals[ok], chain[ok], steps[ok])


def unseen_skin_of_cloud(cloud, cameras: Sequence[Camera], masks: Sequence[np.ndarray]) -> UnseenSkin | None:
    """The unseen skin next to an Open3D ``cloud`` of the views seen by ``cameras`` with ``masks``, or None where there
    is none (module docstring)."""
    skin = unseen_skin(np.asarray(cloud.points), cameras, masks)
    return skin if len(skin) >= 2 else None
