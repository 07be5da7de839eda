"""Fingers of another make: a photographed skin texture wrapped on a finger shaped apart from ``fs3d synth``'s.

The project is scored on synthetic fingers from generators it never saw; its own generator draws its ridges, its
shading and its shape from one code. This maker shares none of that with it:

* **skin**: a contactless photo's texture (another group's, e.g. IMPOSE's ``sample2_texture.png``, read at run time)
  with its own ridges, pores, crease, contrast and baked-in shading, wrapped round the pad as the frontal photo of a
  round finger would unwrap (:func:`skin_lookup`), fading to ridgeless skin toward the nail and beyond its rows;
* **shape** (:class:`TexturedFinger`): a swept section of its own, super-ellipse pad and nail halves of separate depths,
  a tip cap that closes as an ellipsoid, a taper and a bend, with the finger rolled, pitched and shifted in the rig;
* **light**: one direction away from every camera, Lambert plus ambient, optionally on ridges of their own relief
  (bumps drawn from the texture's ridges, so a ridge's look moves with the view) with a Blinn-Phong highlight; a lens
  blur and sensor noise, 8-bit.

Three cameras on a ring round the finger (-45 / 0 / +45 degrees by default) at the real rig's framing: 54 mm away,
41.6 mm across the long side. Each view holds its true camera, depth and mask, as ``fs3d synth``'s do, so
:func:`~fingersplat3d.experiments.geometry.score_geometry` scores a fuse of its images alone. Ray-cast with Open3D.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy import ndimage

__all__ = ["TexturedFinger", "SkinTexture", "random_finger", "skin_texture", "skin_lookup", "textured_capture",
           "RING_DEG", "DISTANCE_MM", "FIELD_MM"]

RING_DEG = (-45.0, 0.0, 45.0)
DISTANCE_MM = 54.0  # the real UWA rig's camera-to-finger distance
FIELD_MM = 41.6  # and what its 1280 px across hold at the finger (focal 1661 px)
RIDGE_PERIOD_MM = 0.46  # an adult's ridge period: the texture is scaled to it
X_AXIS, Y_AXIS, Z_AXIS = np.eye(3)


@dataclass(frozen=True)
class TexturedFinger:
    """A finger's shape (mm), its pose in the rig and its light."""

    width: float = 16.0  # the section's widest extent
    pad_depth: float = 7.0  # from the axis to the pad's surface
    nail_depth: float = 5.5  # from the axis to the nail side
    pad_exponent: float = 2.3  # super-ellipse exponents: 2 an ellipse, larger boxier
    nail_exponent: float = 3.0
    cap: float = 8.0  # length of the tip cap, which closes as an ellipsoid
    taper: float = 0.08  # relative width lost over the modelled length
    bend: float = 0.8  # palmward sag of the axis over the modelled length
    length: float = 48.0
    roll_deg: float = 0.0  # about the finger's axis
    pitch_deg: float = 0.0  # tip toward (+) or away from the cameras
    yaw_deg: float = 0.0  # in the plane of the front image
    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    light: tuple[float, float, float] = (-0.3, -0.5, -0.8)  # toward the light, world
    ambient: float = 0.35
    exposure: float = 1.0
    relief_mm: float = 0.0  # ridge height: the skin's shading then changes with the light and the view across a ridge
    specular: float = 0.0  # a Blinn-Phong highlight's strength (0: Lambert alone)


def random_finger(rng: np.random.Generator) -> TexturedFinger:
    """A finger drawn wide across adult shapes and poses (ranges apart from ``fs3d synth``'s draws)."""
    width = rng.uniform(14.0, 19.0)
    light = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.8, -0.2), -1.0])
    return TexturedFinger(
        width=width, pad_depth=width * rng.uniform(0.36, 0.5), nail_depth=width * rng.uniform(0.28, 0.38),
        pad_exponent=rng.uniform(1.8, 2.8), nail_exponent=rng.uniform(2.5, 4.0), cap=rng.uniform(6.0, 10.0),
        taper=rng.uniform(0.0, 0.15), bend=rng.uniform(0.0, 1.6), roll_deg=rng.uniform(-10, 10),
        pitch_deg=rng.uniform(-5, 5), yaw_deg=rng.uniform(-5, 5),
        offset_mm=tuple(rng.uniform(-2.0, 2.0, 3)), light=tuple(light / np.linalg.norm(light)),
        ambient=rng.uniform(0.25, 0.45), exposure=rng.uniform(0.85, 1.15))


