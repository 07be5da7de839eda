"""One synthetic finger capture: shape + ridge pattern + rig + rendering + ground-truth minutiae."""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..scene import Capture, View
from .render import Appearance, FingerScene, Rendering, skin_weight
from .ridges import BIFURCATION, PATTERN_CLASSES, RidgePattern, make_ridge_pattern
from .rolled import ROLLED_PRINT_FILE, RolledPrint, true_rolled_print
from .rigs import CAMERA_DISTANCE_MM, DEFAULT_SIZES, RIGS, RigView, cfpose_rig, ring_rig, uwa_rig
from .shape import SHAPES, FingerSurface, make_finger_surface, random_finger_params

__all__ = ["SynthConfig", "SynthResult", "synthesize", "minutiae_ground_truth"]

ANGLE_CONVENTION = ("direction points away from the stem: for a ridge ending from the ridge body out "
                    "through the free end, for a bifurcation from the stem into the fork; image angles "
                    "are atan2(dv, du) in degrees, pixel axes u right, v down")


@dataclass(frozen=True)
class SynthConfig:
    """What to generate. ``None`` fields take the rig's defaults."""

    rig: str = "uwa"
    """``uwa`` (3 cameras at -45/0/+45), ``cfpose`` (1 camera, finger rolled/pitched) or ``ring``."""
    size: tuple[int, int] | None = None
    """Image (width, height); uwa/ring 1280x1024, cfpose 1024x1280."""
    focal: float | None = None
    """Focal length in pixels at ``size``; default frames ~36 mm of finger across the long side."""
    distance_mm: float = CAMERA_DISTANCE_MM
    """Camera to finger axis (mm); the default focal keeps the framing, so a short distance is a wide-angle
    close-up (strong perspective, like a phone) and a long one nearly orthographic."""
    angles: tuple[float, ...] | None = None
    """Ring angles in degrees around the finger axis (ring rig; 0 faces the pad)."""
    poses: int = 10
    """Number of shots of the cfpose rig."""
    pattern: str = "random"
    """``arch``, ``loop``, ``whorl`` or ``random`` (drawn 10/60/30 like real frequencies)."""
    period_mm: tuple[float, float] = (0.40, 0.50)
    """Range the ridge period is drawn from."""
    appearance: Appearance = field(default_factory=Appearance)
    """Skin and sensor; ``rgb`` is forced on for cfpose unless ``gray`` is set."""
    gray: bool | None = None
    """Force grayscale (True) or RGB (False); default: uwa/ring gray, cfpose RGB."""
    finger_pose: bool = True
    """uwa rig: lay the finger in the rig as a hand does (random roll, pitch, yaw and shift), not on its axis."""
    shapes: str = "adult"
    """Finger shapes drawn: ``adult`` (human ranges, the pad a half ellipse) or ``wide`` (beyond them, the pad's
    section not the ``prior`` pointmap's own: :func:`~fingersplat3d.synth.shape.random_finger_params`)."""
    mesh_detail: float = 1.0
    """Scale of the surface grid (1.0: 180+80 rows x 240 columns, ~62k vertices). The depth maps are
    exact for whatever mesh is used, and that mesh is the one exported; smaller ships smaller files."""


@dataclass(frozen=True, eq=False)
class SynthResult:
    capture: Capture
    minutiae: dict
    surface: FingerSurface
    pattern: RidgePattern
    renderings: dict[str, Rendering]
    seconds: dict[str, float]
    rolled: RolledPrint
    """The finger's true rolled print (:mod:`~fingersplat3d.synth.rolled`); ``minutiae['rolled_print']`` describes it."""


