"""The skin chart of a reconstructed finger: its surface unrolled by arc length, as a rolled print lays it flat.

A rolled impression records the skin of the pad rolled across the paper from one side of the nail to
the other: distances along the skin become distances on the print. The chart here gives every point
of the model's surface two such distances:

1. **The finger's frame.** The axis is the direction every view's silhouette axis is the image of
   (each view's axis line and its camera centre span a plane that holds the 3D axis: the axis is
   their common direction, by SVD), pointed toward the tip the silhouettes found; with one view, or
   views that all look from one side, the longest direction of the points (PCA). The pad is the side
   the cameras look at (their mean direction to the finger, across the axis); ``side = axis x pad``
   is a frontal photo's right with the tip up, so the print has a photo's handedness.
2. **The section's centre line.** Per 1-mm-ish station, a circle fitted to the points' section
   (Kasa's algebraic fit); a quadratic in the axis coordinate through those centres (the finger
   bends a little). The axis is then turned onto the centre line's direction at its middle and the
   fit redone (:data:`AXIS_ROUNDS`): the silhouettes do not see the finger's pitch toward a camera,
   and rings across a pitched axis put the pad's centre a few pixels above or below its sides on the
   print (measured on synthetic fingers: minutiae located within 8 px 70 % -> see tools/bench_print.py).
3. **The radius grid.** ``rho(x, phi)``: the mean radius of the model's points per cell of a grid of
   stations ``x`` along the axis and azimuths ``phi`` around it (2 degree cells; the station step is
   the arc of one cell at the median radius, so cells are square on the skin), smoothed by a
   normalised Gaussian of :data:`SMOOTHING_CELLS` (holes of a cell or two filled), azimuth periodic.
   **The pad's centre line** (``phi = 0``, the print's middle) is then moved onto the section's mirror line, the
   azimuth about which its widths are symmetric (:func:`mirror_offset`), and the grid made again: the cameras' mean
   direction is where the finger happened to face, not its pad's middle. A finger lying rolled in the rig had its
   print's rows drift sideways wherever the section narrows (the taper, the tip), a shear no similarity takes out
   (measured on 15 synthetic fingers, the true minutiae the print's geometry puts within 8 px: median 84 -> 91 %;
   tools/bench_print.py). A round section, or flanks not seen past their widest point, give no such line: the
   cameras' direction stays (``FingerFrame.pad_from``).
4. **Arc lengths.** ``b``: around each ring from the pad's centre line (``phi = 0``), the summed
   lengths of the grid's segments, signed toward ``side``; ``a``: along each meridian from the ring
   that most meridians cross, growing toward the base (the print is drawn tip up). Rolling turns the
   finger about its axis, so each ring is laid along one row of the paper: every meridian counts from
   one ring. Counting each from its own far end had put the print's rows where the surface happens
   to stop, which at the sides is where the side views lose the cap (measured on synthetic fingers:
   sides shifted 10-25 print pixels along the finger against the pad's centre). This is the chart
   ``fs3d synth`` lays its ridges on (:mod:`fingersplat3d.synth.shape`) up to how a meridian runs
   over the tip cap: near-isometric on the body of the finger, where rings and meridians meet at
   right angles; measured against the true rolled print in ``tools/bench_print.py``.

Pure numpy/scipy; units are the model's.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import ndimage

from ..errors import InputError
from ..scene import Camera
from ..segment.axis_planes import axis_plane_normal, planes_meet

__all__ = ["FingerFrame", "SkinChart", "finger_frame", "skin_chart", "kasa_circle", "PHI_STEP_DEG"]

PHI_STEP_DEG = 2.0  # azimuth cell of the radius grid
AXIS_ROUNDS = 2  # times the axis is turned onto the fitted centre line (step 2)
MIN_POINTS = 200  # fewer model points than this make no chart
MIRROR_SEARCH_DEG = 30  # how far from the cameras' mean direction the section's mirror line is looked for (degrees)
MIRROR_LOOK_DEG = 60  # the section's widths are read from looks this far either side of it (degrees)
MIRROR_MIN_RINGS = 5  # a look's width is used where this many rings are read, and
MIRROR_MIN_SHARE = 0.3  # this share of all the rings
MIRROR_SPAN_DEG = 30  # a mirror position pairs looks up to this far either side of it (degrees)
MIRROR_PAIRS = 15  # a mirror position is scored on this many pairs of looks or more
MIRROR_MIN_SPREAD = 0.02  # widths that vary less than this (relative) over the looks read: a round section, no line
MIRROR_CONTRAST = 0.5  # the mirror's score against the median position's: above, no mirror line (a round section)
MIRROR_MIN_DEG = 0.5  # a mirror line nearer phi = 0 than this leaves the chart as it is
SMOOTHING_CELLS = 2.5
"""Gaussian smoothing of the radius grid, in cells (~0.7 mm on an adult finger): depth rendered from Gaussians is
rough at the ridges' scale, and a chart that followed it would shift the photos' ridges by a fraction of a period
from node to node (measured: a one-cell smoothing left the ridges of the sample's print broken)."""
_PLANES_SPREAD = 0.05  # second singular value of the silhouette planes' normals, relative: below, one-sided views


@dataclass(frozen=True, eq=False)
class FingerFrame:
    """Axis (toward the tip), pad and side directions, and a point near the axis (world units)."""

    axis: np.ndarray  # [3] unit
    pad: np.ndarray  # [3] unit, across the axis, out of the pad (phi = 0)
    side: np.ndarray  # [3] unit, axis x pad: b grows this way
    origin: np.ndarray  # [3]
    axis_from: str  # "silhouettes" | "points"
    pad_from: str = "cameras"  # "cameras" | "mirror line": where phi = 0 was taken from (module docstring, step 3)

    def local(self, points: np.ndarray) -> np.ndarray:
        """World points ``[..., 3]`` -> ``(x along the axis, u toward the pad, w toward the side)``."""
        rel = np.asarray(points, np.float64) - self.origin
        return np.stack([rel @ self.axis, rel @ self.pad, rel @ self.side], -1)

    def world(self, local: np.ndarray) -> np.ndarray:
        local = np.asarray(local, np.float64)
        return self.origin + local[..., :1] * self.axis + local[..., 1:2] * self.pad + local[..., 2:3] * self.side


@dataclass(frozen=True, eq=False)
class SkinChart:
    """The radius grid's nodes, their arc-length coordinates and outward normals (``[X, P]`` arrays)."""

    frame: FingerFrame
    points: np.ndarray  # [X, P, 3] world, NaN where the model has no surface
    normals: np.ndarray  # [X, P, 3] unit, outward
    a: np.ndarray  # [X, P] arc length along the meridians from one ring, growing toward the base (NaN off the surface)
    b: np.ndarray  # [X, P] signed arc length around the rings from the pad's centre line
    x: np.ndarray  # [X] station coordinates along the axis (increasing toward the tip)
    phi: np.ndarray  # [P] azimuths (radians, -pi..pi)

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.a) & np.isfinite(self.b) & np.isfinite(self.points).all(-1)

    @property
    def node_spacing(self) -> float:
        """The typical distance between neighbouring nodes (model units)."""
        return float(self.x[1] - self.x[0]) if len(self.x) > 1 else 1.0