@dataclass(frozen=True, eq=False)
class SkinTexture:
    """A photographed finger's texture, ready to wrap: the gray image, its finger's centre column and half width per
    row, its first and last rows, and its pixels per mm at :data:`RIDGE_PERIOD_MM`."""

    image: np.ndarray  # [H, W] float32
    centre: np.ndarray  # [H] column of the finger's middle, NaN off it
    half_width: np.ndarray  # [H]
    first_row: int
    last_row: int
    px_per_mm: float
    mean: float  # the skin's mean grey level
    ridges: np.ndarray  # [H, W] the ridge texture band-passed, unit RMS on the finger (crests positive)


def skin_texture(path: str | Path) -> SkinTexture:
    """A texture photo (a finger on black, tip up), measured: where its finger is on each row and its ridge period."""
    from ..align.correspond.texture import estimate_ridge_period, ridge_texture
    from ..io.images import read_image

    image = read_image(path, gray=True)
    finger = ndimage.binary_fill_holes(image > 0.03)
    finger = ndimage.binary_opening(finger, iterations=3)
    inner = ndimage.binary_erosion(finger, iterations=6)
    rows = np.flatnonzero(inner.sum(1) > 0.2 * inner.shape[1])
    if rows.size < 50:
        raise ValueError(f"{path}: no finger texture found")
    centre, half = np.full(image.shape[0], np.nan), np.full(image.shape[0], np.nan)
    for row in rows:
        cols = np.flatnonzero(inner[row])
        centre[row], half[row] = (cols[0] + cols[-1]) / 2.0, (cols[-1] - cols[0]) / 2.0
    period = estimate_ridge_period(image, inner)
    ridges = ridge_texture(image, inner, period)
    return SkinTexture(image, centre, half, int(rows[0]), int(rows[-1]), period / RIDGE_PERIOD_MM,
                       float(np.mean(image[inner])), ridges.astype(np.float32))


