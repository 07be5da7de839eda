"""``cameras.json``: the cameras of a capture or a reconstruction.

Schema (docs/conventions.md)::

    {"units": "mm" | "arbitrary", "scale_mm_per_unit": null | float,
     "views": [{"name": "v0", "image": "images/v0.png", "width": W, "height": H,
                "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], "world_to_cam": [[4 x 4]]}]}

``K`` is an OpenCV pinhole (pixel centres at integer coordinates) and ``world_to_cam`` a rigid
4x4 transform (orthonormal rotation with det +1, last row ``0 0 0 1``). ``scale_mm_per_unit`` may
be left out (read as null); with ``"units": "mm"`` it must be null or 1. ``image`` is a path
relative to the folder holding ``cameras.json`` (an absolute path is allowed for a
reconstruction whose inputs live elsewhere). Numbers are written with full precision, so a
write/read round trip is exact.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from .jsonio import read_json
from ..errors import input_error
from ..scene import Camera
from ..atomic import atomic_path

__all__ = ["UNITS", "CameraSet", "read_cameras", "write_cameras"]

UNITS = ("mm", "arbitrary")
_VIEW_KEYS = ("name", "image", "width", "height", "K", "world_to_cam")
_RIGID_TOLERANCE = 1e-6


@dataclass(frozen=True, eq=False)
class CameraSet:
    """The content of one ``cameras.json``; ``cameras`` and ``images`` keep the file's view order."""

    units: str  # "mm" or "arbitrary"
    scale_mm_per_unit: float | None  # millimetres per unit when known, else None
    cameras: dict[str, Camera]  # view name -> camera
    images: dict[str, str]  # view name -> image path as written in the file

    @property
    def names(self) -> list[str]:
        return list(self.cameras)

    def entries(self) -> list[tuple[str, str, Camera]]:
        """``(name, image, camera)`` triples, ready for :func:`write_cameras`."""
        return [(name, self.images[name], camera) for name, camera in self.cameras.items()]

    def __len__(self) -> int:
        return len(self.cameras)


def _check_units(units: Any, scale: Any, where: str | Path) -> tuple[str, float | None]:
    if units not in UNITS:
        raise input_error(where, f'"units" must be "mm" or "arbitrary", got {units!r}')
    if scale is None:
        return units, None
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)) \
            or not math.isfinite(float(scale)) or float(scale) <= 0:
        raise input_error(where, f'"scale_mm_per_unit" must be null or a positive finite number, got {scale!r}')
    if units == "mm" and float(scale) != 1.0:
        raise input_error(where, f'"units" is "mm" so "scale_mm_per_unit" must be null or 1, got {scale!r}')
    return units, float(scale)


def _number_matrix(value: Any, shape: tuple[int, int], path: Path, what: str) -> np.ndarray:
    """A nested JSON list of plain numbers with the given shape, as float64."""
    rows_ok = isinstance(value, list) and len(value) == shape[0] and all(
        isinstance(row, list) and len(row) == shape[1] for row in value)
    if not rows_ok:
        raise input_error(path, f"{what} must be a {shape[0]}x{shape[1]} list of numbers")
    for row in value:
        for number in row:
            if isinstance(number, bool) or not isinstance(number, (int, float)):
                raise input_error(path, f"{what} must contain only numbers, found {number!r}")
            if not math.isfinite(number):
                raise input_error(path, f"{what} contains a non-finite number ({number})")
    return np.array(value, dtype=np.float64)