def finger_frame(points: np.ndarray, cameras: Sequence[Camera], axes_2d: Sequence[tuple[np.ndarray, np.ndarray]]) -> FingerFrame:
    """The finger's frame (module docstring, step 1) from its points ``[N, 3]`` and, per view, its camera and
    silhouette axis ``(origin uv, unit direction toward the tip)``."""
    points = np.asarray(points, np.float64)
    if len(points) < MIN_POINTS:
        raise InputError(f"the model has {len(points)} surface points: too few to unroll")
    centroid = points.mean(0)
    normals, tips = [], []
    for camera, (origin, direction) in zip(cameras, axes_2d):
        normal = axis_plane_normal(camera, origin, direction)
        if normal is not None:
            normals.append(normal)
            tips.append((camera, camera.pixel_directions(np.asarray(origin, np.float64)) @ camera.rotation,
                         np.asarray(direction, np.float64)))
    axis = planes_meet(normals, _PLANES_SPREAD)
    axis_from = "points" if axis is None else "silhouettes"
    if axis is None:
        _, _, vectors = np.linalg.svd(points - centroid, full_matrices=False)
        axis = vectors[0]
    # Toward the tip: the way the views' silhouettes say it points, each seen in its image.
    vote = 0.0
    for camera, ray, direction in tips:
        along = camera.rotation @ axis
        ray_cam = camera.rotation @ ray
        image_direction = along[:2] - ray_cam[:2] / ray_cam[2] * along[2]
        vote += float(np.sign(image_direction @ direction))
    axis = axis if vote >= 0 else -axis
    toward_cameras = np.mean([c.center - centroid for c in cameras], 0) if len(cameras) else np.zeros(3)
    pad = toward_cameras - (toward_cameras @ axis) * axis
    if np.linalg.norm(pad) < 1e-9:  # no camera off the axis: any direction across it
        pad = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    pad = pad / np.linalg.norm(pad)
    return FingerFrame(axis, pad, np.cross(axis, pad), centroid, axis_from)


