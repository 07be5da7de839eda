"""Render a synthetic finger with Open3D ray casting: image, mask and exact depth from the same rays.

One ray per pixel centre goes through the triangle mesh of :class:`FingerSurface`. The hit gives
camera-frame depth exactly (rays are built with camera-frame z = 1, so the hit distance *is* the
depth), the mask, and barycentric coordinates with which the per-vertex skin coordinates, normals
and tangents are interpolated. The ridge pattern is then a texture in skin coordinates:

* albedo: skin tone with low-frequency variation; valleys darker than ridges (cavity term);
* relief: the ridge field as a height map bumps the shading normal (ridge relief shading);
* light: Lambertian with ambient, optional Blinn-Phong highlight (stronger on ridge crests), and
  glints: sparse bright specks fixed on the skin (sweat pores) that light up where their
  highlight faces the camera, so they differ between views as on real skin;
* sensor: Gaussian blur and Gaussian noise; dark background.

The defaults are matched to the real UWA captures by the statistics of
:mod:`fingersplat3d.eval.appearance` (``tools/bench_realism.py``, README): faint ridges, soft
optics, low sensor noise, glints.

The geometry is not displaced by the ridges (relief of a few hundredths of a mm), so the depth is
the exact depth of the ground-truth mesh that is written next to the images.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..scene import Camera
from .ridges import RidgePattern
from .shape import FingerSurface

__all__ = ["Appearance", "Rendering", "FingerScene", "skin_weight"]

_LUMA = np.array([0.299, 0.587, 0.114])
GLINTS_PER_MM2 = 1.0
WRINKLES = 24  # plane waves of the fine skin texture


@dataclass(frozen=True)
class Appearance:
    """How the skin and the sensor look. Intensities are in [0, 1]."""

    rgb: bool = False
    """Render three channels (skin colour) instead of one."""
    albedo: tuple[float, float, float] = (0.82, 0.60, 0.50)
    """Mean skin albedo (RGB); grayscale uses its luminance."""
    albedo_variation: float = 0.08
    """Relative amplitude of the low-frequency albedo blotches."""
    ridge_contrast: float = 0.18
    """How much darker valleys are than ridge crests (cavity / ambient-occlusion term)."""
    relief_mm: float = 0.012
    """Ridge height used to bump the shading normal (half of crest-to-valley)."""
    ambient: float = 0.3
    """Share of light that is ambient (not direction dependent)."""
    specular: float = 0.12
    """Strength of the Blinn-Phong highlight (0 for none)."""
    glints: float = 0.35
    """Strength of the glints on the skin (0 for none)."""
    wrinkles: float = 0.06
    """Relative amplitude of the fine skin texture (creases and wrinkles 0.3-1 mm across), everywhere on the
    skin, beyond the crease too, as on real fingers (0 for none)."""
    shininess: float = 24.0
    """Blinn-Phong exponent."""
    crease_depth: float = 0.35
    """Darkening of the distal interphalangeal crease (0 for none)."""
    exposure: float = 0.9
    """Global gain."""
    background: float = 0.02
    """Background intensity (dark by default)."""
    blur_px: float = 2.0
    """Gaussian blur sigma in pixels (optics) at the rig's default image size (scaled with the image); 0 for none."""
    noise: float = 0.006
    """Gaussian sensor noise sigma; 0 for none."""


@dataclass(frozen=True, eq=False)
class Rendering:
    """What one camera sees of the finger."""

    image: np.ndarray  # [H, W] or [H, W, 3] float32 in [0, 1]
    mask: np.ndarray  # [H, W] bool, finger pixels
    depth: np.ndarray  # [H, W] float32 camera-frame z in mm, NaN off the finger
    skin_ab: np.ndarray  # [H, W, 2] float32 skin coordinates (a, b) mm, NaN off the finger
    normal: np.ndarray  # [H, W, 3] float32 world-frame smooth surface normal, NaN off the finger