def _positive_int(value: Any, path: Path, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value != int(value) or value < 1:
        raise input_error(path, f"{what} must be a positive integer, got {value!r}")
    return int(value)


def _parse_view(entry: Any, index: int, path: Path) -> tuple[str, str, Camera]:
    if not isinstance(entry, dict):
        raise input_error(path, f"views[{index}] must be an object, got {type(entry).__name__}")
    name = entry.get("name")
    if not isinstance(name, str) or not name:
        raise input_error(path, f'views[{index}] has no "name" (a non-empty string)')
    label = f"view {name!r}"
    missing = [key for key in _VIEW_KEYS if key not in entry]
    if missing:
        raise input_error(path, f"{label} is missing {', '.join(repr(key) for key in missing)}")
    image = entry["image"]
    if not isinstance(image, str) or not image:
        raise input_error(path, f'{label} has an invalid "image" (a non-empty path string is needed)')
    width = _positive_int(entry["width"], path, f'{label} "width"')
    height = _positive_int(entry["height"], path, f'{label} "height"')
    K = _number_matrix(entry["K"], (3, 3), path, f'{label} "K"')
    if K[0, 0] <= 0 or K[1, 1] <= 0 or K[0, 1] != 0 or K[1, 0] != 0 or not np.array_equal(K[2], [0, 0, 1]):
        raise input_error(path, f'{label} "K" must be [[fx,0,cx],[0,fy,cy],[0,0,1]] with positive focal lengths')
    pose = _number_matrix(entry["world_to_cam"], (4, 4), path, f'{label} "world_to_cam"')
    rotation = pose[:3, :3]
    if not np.array_equal(pose[3], [0, 0, 0, 1]) or np.linalg.det(rotation) < 0 or \
            not np.allclose(rotation @ rotation.T, np.eye(3), atol=_RIGID_TOLERANCE):
        raise input_error(path, f'{label} "world_to_cam" is not a rigid transform '
                                "(rotation must be orthonormal with det +1 and the last row 0 0 0 1)")
    try:
        camera = Camera(K, pose, width, height)
    except ValueError as error:  # anything Camera checks that the lines above did not
        raise input_error(path, f"{label} has an invalid camera ({error})") from None
    return name, image, camera


def read_cameras(path: str | Path) -> CameraSet:
    """Read and validate a ``cameras.json``; every problem is an ``InputError`` naming the file."""
    path = Path(path)
    data = read_json(path)
    if not isinstance(data, dict):
        raise input_error(path, "must hold a JSON object with \"units\" and \"views\"")
    for key in ("units", "views"):
        if key not in data:
            raise input_error(path, f"is missing the key {key!r}")
    units, scale = _check_units(data["units"], data.get("scale_mm_per_unit"), path)
    if not isinstance(data["views"], list) or not data["views"]:
        raise input_error(path, '"views" must be a non-empty list')
    cameras: dict[str, Camera] = {}
    images: dict[str, str] = {}
    for index, entry in enumerate(data["views"]):
        name, image, camera = _parse_view(entry, index, path)
        if name in cameras:
            raise input_error(path, f"view {name!r} appears twice")
        cameras[name], images[name] = camera, image
    return CameraSet(units, scale, cameras, images)


def _entries(cameras: Mapping[str, Camera] | Iterable[tuple[str, str, Camera]]) -> list[tuple[str, str, Camera]]:
    if isinstance(cameras, CameraSet):
        return cameras.entries()
    if isinstance(cameras, Mapping):
        return [(str(name), f"images/{name}.png", camera) for name, camera in cameras.items()]
    return [(str(name), str(image), camera) for name, image, camera in cameras]


def write_cameras(path: str | Path, cameras: Mapping[str, Camera] | Iterable[tuple[str, str, Camera]],
                  units: str = "mm", scale_mm_per_unit: float | None = None, extra: Mapping[str, Any] | None = None) -> Path:
    """Write ``cameras.json`` atomically.

    ``cameras`` is a mapping ``name -> Camera`` (images are then ``images/<name>.png``), a list of
    ``(name, image_relpath, Camera)`` or a :class:`CameraSet` (its entries; ``units`` still applies).
    ``extra``: more top-level keys after ``views`` (readers of the schema ignore them).
    """
    path = Path(path)
    entries = _entries(cameras)
    units, scale = _check_units(units, scale_mm_per_unit, path)
    names = [name for name, _, _ in entries]
    if not entries:
        raise ValueError(f"{path}: no cameras to write")
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: view names must be unique, got {names}")
    lines = []
    for name, image, camera in entries:
        if not isinstance(camera, Camera):
            raise TypeError(f"{path}: view {name!r}: expected a Camera, got {type(camera).__name__}")
        view = {"name": name, "image": image, "width": camera.width, "height": camera.height,
                "K": camera.K.tolist(), "world_to_cam": camera.world_to_cam.tolist()}
        lines.append("    " + json.dumps(view, allow_nan=False))
    text = ('{\n  "units": ' + json.dumps(units) + ',\n  "scale_mm_per_unit": ' + json.dumps(scale)
            + ',\n  "views": [\n' + ",\n".join(lines) + "\n  ]"
            + "".join(f",\n  {json.dumps(str(key))}: {json.dumps(value, indent=2, allow_nan=False)}" for key, value in (extra or {}).items())
            + "\n}\n")
    with atomic_path(path) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return path