def skin_lookup(texture: SkinTexture, along_mm: np.ndarray, around_mm: np.ndarray,
                relief_mm: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The skin's grey level at arc lengths ``along_mm`` from the tip's pole and ``around_mm`` from the pad's middle:
    the texture read as the frontal photo of a round finger (``x = centre + half sin(s / half)``, its own radius),
    fading to its mean grey where that photo grazes the skin (beyond ~63 degrees of it) and off its rows; and ``[N, 2]``
    the slopes (along, around) of ridges ``relief_mm`` high drawn from its band-passed ridges, faded alike."""
    row = texture.first_row + (along_mm - 2.0) * texture.px_per_mm  # its top row 2 mm behind the pole
    clipped = np.clip(np.rint(row), texture.first_row, texture.last_row).astype(int)
    half = texture.half_width[clipped]
    angle = around_mm * texture.px_per_mm / half
    bounded = np.clip(angle, -1.35, 1.35)
    col = texture.centre[clipped] + half * np.sin(bounded)
    weight = np.clip((1.35 - np.abs(angle)) / 0.25, 0.0, 1.0)
    weight *= np.clip(np.minimum(row - texture.first_row, texture.last_row - row) / (1.5 * texture.px_per_mm), 0, 1)
    at = [np.clip(row, 0, texture.image.shape[0] - 1), col]
    value = ndimage.map_coordinates(texture.image, at, order=1, mode="nearest")
    slopes = np.zeros((len(value), 2))
    if relief_mm > 0:
        d_row, d_col = np.gradient(texture.ridges)
        # Crests 0.5 relief above the mean, valleys below it: height per texture pixel, then per mm of skin.
        slopes[:, 0] = ndimage.map_coordinates(d_row, at, order=1, mode="nearest") * texture.px_per_mm
        slopes[:, 1] = ndimage.map_coordinates(d_col, at, order=1, mode="nearest") * texture.px_per_mm * np.cos(bounded)
        slopes *= (0.5 * relief_mm / np.sqrt(2.0)) * weight[:, None]
    return texture.mean + weight * (value - texture.mean), slopes


def _surface(finger: TexturedFinger, stations: int = 260, around: int = 360):
    """The finger's mesh in its own frame (x from the tip's pole toward the hand, pad toward -z): vertices, triangles,
    per vertex the arc lengths along the pad from the pole and round the section from the pad's middle, and the unit
    tangents along and round."""
    t = np.linspace(0.0, 1.0, stations) ** 1.6  # denser near the tip
    d = t * finger.length
    closing = np.sqrt(np.clip(1.0 - (1.0 - np.minimum(d / finger.cap, 1.0)) ** 2, 0.0, 1.0))
    scale = closing * (1.0 - finger.taper * d / finger.length)
    psi = np.linspace(-np.pi, np.pi, around, endpoint=False)
    s, c = np.sin(psi), np.cos(psi)
    y = 0.5 * finger.width * np.sign(s) * np.abs(s) ** (2.0 / np.where(c >= 0, finger.pad_exponent, finger.nail_exponent))
    z = np.where(c >= 0, -finger.pad_depth * np.abs(c) ** (2.0 / finger.pad_exponent),
                 finger.nail_depth * np.abs(c) ** (2.0 / finger.nail_exponent))
    sag = -finger.bend * (d / finger.length) ** 2
    vertices = np.stack([np.repeat(d, around), (scale[:, None] * y).ravel(), (scale[:, None] * z + sag[:, None]).ravel()], 1)
    # Arc lengths: round each ring from the pad's middle, along the pad line from the pole.
    ring = vertices.reshape(stations, around, 3)
    steps = np.linalg.norm(np.diff(np.concatenate([ring, ring[:, :1]], 1), axis=1), axis=-1)
    middle = around // 2  # psi = 0: the pad's middle
    forward = np.cumsum(steps[:, middle:], 1)
    backward = np.cumsum(steps[:, :middle][:, ::-1], 1)
    around_mm = np.zeros((stations, around))
    around_mm[:, middle + 1:] = forward[:, :-1]
    around_mm[:, :middle] = -backward[:, ::-1]
    pad_line = ring[:, middle]
    along_mm = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pad_line, axis=0), axis=1))])
    along = np.repeat(along_mm[:, None], around, 1)
    triangles = []
    for k in range(stations - 1):
        a, b = k * around + np.arange(around), k * around + (np.arange(around) + 1) % around
        triangles.append(np.stack([a, a + around, b], 1))
        triangles.append(np.stack([b, a + around, b + around], 1))
    tangent_along = np.gradient(ring, axis=0)
    tangent_around = np.roll(ring, -1, axis=1) - np.roll(ring, 1, axis=1)
    tangents = [t.reshape(-1, 3) / np.maximum(np.linalg.norm(t.reshape(-1, 3), axis=1, keepdims=True), 1e-12)
                for t in (tangent_along, tangent_around)]
    return vertices, np.concatenate(triangles), along.ravel(), around_mm.ravel(), tangents


def _blotches(along_mm: np.ndarray, around_mm: np.ndarray, seed: int, strength: float = 0.05) -> np.ndarray:
    """A smooth tone on the skin, fixed to it (periods of 1.5-8 mm, about ``strength`` of the grey): skin is never
    one flat grey, behind the crease either."""
    rng = np.random.default_rng(seed + 7919)
    tone = np.zeros_like(along_mm)
    for _ in range(8):
        period, direction, phase = rng.uniform(1.5, 8.0), rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi)
        tone += np.sin(2 * np.pi * (np.cos(direction) * along_mm + np.sin(direction) * around_mm) / period + phase)
    return 1.0 + strength * tone / np.sqrt(4.0)


def textured_capture(finger: TexturedFinger, texture: SkinTexture, *, size: tuple[int, int] = (1280, 1024),
                     ring_deg=RING_DEG, distance_mm: float = DISTANCE_MM, field_mm: float = FIELD_MM,
                     noise: float = 0.01, seed: int = 0, along_deg=None, zooms=None):
    """A :class:`~fingersplat3d.scene.Capture` of ``finger`` by cameras on a ring round it: each view its 8-bit image,
    true mask, camera and depth (mm). The finger lies along the image rows, tip left, its base out of the frame.
    ``along_deg``: per camera, how far it is also turned along the finger (about the axis across it), so that the
    cameras' optical axes leave one plane, as a rig's cameras mounted at slightly different places do. ``zooms``: per
    camera, its focal over the others' (lenses set alike only nearly)."""
    import open3d as o3d

    from ..scene import Camera, Capture, View, look_at
    from ..synth.rigs import rotation_about

    rng = np.random.default_rng(seed)
    # long enough to leave the frame whatever the framing (a hand behind it, not a stub's cut end)
    finger = replace(finger, length=max(finger.length, 1.2 * field_mm))
    vertices, triangles, along, around, tangents = _surface(finger)
    # The finger in the world: the tip pole 0.35 of the field left of the front image's centre, axis along world x,
    # pad toward -z (the cameras).
    pose = rotation_about(X_AXIS, finger.roll_deg) @ rotation_about(Y_AXIS, finger.pitch_deg) \
        @ rotation_about(Z_AXIS, finger.yaw_deg)
    tip = np.array([-0.35 * field_mm, 0.0, 0.0]) + np.asarray(finger.offset_mm)
    world = vertices @ pose.T + tip
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(world), o3d.utility.Vector3iVector(triangles))
    mesh.compute_vertex_normals()
    normals = np.asarray(mesh.vertex_normals)
    tangents = [t @ pose.T for t in tangents]
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    width, height = size
    focal = width / field_mm * distance_mm
    light = np.asarray(finger.light, np.float64) / np.linalg.norm(finger.light)
    views = []
    along_deg = np.zeros(len(ring_deg)) if along_deg is None else np.asarray(along_deg, np.float64)
    for k, angle in enumerate(ring_deg):
        turn = rotation_about(X_AXIS, angle) @ rotation_about(Y_AXIS, along_deg[k])
        eye = turn @ np.array([0.0, 0.0, -distance_mm])
        zoom = 1.0 if zooms is None else float(zooms[k])
        camera = Camera.from_focal(focal * zoom, width, height,
                                   look_at(eye, np.zeros(3), turn @ np.array([0.0, -1.0, 0.0])))
        directions = camera.pixel_directions(camera.pixel_grid()) @ camera.rotation
        rays = np.concatenate([np.broadcast_to(camera.center, directions.shape), directions], -1).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor(rays.reshape(-1, 6)), nthreads=0)
        depth = hit["t_hit"].numpy().reshape(height, width).astype(np.float64)
        mask = np.isfinite(depth)
        ids = hit["primitive_ids"].numpy().reshape(-1)[mask.ravel()].astype(np.int64)
        uv = hit["primitive_uvs"].numpy().reshape(-1, 2)[mask.ravel()].astype(np.float64)
        corners = triangles[ids]
        weights = np.stack([1.0 - uv.sum(1), uv[:, 0], uv[:, 1]], 1)

        def interpolate(values):
            return (values[corners] * (weights if values.ndim == 1 else weights[..., None])).sum(1)

        a_mm, b_mm = interpolate(along), interpolate(around)
        grey, slopes = skin_lookup(texture, a_mm, b_mm, finger.relief_mm)
        grey = grey * _blotches(a_mm, b_mm, seed)
        normal = interpolate(normals) - slopes[:, :1] * interpolate(tangents[0]) - slopes[:, 1:] * interpolate(tangents[1])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        shade = finger.ambient + (1.0 - finger.ambient) * np.clip(normal @ light, 0.0, None)
        if finger.specular > 0:
            points = camera.depth_to_points(np.where(mask, depth, np.nan))[mask]
            toward = camera.center - points
            halfway = light + toward / np.linalg.norm(toward, axis=1, keepdims=True)
            halfway /= np.linalg.norm(halfway, axis=1, keepdims=True)
            shade = shade + finger.specular * np.clip((normal * halfway).sum(1), 0.0, None) ** 20 / np.maximum(grey, 0.05)
        image = np.full((height, width), 0.04)
        image[mask] = finger.exposure * grey * shade / (finger.ambient + (1.0 - finger.ambient) * 0.8)
        image = ndimage.gaussian_filter(image, 0.7) + rng.normal(0.0, noise, image.shape)
        image = np.round(np.clip(image, 0.0, 1.0) * 255.0) / 255.0
        views.append(View(f"v{k}", image.astype(np.float32), mask, camera,
                          np.where(mask, depth, np.nan).astype(np.float32)))
    return Capture(tuple(views), {"seed": seed, "generator": "textured_finger", "ring_deg": list(ring_deg)})