def _turned(frame: FingerFrame, slope: np.ndarray) -> FingerFrame:
    """``frame`` with its axis turned onto the direction ``axis + slope[0] pad + slope[1] side``."""
    axis = frame.axis + slope[0] * frame.pad + slope[1] * frame.side
    axis = axis / np.linalg.norm(axis)
    pad = frame.pad - (frame.pad @ axis) * axis
    pad = pad / np.linalg.norm(pad)
    return FingerFrame(axis, pad, np.cross(axis, pad), frame.origin, frame.axis_from, frame.pad_from)


def _rolled(frame: FingerFrame, angle: float) -> FingerFrame:
    """``frame`` with its pad turned by ``angle`` radians about the axis, toward ``side`` (onto the mirror line)."""
    pad = np.cos(angle) * frame.pad + np.sin(angle) * frame.side
    return FingerFrame(frame.axis, pad, np.cross(frame.axis, pad), frame.origin, frame.axis_from, "mirror line")


def kasa_circle(u: np.ndarray, w: np.ndarray) -> np.ndarray | None:
    """``[3]``: the centre ``(cu, cw)`` and radius of the circle through the points ``(u, w)`` (Kasa's algebraic fit:
    least squares on ``u^2 + w^2 = 2 cu u + 2 cw w + c``), or None where it has no real radius."""
    design = np.column_stack([u, w, np.ones_like(u)])
    solution, *_ = np.linalg.lstsq(design, u * u + w * w, rcond=None)
    cu, cw = solution[0] / 2, solution[1] / 2
    squared = solution[2] + cu * cu + cw * cw
    return np.array([cu, cw, np.sqrt(squared)]) if squared > 0 else None


def _centre_line(local: np.ndarray, station: float) -> np.ndarray:
    """Quadratic coefficients ``[3, 2]`` of the section centre ``(u, w)`` against ``x`` (module docstring, step 2)."""
    x, u, w = local.T
    edges = np.arange(x.min(), x.max() + station, station)
    found = []
    for low in edges[:-1]:
        inside = (x >= low) & (x < low + station)
        if inside.sum() < 30:
            continue
        circle = kasa_circle(u[inside], w[inside])
        if circle is not None:
            found.append((low + 0.5 * station, *circle, inside.sum()))
    if not found:
        return np.array([[0.0, 0.0], [0.0, 0.0], [np.median(u), np.median(w)]])
    found = np.array(found)
    typical = np.median(found[:, 3])
    keep = (found[:, 3] > 0.5 * typical) & (found[:, 3] < 1.5 * typical)  # no tip cap or stray stations
    found = found[keep] if keep.sum() >= 1 else found
    degree = min(2, len(found) - 1)
    coefficients = np.zeros((3, 2))
    for column in (0, 1):
        fit = np.polyfit(found[:, 0], found[:, 1 + column], degree, w=np.sqrt(found[:, 4]))
        coefficients[3 - len(fit):, column] = fit
    return coefficients


