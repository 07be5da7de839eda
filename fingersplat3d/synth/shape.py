"""A procedural distal phalanx: a tapered, slightly bent tube with a rounded tip, in millimetres.

Finger frame: the finger axis is +x (base at ``x = tip_x - length``, tip pole at ``x = tip_x``),
the pad (palmar side) faces -z and the nail side +z; y completes a right-handed frame.

The surface is a grid over (axial station i, azimuth j): ``phi = 0`` points at the pad centre,
``phi = pi`` at the nail. The cross-section is not a circle: an ellipse on the pad half (a super-ellipse with the
``wide`` shapes), a flatter super-ellipse on the nail half, wider than high. Along the axis the section tapers, the axis bends
slightly toward the palm, and the last ``cap`` millimetres close as an ellipsoidal cap.

Skin "pattern coordinates" ``(a, b)`` in mm let a flat ridge pattern be laid on the surface:
``a`` is arc length along each meridian measured from the tip pole, ``b`` the signed arc length
around each ring measured from the pad centre line. Both are exact arc lengths on the mesh; the
map is near-isometric on the body of the finger and shears on the tip cap.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["FingerParams", "FingerSurface", "random_finger_params", "make_finger_surface"]


@dataclass(frozen=True)
class FingerParams:
    """Shape of one synthetic finger (all lengths in mm)."""

    width: float = 16.0
    """Largest width of the cross-section (y extent), 14-20 mm in adults."""
    height_ratio: float = 0.82
    """Cross-section height (z extent) over width: fingers are wider than high."""
    pad_share: float = 0.56
    """Share of the section height on the pad side of the axis (the pad is fuller than the nail side)."""
    nail_flatness: float = 3.2
    """Super-ellipse exponent of the nail half (2 = ellipse, larger = flatter, boxier)."""
    pad_exponent: float = 2.0
    """Super-ellipse exponent of the pad half: 2 is a half ellipse, the ``prior`` pointmap's own section; larger
    makes a flatter pad with fuller sides, smaller a more pointed one (drawn only by the ``wide`` shapes)."""
    length: float = 44.0
    """Modelled length from the tip pole back toward the hand (beyond the distal crease)."""
    cap: float = 9.0
    """Length of the rounded tip cap."""
    taper: float = 0.10
    """Relative width lost from the base to the start of the cap."""
    bend: float = 0.8
    """Palmward sag of the axis over the modelled length (mm)."""
    crease: float = 26.0
    """Distance of the distal interphalangeal crease from the tip, along the pad: where ridges end."""
    pad_bulge: float = 0.0
    """Extra fullness of the pad behind the tip (relative, peaking one cap length from the pole):
    real fingertips are bulbous there, wider and deeper on the pad side than the body behind."""
    tip_x: float = 12.0
    """World x of the tip pole."""


SHAPES = ("adult", "wide")
"""Families :func:`random_finger_params` draws from."""


def random_finger_params(rng: np.random.Generator, shapes: str = "adult") -> FingerParams:
    """Random adult finger, drawn wide across human ranges (thumbs to little fingers, slim to
    bulbous): the reconstruction must not depend on one shape.

    ``shapes="wide"`` draws the same and then, from the same stream, a pad that is not the half ellipse the ``prior``
    pointmap assumes (super-ellipse exponent 1.6-3.5), sections 0.55-1.05 as high as wide, bends up to 6 mm, a taper
    from -0.25 (widening toward the tip) to 0.35 and a fuller pad bulge: what another generator's or another
    group's fingers may be, measured by ``tools/bench_fuse.py --cases uwa3-wide``."""
    if shapes not in SHAPES:
        raise ValueError(f"unknown finger shapes {shapes!r}; choose one of {', '.join(SHAPES)}")
    params = _adult_params(rng)
    if shapes == "wide":
        params = replace(params, pad_exponent=rng.uniform(1.6, 3.5), height_ratio=rng.uniform(0.55, 1.05),
                         bend=rng.uniform(0.0, 6.0), taper=rng.uniform(-0.25, 0.35), pad_bulge=rng.uniform(0.0, 0.35))
    return params