def _validate(config: SynthConfig) -> None:
    if config.rig not in RIGS:
        raise InputError(f"unknown rig {config.rig!r}; choose one of {', '.join(RIGS)}")
    if config.shapes not in SHAPES:
        raise InputError(f"unknown finger shapes {config.shapes!r}; choose one of {', '.join(SHAPES)}")
    if config.pattern != "random" and config.pattern not in PATTERN_CLASSES:
        raise InputError(f"unknown pattern {config.pattern!r}; choose random or one of {', '.join(PATTERN_CLASSES)}")
    if config.size is not None and (len(config.size) != 2 or min(config.size) < 8 or max(config.size) > 16384):
        raise InputError(f"image size must be two numbers between 8 and 16384, got {config.size}")
    if config.focal is not None and not (np.isfinite(config.focal) and config.focal > 0):
        raise InputError(f"focal length must be a positive number of pixels, got {config.focal}")
    if not (np.isfinite(config.distance_mm) and 30.0 <= config.distance_mm <= 2000.0):
        raise InputError(f"camera distance must lie within 30..2000 mm, got {config.distance_mm}")
    if config.rig == "ring" and not config.angles:
        raise InputError("the ring rig needs camera angles, e.g. --angles=-30,0,30")
    if config.rig == "cfpose" and not 1 <= config.poses <= 100:
        raise InputError(f"cfpose poses must be between 1 and 100, got {config.poses}")
    if not 0.1 <= config.mesh_detail <= 4.0:
        raise InputError(f"mesh detail must lie within 0.1..4, got {config.mesh_detail}")
    low, high = config.period_mm
    if not 0.2 <= low <= high <= 1.0:
        raise InputError(f"ridge period range must lie within 0.2..1.0 mm, got {config.period_mm}")


def synthesize(seed: int, config: SynthConfig = SynthConfig()) -> SynthResult:
    """Generate one finger and photograph it with the configured rig. Deterministic in ``seed``."""
    _validate(config)
    seconds: dict[str, float] = {}
    clock = time.perf_counter()
    rng = np.random.default_rng(seed)
    params = random_finger_params(rng, config.shapes)
    pattern_class = config.pattern if config.pattern != "random" else str(rng.choice(PATTERN_CLASSES, p=[0.1, 0.6, 0.3]))
    period = float(rng.uniform(*config.period_mm))
    detail = config.mesh_detail
    surface = make_finger_surface(params, max(8, round(180 * detail)), max(6, round(80 * detail)),
                                  max(16, round(240 * detail)))
    seconds["shape"] = time.perf_counter() - clock

    clock = time.perf_counter()
    half_width = float(np.floor(min(np.nanmax(np.abs(surface.pattern_ab[:, 1])) * 0.62, 16.0) / 0.05) * 0.05)
    pattern = make_ridge_pattern(np.random.default_rng(rng.integers(2**63)), params.crease + 1.0, half_width,
                                 period_mm=period, pattern_class=pattern_class, core_a_mm=None)
    seconds["ridges"] = time.perf_counter() - clock

    clock = time.perf_counter()
    size = tuple(config.size) if config.size else DEFAULT_SIZES[config.rig]
    if config.rig == "uwa":
        rig = uwa_rig(params, size, config.focal, np.random.default_rng(rng.integers(2**63)) if config.finger_pose else None,
                      distance=config.distance_mm)
    elif config.rig == "ring":
        rig = ring_rig(params, config.angles, size, config.focal, distance=config.distance_mm)
    else:
        rig = cfpose_rig(params, np.random.default_rng(rng.integers(2**63)), size, config.focal, config.poses,
                         distance=config.distance_mm)
    gray = config.gray if config.gray is not None else config.rig != "cfpose"
    # Optics and glints are set for the rig's default image size: a smaller image is blurred less (in pixels).
    zoom = size[0] / DEFAULT_SIZES[config.rig][0]
    appearance = replace(config.appearance, rgb=not gray, blur_px=config.appearance.blur_px * zoom)
    scene = FingerScene(surface, pattern, seed=int(rng.integers(2**31)))
    noise_rng = np.random.default_rng(rng.integers(2**63))
    renderings = {view.name: scene.render(view.camera, view.light_world, appearance, noise_rng) for view in rig}
    seconds["render"] = time.perf_counter() - clock

    clock = time.perf_counter()
    minutiae = minutiae_ground_truth(surface, pattern, rig, renderings)
    rolled = true_rolled_print(surface, pattern, minutiae["minutiae_3d"])
    minutiae["rolled_print"] = rolled.as_json(ROLLED_PRINT_FILE)
    seconds["minutiae"] = time.perf_counter() - clock
    views = tuple(View(view.name, renderings[view.name].image, renderings[view.name].mask, view.camera,
                       renderings[view.name].depth) for view in rig)
    metadata = {
        "generator": "fs3d synth", "seed": int(seed), "rig": config.rig, "units": "mm",
        "pattern_class": pattern_class, "ridge_period_mm": period,
        "finger_shape": asdict(params), "appearance": asdict(appearance),
        "poses": {view.name: view.pose for view in rig},
        "lights_world": {view.name: [float(x) for x in view.light_world] for view in rig},
    }
    return SynthResult(Capture(views, metadata), minutiae, surface, pattern, renderings, seconds, rolled)