def skin_chart(points: np.ndarray, frame: FingerFrame, mirror: bool = True) -> SkinChart:
    """The chart of the surface sampled by ``points [N, 3]`` in ``frame`` (module docstring, steps 2-4); ``mirror``:
    phi = 0 moved onto the section's mirror line where it has one (step 3)."""
    points = np.asarray(points, np.float64)
    points = points[np.isfinite(points).all(1)]
    if len(points) < MIN_POINTS:
        raise InputError(f"the model has {len(points)} surface points: too few to unroll")
    for round_ in range(AXIS_ROUNDS + 1):
        local = frame.local(points)
        spread = np.percentile(np.hypot(local[:, 1] - np.median(local[:, 1]), local[:, 2] - np.median(local[:, 2])), 90)
        centre = _centre_line(local, max(spread / 8.0, 1e-9))
        middle = float(np.median(local[:, 0]))
        slope = np.array([np.polyval(np.polyder(centre[:, c]), middle) for c in (0, 1)])
        if np.hypot(*slope) < 1e-4 or round_ == AXIS_ROUNDS:  # the last centre line stays in the frame it was fitted in
            break
        frame = _turned(frame, slope)  # rings across the centre line, not across the first guess of the axis
    cu, cw = (np.polyval(centre[:, c], local[:, 0]) for c in (0, 1))
    radius = np.hypot(local[:, 1] - cu, local[:, 2] - cw)
    azimuth = np.arctan2(local[:, 2] - cw, local[:, 1] - cu)
    phi_step = np.radians(PHI_STEP_DEG)
    step = max(float(np.median(radius)) * phi_step, 1e-9)
    low = local[:, 0].min()
    stations = int(np.floor((local[:, 0].max() - low) / step)) + 1
    columns = int(round(2 * np.pi / phi_step))
    row = np.clip(((local[:, 0] - low) / step).astype(int), 0, stations - 1)
    col = np.clip(((azimuth + np.pi) / phi_step).astype(int), 0, columns - 1)
    cell = row * columns + col
    count = np.bincount(cell, minlength=stations * columns).reshape(stations, columns).astype(np.float64)
    total = np.bincount(cell, radius, minlength=stations * columns).reshape(stations, columns)
    smooth = dict(sigma=SMOOTHING_CELLS, mode=("nearest", "wrap"))
    weight = ndimage.gaussian_filter(np.minimum(count, 1.0), **smooth)
    mean = np.divide(total, np.maximum(count, 1e-12), out=np.zeros_like(total), where=count > 0)
    rho = ndimage.gaussian_filter(mean * (count > 0), **smooth) / np.maximum(weight, 1e-12)
    near = ndimage.binary_dilation(count > 0, structure=np.ones((3, 3), bool), iterations=1)
    rho = np.where(near & (weight > 0.15), rho, np.nan)
    if mirror:
        offset = mirror_offset(rho)
        if offset is not None and abs(offset) > np.radians(MIRROR_MIN_DEG):
            return skin_chart(points, _rolled(frame, offset), mirror=False)
    x = low + (np.arange(stations) + 0.5) * step
    phi = -np.pi + (np.arange(columns) + 0.5) * phi_step
    cu_s, cw_s = (np.polyval(centre[:, c], x) for c in (0, 1))
    local_nodes = np.stack([np.broadcast_to(x[:, None], rho.shape), cu_s[:, None] + rho * np.cos(phi)[None, :],
                            cw_s[:, None] + rho * np.sin(phi)[None, :]], -1)
    nodes = frame.world(local_nodes)
    return SkinChart(frame, nodes, _normals(nodes, frame), *_arc_lengths(nodes, phi), x, phi)