def _adult_params(rng: np.random.Generator) -> FingerParams:
    width = rng.uniform(13.0, 22.0)
    return FingerParams(
        width=width,
        height_ratio=rng.uniform(0.68, 0.95),
        pad_share=rng.uniform(0.5, 0.66),
        nail_flatness=rng.uniform(2.0, 4.5),
        cap=width * rng.uniform(0.42, 0.7),
        taper=rng.uniform(0.0, 0.2),
        bend=rng.uniform(0.0, 2.5),
        crease=width * rng.uniform(1.4, 1.8),
        pad_bulge=rng.uniform(0.0, 0.18),
    )


@dataclass(frozen=True, eq=False)
class FingerSurface:
    """The sampled finger: a closed triangle mesh plus per-vertex skin coordinates."""

    params: FingerParams
    grid: np.ndarray  # [R, C, 3] surface points, row 0 = base ring, last row = ring next to the pole
    pole: np.ndarray  # [3] tip pole
    vertices: np.ndarray  # [V, 3]: grid rows flattened, then the tip pole, then the base centre
    triangles: np.ndarray  # [T, 3] int32, counter-clockwise seen from outside
    normals: np.ndarray  # [V, 3] outward unit vertex normals
    pattern_ab: np.ndarray  # [V, 2] skin coordinates (a, b) in mm; NaN on the base cap
    tangent_a: np.ndarray  # [V, 3] unit d(point)/da (toward the base)
    tangent_b: np.ndarray  # [V, 3] unit d(point)/db

    @property
    def rows(self) -> int:
        return self.grid.shape[0]

    @property
    def cols(self) -> int:
        return self.grid.shape[1]

    def surface_at(self, a: np.ndarray, b: np.ndarray, iterations: int = 8) -> np.ndarray:
        """Surface points ``[N, 3]`` at skin coordinates ``(a, b)`` (mm), by inverting the grid map.

        Newton iterations on the bilinear interpolation of the grid's (a, b) in continuous
        (row, column) index space, started from the nearest vertex. Coordinates outside the skin
        return NaN.
        """
        a = np.atleast_1d(np.asarray(a, np.float64))
        b = np.atleast_1d(np.asarray(b, np.float64))
        rows, cols = self.rows, self.cols
        ab_grid = self.pattern_ab[: rows * cols].reshape(rows, cols, 2)
        tree = cKDTree(ab_grid.reshape(-1, 2))
        _, nearest = tree.query(np.stack([a, b], axis=1))
        index = np.stack([nearest // cols, nearest % cols], axis=1).astype(np.float64)
        target = np.stack([a, b], axis=1)
        for _ in range(iterations):
            value, jac = _bilinear_with_jacobian(ab_grid, index)
            det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
            det = np.where(np.abs(det) < 1e-12, 1e-12, det)
            residual = target - value
            step_r = (jac[:, 1, 1] * residual[:, 0] - jac[:, 0, 1] * residual[:, 1]) / det
            step_c = (-jac[:, 1, 0] * residual[:, 0] + jac[:, 0, 0] * residual[:, 1]) / det
            index[:, 0] = np.clip(index[:, 0] + np.clip(step_r, -3, 3), 0, rows - 1)
            index[:, 1] = index[:, 1] + np.clip(step_c, -3, 3)
        value, _ = _bilinear_with_jacobian(ab_grid, index)
        points, _ = _bilinear_with_jacobian(self.grid, index)
        bad = np.linalg.norm(value - target, axis=1) > 1e-3
        points[bad] = np.nan
        return points

    def to_open3d(self):
        """The surface as an ``open3d.geometry.TriangleMesh`` (imported lazily)."""
        import open3d as o3d

        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(self.vertices),
                                         o3d.utility.Vector3iVector(self.triangles))
        mesh.vertex_normals = o3d.utility.Vector3dVector(self.normals)
        return mesh


def _bilinear_with_jacobian(grid: np.ndarray, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear value ``[N, D]`` and Jacobian ``[N, D, 2]`` of ``grid [R, C, D]`` at float (row, col).

    Columns wrap around (azimuth is periodic); rows are clamped. Written here rather than with
    ``scipy.ndimage.map_coordinates`` (:mod:`fingersplat3d.sampling`): the surface's normals need
    the Jacobian, which the library samplers do not give.
    """
    rows, cols = grid.shape[:2]
    r = np.clip(index[:, 0], 0, rows - 1 - 1e-9)
    r0 = np.floor(r).astype(int)
    r1 = np.minimum(r0 + 1, rows - 1)
    fr = (r - r0)[:, None]
    c = index[:, 1]
    c0f = np.floor(c)
    fc = (c - c0f)[:, None]
    c0 = c0f.astype(int) % cols
    c1 = (c0 + 1) % cols
    g00, g01, g10, g11 = grid[r0, c0], grid[r0, c1], grid[r1, c0], grid[r1, c1]
    value = (1 - fr) * ((1 - fc) * g00 + fc * g01) + fr * ((1 - fc) * g10 + fc * g11)
    d_row = (1 - fc) * (g10 - g00) + fc * (g11 - g01)
    d_col = (1 - fr) * (g01 - g00) + fr * (g11 - g10)
    return value, np.stack([d_row, d_col], axis=-1)


def _section(phi: np.ndarray, params: FingerParams) -> np.ndarray:
    """Unit-width cross-section ``[..., 2]`` (y, z) at azimuth ``phi`` (0 = pad centre, -z)."""
    sin, cos = np.sin(phi), np.cos(phi)
    half_height = params.height_ratio
    y = 0.5 * np.sign(sin) * np.abs(sin) ** np.where(cos >= 0, 2.0 / params.pad_exponent, 2.0 / params.nail_flatness)
    pad = -half_height * params.pad_share * np.sign(cos) * np.abs(cos) ** (2.0 / params.pad_exponent)
    nail = half_height * (1 - params.pad_share) * np.abs(cos) ** (2.0 / params.nail_flatness)
    z = np.where(cos >= 0, pad, nail)
    return np.stack([y, z], axis=-1)


def make_finger_surface(params: FingerParams, body_rows: int = 180, cap_rows: int = 80,
                        cols: int = 240) -> FingerSurface:
    """Sample the finger surface, triangulate it (closed: tip pole and base disc) and add skin coordinates."""
    # Axial stations: uniform along the body, uniform in angle over the cap (denser near the pole).
    body_len = params.length - params.cap
    x_body = np.linspace(0.0, body_len, body_rows, endpoint=False)
    psi = np.linspace(0.0, np.pi / 2, cap_rows + 1)[:-1]  # exclude the pole itself
    x_cap = body_len + params.cap * np.sin(psi)
    x = np.concatenate([x_body, x_cap])
    scale = np.concatenate([np.ones_like(x_body), np.cos(psi)])  # ellipsoidal closing of the cap
    taper = 1.0 - params.taper * np.minimum(x, body_len) / body_len
    width = params.width * taper * scale
    phi = np.linspace(-np.pi, np.pi, cols, endpoint=False) + np.pi / cols
    section = _section(phi, params)  # [C, 2]
    # Axis sags palmward (-z) toward the tip; base at x = 0 in local coordinates.
    sag = -params.bend * (x / params.length) ** 2
    # The pad bulge: the pad half grows around one cap length behind the pole (a smooth bump along x).
    bump = params.pad_bulge * np.exp(-0.5 * ((x - (params.length - params.cap)) / (0.6 * params.cap)) ** 2)
    pad_side = np.clip(-section[:, 1] / max(params.height_ratio * params.pad_share, 1e-9), 0.0, 1.0)  # 1 at the pad centre
    grow = 1.0 + bump[:, None] * pad_side[None, :]
    grid = np.empty((x.size, cols, 3))
    grid[..., 0] = x[:, None]
    grid[..., 1] = width[:, None] * section[None, :, 0] * (1.0 + 0.5 * (grow - 1.0))
    grid[..., 2] = width[:, None] * section[None, :, 1] * grow + sag[:, None]
    pole = np.array([params.length, 0.0, -params.bend])  # the sag at x = length
    base_centre = np.array([0.0, 0.0, 0.0])
    offset = np.array([params.tip_x - params.length, 0.0, 0.0])
    grid += offset
    pole = pole + offset
    base_centre = base_centre + offset

    rows = x.size
    vertices = np.concatenate([grid.reshape(-1, 3), pole[None], base_centre[None]])
    pole_index, base_index = rows * cols, rows * cols + 1
    triangles = _triangulate(rows, cols, pole_index, base_index)
    normals = _vertex_normals(vertices, triangles)
    pattern_ab, tangent_a, tangent_b = _skin_coordinates(grid, pole)
    nan_row = np.full((1, 2), np.nan)
    zero = np.zeros((2, 3))
    pattern = np.concatenate([pattern_ab.reshape(-1, 2), np.zeros((1, 2)), nan_row])
    tangent_a = np.concatenate([tangent_a.reshape(-1, 3), zero])
    tangent_b = np.concatenate([tangent_b.reshape(-1, 3), zero])
    return FingerSurface(params, grid, pole, vertices, triangles, normals, pattern, tangent_a, tangent_b)


def _triangulate(rows: int, cols: int, pole: int, base: int) -> np.ndarray:
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols), indexing="ij")
    v00 = r * cols + c
    v01 = r * cols + (c + 1) % cols
    v10 = (r + 1) * cols + c
    v11 = (r + 1) * cols + (c + 1) % cols
    # With x toward the tip and phi increasing from -z through +y, (v00, v01, v10) faces outward.
    quads = np.concatenate([np.stack([v00, v01, v10], -1).reshape(-1, 3),
                            np.stack([v01, v11, v10], -1).reshape(-1, 3)])
    last = (rows - 1) * cols + np.arange(cols)
    tip = np.stack([last, (last - (rows - 1) * cols + 1) % cols + (rows - 1) * cols, np.full(cols, pole)], -1)
    first = np.arange(cols)
    base_fan = np.stack([np.full(cols, base), (first + 1) % cols, first], -1)
    return np.concatenate([quads, tip, base_fan]).astype(np.int32)


def _vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    v0, v1, v2 = (vertices[triangles[:, k]] for k in range(3))
    face = np.cross(v1 - v0, v2 - v0)  # area-weighted
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.maximum(length, 1e-12)


def _skin_coordinates(grid: np.ndarray, pole: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arc-length coordinates (a from the pole along meridians, b around rings from phi = 0)."""
    rows, cols = grid.shape[:2]
    # a: cumulative meridian length from the pole back toward the base.
    steps = np.linalg.norm(np.diff(grid, axis=0), axis=-1)  # [R-1, C]
    to_pole = np.linalg.norm(grid[-1] - pole, axis=-1)  # [C]
    a = np.empty((rows, cols))
    a[-1] = to_pole
    a[:-1] = to_pole + np.cumsum(steps[::-1], axis=0)[::-1]
    # b: ring arc length from the pad centre line, which lies between columns cols/2-1 and cols/2.
    ring_steps = np.linalg.norm(np.roll(grid, -1, axis=1) - grid, axis=-1)  # [R, C] from j to j+1
    centre = cols // 2
    cumulative = np.cumsum(ring_steps, axis=1)
    cumulative = np.concatenate([np.zeros((rows, 1)), cumulative[:, :-1]], axis=1)  # length from column 0
    b = cumulative - (cumulative[:, centre - 1:centre] + 0.5 * ring_steps[:, centre - 1:centre])
    half = 0.5 * cumulative[:, -1:] + 0.5 * ring_steps[:, -1:]
    b = np.where(b > half, b - 2 * half, b)  # wrap to (-half, half]
    tangent_a = np.gradient(grid, axis=0) * -1.0  # toward the base is decreasing row index
    tangent_a /= np.maximum(np.linalg.norm(tangent_a, axis=-1, keepdims=True), 1e-12)
    tangent_b = np.roll(grid, -1, axis=1) - np.roll(grid, 1, axis=1)
    tangent_b /= np.maximum(np.linalg.norm(tangent_b, axis=-1, keepdims=True), 1e-12)
    return np.stack([a, b], axis=-1), tangent_a, tangent_b