def minutiae_ground_truth(surface: FingerSurface, pattern: RidgePattern, rig: list[RigView],
                          renderings: dict[str, Rendering], step_mm: float = 0.15) -> dict:
    """Ground-truth minutiae in 3D (mm) and, per view, in pixels with visibility.

    A minutia is kept when it lies well inside the ridge area (skin weight 1); it is visible in a
    view when it projects inside the image, is not occluded (the view's depth at its pixel agrees
    with its own depth) and the skin faces the camera (cosine > 0.2).
    """
    rows = pattern.minutiae
    inside = skin_weight(rows[:, :2], pattern, surface.params.crease) >= 0.999
    rows = rows[inside & (rows[:, 0] > 1.0)]
    a, b, angle = rows[:, 0], rows[:, 1], rows[:, 2]
    points = surface.surface_at(a, b)
    ahead = surface.surface_at(a + step_mm * np.cos(angle), b + step_mm * np.sin(angle))
    side_a = surface.surface_at(a + step_mm, b)
    side_b = surface.surface_at(a, b + step_mm)
    normal = np.cross(side_a - points, side_b - points)  # outward: a (toward the base) x b
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    keep = np.all(np.isfinite(points) & np.isfinite(ahead) & np.isfinite(normal), axis=1)
    rows, points, ahead, normal = rows[keep], points[keep], ahead[keep], normal[keep]
    direction = ahead - points
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    minutiae_3d = [
        {"id": int(i), "kind": "bifurcation" if int(row[3]) == BIFURCATION else "ending",
         "xyz": [float(x) for x in p], "direction": [float(x) for x in d], "normal": [float(x) for x in n],
         "skin_ab_mm": [float(row[0]), float(row[1])], "skin_angle_rad": float(row[2])}
        for i, (row, p, d, n) in enumerate(zip(rows, points, direction, normal))
    ]
    per_view = {}
    for view in rig:
        camera, depth = view.camera, renderings[view.name].depth
        uv, z = camera.project(points)
        uv_ahead, _ = camera.project(points + 0.2 * direction)
        pixel = np.round(np.nan_to_num(uv, nan=-1)).astype(int)
        in_image = (z > 0) & (pixel[:, 0] >= 0) & (pixel[:, 0] < camera.width) & (pixel[:, 1] >= 0) & (pixel[:, 1] < camera.height)
        seen_depth = np.full(len(points), np.nan)
        seen_depth[in_image] = depth[pixel[in_image, 1], pixel[in_image, 0]]
        facing = ((camera.center[None] - points) * normal).sum(1) / np.maximum(np.linalg.norm(camera.center[None] - points, axis=1), 1e-12)
        with np.errstate(invalid="ignore"):
            visible = in_image & (np.abs(seen_depth - z) < 0.05 + 0.002 * np.abs(z)) & (facing > 0.2)
        delta = uv_ahead - uv
        angles = np.degrees(np.arctan2(delta[:, 1], delta[:, 0]))
        per_view[view.name] = [
            {"id": int(i), "uv": [float(uv[i, 0]), float(uv[i, 1])] if np.all(np.isfinite(uv[i])) else None,
             "angle_deg": float(angles[i]) if np.isfinite(angles[i]) else None, "visible": bool(visible[i])}
            for i in range(len(points))
        ]
    return {
        "units": "mm", "angle_convention": ANGLE_CONVENTION, "pattern_class": pattern.pattern_class,
        "ridge_period_mm": pattern.period_mm,
        "cores_3d": _skin_points(surface, pattern.cores), "deltas_3d": _skin_points(surface, pattern.deltas),
        "minutiae_3d": minutiae_3d, "views": per_view,
    }


def _skin_points(surface: FingerSurface, ab: np.ndarray) -> list:
    if len(ab) == 0:
        return []
    points = surface.surface_at(ab[:, 0], ab[:, 1])
    return [[float(x) for x in p] for p in points if np.all(np.isfinite(p))]