def mirror_offset(rho: np.ndarray) -> float | None:
    """The azimuth (radians, toward ``side``) of the section's mirror line (module docstring, step 3), or None.

    Seen from azimuth ``look``, a ring's width is the spread of its nodes across that direction; a section mirrored
    about ``theta0`` is as wide from ``theta0 + d`` as from ``theta0 - d``. Widths are read only where both extremes
    are inside the surface (a neighbour on either side): an extreme at the surface's edge is where the views stopped,
    not the flank's widest point. Each ring's widths are taken relative to its own median, and per ``look`` their
    median over the rings (a look read by fewer than :data:`MIRROR_MIN_RINGS` of them, or :data:`MIRROR_MIN_SHARE` of
    all, is not used). Mirror positions within :data:`MIRROR_SEARCH_DEG`, in degrees, are scored by the mean squared
    difference of the widths they pair up to :data:`MIRROR_SPAN_DEG` either side (:data:`MIRROR_PAIRS` pairs or more);
    the best is refined by a parabola. None where the widths vary by less than :data:`MIRROR_MIN_SPREAD` over the looks
    or the best does not stand out (above :data:`MIRROR_CONTRAST` times the median score): a section too round to
    have a line; where the best is at the search's edge; or where no look is read (the flanks not seen past their
    widest point, as in renders cropped to the pad). The flanks are what the silhouettes hold; the radii's
    own symmetry, tried first, was misled by the relief of another group's renders (a line 8-10 degrees off on every
    triplet of a finger whose silhouettes are symmetric about its middle render).
    """
    stations, columns = rho.shape
    phi = -np.pi + (np.arange(columns) + 0.5) * np.radians(PHI_STEP_DEG)
    valid = np.isfinite(rho)
    radius = np.where(valid, rho, 0.0)
    inner = valid & np.roll(valid, 1, 1) & np.roll(valid, -1, 1)
    rows = np.arange(stations)
    looks = np.arange(-MIRROR_LOOK_DEG, MIRROR_LOOK_DEG + 1)
    widths = np.full((len(looks), stations), np.nan)
    for index, look in enumerate(np.radians(looks)):
        across = radius * np.sin(phi - look)[None, :]
        high = np.argmax(np.where(valid, across, -np.inf), 1)
        low = np.argmin(np.where(valid, across, np.inf), 1)
        read = inner[rows, high] & inner[rows, low]
        widths[index, read] = (across[rows, high] - across[rows, low])[read]
    read = np.isfinite(widths)
    rings = read.any(0)
    if not rings.any():
        return None
    typical = np.array([np.median(widths[read[:, ring], ring]) for ring in np.flatnonzero(rings)])
    relative = widths[:, rings] / typical
    enough = read[:, rings].sum(1) >= max(MIRROR_MIN_RINGS, MIRROR_MIN_SHARE * stations)
    profile = np.full(len(looks), np.nan)
    for index in np.flatnonzero(enough):
        finite = relative[index][np.isfinite(relative[index])]
        profile[index] = np.median(finite) if finite.size else np.nan
    if not np.any(np.isfinite(profile)) or np.nanmax(profile) - np.nanmin(profile) < MIRROR_MIN_SPREAD:
        return None
    centres = np.arange(-MIRROR_SEARCH_DEG, MIRROR_SEARCH_DEG + 1)
    cost = np.full(len(centres), np.inf)
    offsets = np.arange(1, MIRROR_SPAN_DEG + 1)
    for index, centre in enumerate(centres):
        ahead, behind = centre + offsets + MIRROR_LOOK_DEG, centre - offsets + MIRROR_LOOK_DEG  # indices into looks
        inside = (ahead < len(looks)) & (behind >= 0)
        pairs = profile[ahead[inside]], profile[behind[inside]]
        both = np.isfinite(pairs[0]) & np.isfinite(pairs[1])
        if both.sum() >= MIRROR_PAIRS:
            cost[index] = float(np.mean((pairs[0][both] - pairs[1][both]) ** 2))
    scored = cost[np.isfinite(cost)]
    best = int(np.argmin(cost))
    if (not scored.size or best in (0, len(cost) - 1) or not np.median(scored) > 0
            or cost[best] > MIRROR_CONTRAST * np.median(scored)):
        return None
    before, here, after = cost[best - 1:best + 2]
    curvature = before - 2 * here + after
    fraction = 0.5 * (before - after) / curvature if np.isfinite(curvature) and curvature > 0 else 0.0
    return float(np.radians(centres[best] + np.clip(fraction, -0.5, 0.5)))


