"""``minutiae.json``: ground-truth minutiae of a finger, in 3D and as seen in each view.

Schema::

    {"minutiae_3d": [{"id": 0, "kind": "ending" | "bifurcation",
                      "xyz": [x, y, z], "direction": [dx, dy, dz]}, ...],
     "views": {"v0": [{"id": 0, "uv": [u, v], "angle_deg": a, "visible": true}, ...], ...},
     ... free keys: "cores", "deltas", "pattern_class", "angle_convention", ...}

``minutiae_3d`` is required; ``views`` is optional (read as ``{}``). Ids are integers or strings,
unique in ``minutiae_3d``; every id in ``views`` must name a 3D minutia. ``xyz`` is in the
capture's world frame and units; ``direction`` is a non-zero 3-vector along the ridge; ``uv`` is a
pixel position (OpenCV convention, pixel centres at integers). Free keys are kept as they are;
numpy arrays and scalars in them are written as plain JSON.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from .jsonio import read_json
from ..errors import input_error
from ..atomic import atomic_path

__all__ = ["MINUTIA_KINDS", "read_minutiae", "write_minutiae", "validate_minutiae"]

MINUTIA_KINDS = ("ending", "bifurcation")


def _plain(value: Any) -> Any:
    """numpy arrays / scalars to JSON-ready Python values (``json.dumps`` ``default`` hook)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (tuple, set)):
        return list(value)
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _vector(value: Any, size: int, where: str, path: str | Path | None, nonzero: bool = False) -> list[float]:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) != size or any(
            isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)) for x in value):
        raise input_error(path, f"{where} must be a list of {size} numbers, got {value!r}")
    numbers = [float(x) for x in value]
    if not all(math.isfinite(x) for x in numbers):
        raise input_error(path, f"{where} contains NaN or Inf")
    if nonzero and not any(numbers):
        raise input_error(path, f"{where} must not be the zero vector")
    return numbers


def _identifier(value: Any, where: str, path: str | Path | None) -> int | str:
    if isinstance(value, np.integer):
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise input_error(path, f'{where} has an invalid "id" {value!r} (an integer or a string is needed)')
    return value


def _check_keys(entry: Any, keys: tuple[str, ...], where: str, path: str | Path | None) -> None:
    if not isinstance(entry, dict):
        raise input_error(path, f"{where} must be an object")
    missing = [key for key in keys if key not in entry]
    if missing:
        raise input_error(path, f"{where} is missing {', '.join(repr(key) for key in missing)}")


def validate_minutiae(data: Any, path: str | Path | None = None) -> dict:
    """Check ``data`` against the schema; return a plain-Python copy (lists, floats) of it.

    Problems raise ``InputError`` naming ``path`` (when given) and the offending entry.
    """
    if not isinstance(data, dict):
        raise input_error(path, "minutiae data must be a JSON object")
    if "minutiae_3d" not in data:
        raise input_error(path, 'is missing the key "minutiae_3d"')
    if not isinstance(data["minutiae_3d"], (list, tuple)):
        raise input_error(path, '"minutiae_3d" must be a list')
    result = dict(data)
    minutiae, ids = [], set()
    for index, entry in enumerate(data["minutiae_3d"]):
        where = f"minutiae_3d[{index}]"
        _check_keys(entry, ("id", "kind", "xyz", "direction"), where, path)
        identifier = _identifier(entry["id"], where, path)
        if identifier in ids:
            raise input_error(path, f"{where} repeats the id {identifier!r}")
        ids.add(identifier)
        if entry["kind"] not in MINUTIA_KINDS:
            raise input_error(path, f'{where} has kind {entry["kind"]!r} (expected "ending" or "bifurcation")')
        minutiae.append({**entry, "id": identifier,
                         "xyz": _vector(entry["xyz"], 3, f'{where} "xyz"', path),
                         "direction": _vector(entry["direction"], 3, f'{where} "direction"', path, nonzero=True)})
    result["minutiae_3d"] = minutiae
    views = data.get("views", {})
    if not isinstance(views, dict):
        raise input_error(path, '"views" must be an object mapping view names to lists')
    result["views"] = {}
    for name, observations in views.items():
        if not isinstance(name, str) or not isinstance(observations, (list, tuple)):
            raise input_error(path, f'"views" entry {name!r} must map a view name to a list')
        checked = []
        for index, entry in enumerate(observations):
            where = f"views[{name!r}][{index}]"
            _check_keys(entry, ("id", "uv", "angle_deg", "visible"), where, path)
            identifier = _identifier(entry["id"], where, path)
            if identifier not in ids:
                raise input_error(path, f"{where} refers to id {identifier!r}, which is not in minutiae_3d")
            angle = entry["angle_deg"]
            if isinstance(angle, bool) or not isinstance(angle, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(float(angle)):
                raise input_error(path, f'{where} "angle_deg" must be a finite number, got {angle!r}')
            visible = entry["visible"]
            if not isinstance(visible, (bool, np.bool_)):
                raise input_error(path, f'{where} "visible" must be true or false, got {visible!r}')
            checked.append({**entry, "id": identifier, "uv": _vector(entry["uv"], 2, f'{where} "uv"', path),
                            "angle_deg": float(angle), "visible": bool(visible)})
        result["views"][name] = checked
    return result


def _format(data: dict) -> str:
    """JSON with one minutia per line (readable diffs, no number-per-line sprawl)."""
    def dump(value: Any) -> str:
        return json.dumps(value, default=_plain, allow_nan=False)

    def rows(items: list, indent: str) -> str:
        if not items:
            return "[]"
        return "[\n" + ",\n".join(indent + "  " + dump(item) for item in items) + "\n" + indent + "]"

    parts = []
    for key, value in data.items():
        if key == "minutiae_3d":
            text = rows(value, "  ")
        elif key == "views":
            inner = [f"    {dump(name)}: {rows(items, '    ')}" for name, items in value.items()]
            text = "{\n" + ",\n".join(inner) + "\n  }" if inner else "{}"
        else:
            text = dump(value)
        parts.append(f"  {dump(key)}: {text}")
    return "{\n" + ",\n".join(parts) + "\n}"


def write_minutiae(path: str | Path, data: dict) -> Path:
    """Validate ``data`` and write it as ``minutiae.json``, atomically."""
    path = Path(path)
    checked = validate_minutiae(data, path)
    try:
        text = _format(checked)
    except (TypeError, ValueError) as error:
        raise input_error(path, f"minutiae data cannot be written as JSON ({error})") from None
    with atomic_path(path) as temporary:
        temporary.write_text(text + "\n", encoding="utf-8")
    return path


def read_minutiae(path: str | Path) -> dict:
    """Read and validate a ``minutiae.json``; returns the dict (``views`` always present)."""
    path = Path(path)
    data = read_json(path)
    return validate_minutiae(data, path)