def skin_weight(ab: np.ndarray, pattern: RidgePattern, crease_mm: float, fade_mm: float = 1.0) -> np.ndarray:
    """Where ridges are: 1 inside the pattern area (tip to crease, +-half width), fading to 0."""
    a, b = ab[..., 0], ab[..., 1]
    half_width = (pattern.ridges.shape[1] - 1) * pattern.spacing_mm / 2
    limit_a = min(crease_mm, pattern.length_mm)
    inside_a = np.clip((limit_a - a) / fade_mm, 0.0, 1.0)
    inside_b = np.clip((half_width - np.abs(b)) / fade_mm, 0.0, 1.0)
    weight = _smoothstep(inside_a) * _smoothstep(inside_b)
    return np.where(np.isfinite(weight), weight, 0.0)


def _smoothstep(t: np.ndarray) -> np.ndarray:
    return t * t * (3.0 - 2.0 * t)


class FingerScene:
    """A finger surface with its ridge pattern, ready to be ray cast from any camera."""

    def __init__(self, surface: FingerSurface, pattern: RidgePattern, seed: int = 0) -> None:
        import open3d as o3d  # the Open3D adapter layer: imported here, not by the pure-math modules

        self.surface = surface
        self.pattern = pattern
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(surface.vertices.astype(np.float32))
        mesh.triangle.indices = o3d.core.Tensor(surface.triangles.astype(np.int32))
        self._raycaster = o3d.t.geometry.RaycastingScene()
        self._raycaster.add_triangles(mesh)
        self._o3d = o3d
        self._weight = skin_weight(surface.pattern_ab, pattern, surface.params.crease)
        grad_a, grad_b = np.gradient(pattern.ridges.astype(np.float64), pattern.spacing_mm)
        self._grad_a, self._grad_b = grad_a.astype(np.float32), grad_b.astype(np.float32)
        blotch_rng = np.random.default_rng(seed)
        self._blotch_k = blotch_rng.normal(size=(6, 3)) * (2 * np.pi / blotch_rng.uniform(3.0, 12.0, size=(6, 1)))
        self._blotch_phase = blotch_rng.uniform(0, 2 * np.pi, size=6)
        self._blotch_tint = blotch_rng.normal(0.0, 0.35, size=(6, 3))
        # Glints: specks at random places of the skin (GLINTS_PER_MM2), ~2 grid cells across.
        cells = pattern.ridges.shape
        count = int(GLINTS_PER_MM2 * cells[0] * cells[1] * pattern.spacing_mm ** 2)
        specks = np.zeros(cells, np.float32)
        specks[blotch_rng.integers(0, cells[0], count), blotch_rng.integers(0, cells[1], count)] = blotch_rng.uniform(0.5, 1.0, count)
        self._glints = cv2.GaussianBlur(specks, (0, 0), 0.8) * 8.0
        directions = blotch_rng.normal(size=(WRINKLES, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        self._wrinkle_k = directions * (2 * np.pi / blotch_rng.uniform(0.3, 1.0, size=(WRINKLES, 1)))
        self._wrinkle_phase = blotch_rng.uniform(0, 2 * np.pi, size=WRINKLES)

    def cast(self, camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Depth ``[H, W]`` (NaN = miss), triangle ids ``[H, W]`` and barycentrics ``[H, W, 2]``."""
        directions = camera.pixel_directions(camera.pixel_grid()) @ camera.rotation  # world, cam z = 1
        origins = np.broadcast_to(camera.center, directions.shape)
        rays = np.concatenate([origins, directions], axis=-1).astype(np.float32)
        hit = self._raycaster.cast_rays(self._o3d.core.Tensor(rays.reshape(-1, 6)), nthreads=0)
        t_hit = hit["t_hit"].numpy().reshape(camera.height, camera.width)
        ids = hit["primitive_ids"].numpy().reshape(camera.height, camera.width).astype(np.int64)
        uvs = hit["primitive_uvs"].numpy().reshape(camera.height, camera.width, 2)
        depth = np.where(np.isfinite(t_hit), t_hit, np.nan).astype(np.float32)
        return depth, ids, uvs

    def render(self, camera: Camera, light_world: np.ndarray, appearance: Appearance,
               rng: np.random.Generator) -> Rendering:
        """Render one view; ``light_world`` points from the finger toward the light."""
        depth, ids, uvs = self.cast(camera)
        mask = np.isfinite(depth)
        surface = self.surface
        tri = surface.triangles[ids[mask]]  # [N, 3]
        bary = np.stack([1.0 - uvs[mask].sum(-1), uvs[mask][:, 0], uvs[mask][:, 1]], axis=-1)[..., None]

        def interp(values: np.ndarray) -> np.ndarray:
            return (values[tri] * bary).sum(axis=1)

        points = camera.unproject(np.argwhere(mask)[:, ::-1].astype(np.float64), depth[mask])
        normal = _normalize(interp(surface.normals))
        ab = interp(np.nan_to_num(surface.pattern_ab))
        weight = interp(self._weight[:, None])[:, 0]
        height = self.pattern.sample(ab[:, 0], ab[:, 1]) * weight
        slope = (self.pattern.sample(ab[:, 0], ab[:, 1], self._grad_a)[:, None] * interp(surface.tangent_a)
                 + self.pattern.sample(ab[:, 0], ab[:, 1], self._grad_b)[:, None] * interp(surface.tangent_b)) * weight[:, None]
        bumped = _normalize(normal - appearance.relief_mm * slope)

        light = _normalize(np.asarray(light_world, np.float64)[None])
        to_camera = _normalize(camera.center[None] - points)
        diffuse = np.clip((bumped * light).sum(-1), 0.0, None)
        half = _normalize(light + to_camera)
        highlight = np.clip((bumped * half).sum(-1), 0.0, None) ** appearance.shininess
        cavity = 1.0 - appearance.ridge_contrast * 0.5 * (1.0 - height)
        blotch = np.sin(points @ self._blotch_k.T + self._blotch_phase)  # [N, 6]
        albedo = np.asarray(appearance.albedo)[None] * (1.0 + appearance.albedo_variation * (blotch @ (1 + self._blotch_tint)) / 3)
        wrinkle = np.cos(points @ self._wrinkle_k.T + self._wrinkle_phase).sum(-1) / np.sqrt(WRINKLES / 2)
        albedo = albedo * (1.0 + appearance.wrinkles * np.tanh(wrinkle))[:, None]
        crease = 1.0 - appearance.crease_depth * np.exp(-(((ab[:, 0] - surface.params.crease) / 0.35) ** 2))
        shade = (appearance.ambient + (1 - appearance.ambient) * diffuse) * cavity * crease
        crest = 0.5 + 0.25 * (height + 1.0)
        glint = self.pattern.sample(ab[:, 0], ab[:, 1], self._glints) * weight * np.clip((bumped * half).sum(-1), 0.0, None) ** 6
        color = appearance.exposure * (albedo * shade[:, None] + appearance.specular * (highlight * crest)[:, None]
                                       + appearance.glints * glint[:, None])
        if not appearance.rgb:
            color = color @ _LUMA[:, None]
        channels = color.shape[1]
        image = np.full((camera.height, camera.width, channels), appearance.background, np.float32)
        image[mask] = color
        if appearance.blur_px > 0:
            image = cv2.GaussianBlur(image, (0, 0), appearance.blur_px).reshape(image.shape)
        if appearance.noise > 0:
            image = image + rng.normal(0.0, appearance.noise, image.shape).astype(np.float32)
        image = np.clip(image, 0.0, 1.0)
        skin_ab = np.full((camera.height, camera.width, 2), np.nan, np.float32)
        skin_ab[mask] = np.where(weight[:, None] > 0, ab, np.nan)
        normals = np.full((camera.height, camera.width, 3), np.nan, np.float32)
        normals[mask] = normal
        return Rendering(image[..., 0] if channels == 1 else image, mask, depth, skin_ab, normals)


def _normalize(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.maximum(np.linalg.norm(vectors, axis=-1, keepdims=True), 1e-12)