def _derivative(nodes: np.ndarray, axis: int, wrap: bool) -> np.ndarray:
    """Central difference of the node grid along ``axis``; one-sided where a neighbour is missing (the chart's rim)."""
    if nodes.shape[axis] < 2:
        return np.full_like(nodes, np.nan)
    if wrap:
        ahead, behind = np.roll(nodes, -1, axis) - nodes, nodes - np.roll(nodes, 1, axis)
    else:
        step = np.diff(nodes, axis=axis)
        pad = np.full_like(np.take(nodes, [0], axis=axis), np.nan)
        ahead, behind = np.concatenate([step, pad], axis), np.concatenate([pad, step], axis)
    both = 0.5 * (ahead + behind)
    return np.where(np.isfinite(both), both, np.where(np.isfinite(ahead), ahead, behind))


def _normals(nodes: np.ndarray, frame: FingerFrame) -> np.ndarray:
    """Unit outward normals of the node grid (NaN only where a node has no neighbour in some direction)."""
    along = _derivative(nodes, 0, wrap=False) if nodes.shape[0] > 1 else np.broadcast_to(frame.axis, nodes.shape)
    normal = np.cross(along, _derivative(nodes, 1, wrap=True))
    radial = nodes - frame.origin
    radial = radial - (radial @ frame.axis)[..., None] * frame.axis
    normal = np.where(((normal * radial).sum(-1) < 0)[..., None], -normal, normal)
    with np.errstate(invalid="ignore", divide="ignore"):
        return normal / np.linalg.norm(normal, axis=-1, keepdims=True)


def _arc_lengths(nodes: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(a, b)`` of every node (module docstring, step 4); NaN where the path from its origin is broken."""
    stations, columns = nodes.shape[:2]
    ring = np.linalg.norm(np.diff(nodes, axis=1), axis=-1)  # [X, P-1]: node j to j+1
    zero = int(np.argmin(np.abs(phi)))
    b = np.full((stations, columns), np.nan)
    b[:, zero] = 0.0
    b[:, zero + 1:] = np.cumsum(ring[:, zero:], axis=1)  # NaN propagates past a gap
    b[:, :zero] = -np.cumsum(ring[:, :zero][:, ::-1], axis=1)[:, ::-1]
    b[~np.isfinite(nodes).all(-1)] = np.nan
    # a: summed along each meridian from the ring that most meridians cross (rolling lays each ring along one row).
    meridian = np.linalg.norm(np.diff(nodes, axis=0), axis=-1)  # [X-1, P]: station i to i+1
    finite = np.isfinite(nodes).all(-1)
    a = np.full((stations, columns), np.nan)
    if not finite.any():
        return a, b
    reference = int(np.argmax(finite.sum(1)))
    a[reference] = np.where(finite[reference], 0.0, np.nan)
    a[reference + 1:] = a[reference] - np.cumsum(meridian[reference:], axis=0)  # toward the tip
    a[:reference] = a[reference] + np.cumsum(meridian[:reference][::-1], axis=0)[::-1]  # toward the base
    a[~np.isfinite(nodes).all(-1)] = np.nan
    return a, b
