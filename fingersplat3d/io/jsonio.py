"""Reading JSON files with one clear error sentence naming the file, and values made plain JSON before one is written."""
from __future__ import annotations

import json
import math
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..errors import input_error

__all__ = ["read_json", "to_jsonable"]


def read_json(path: str | Path) -> Any:
    """Parse a JSON file; a missing, unreadable or malformed file is an ``InputError`` naming it."""
    path = Path(path)
    if not path.is_file():
        raise input_error(path, "file not found")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise input_error(path, f"not valid JSON ({error.msg} at line {error.lineno}, column {error.colno})") from None
    except (UnicodeDecodeError, OSError) as error:
        raise input_error(path, f"cannot be read ({error})") from None


def to_jsonable(value: Any, where: str = "metadata") -> Any:
    """Plain JSON values from numpy arrays/scalars, tuples, sets (sorted), paths and dataclasses.

    Non-finite floats become ``null`` (JSON has no NaN); anything else unknown is a ``TypeError`` naming ``where`` it
    sits. The one converter of every JSON file the project writes (capture manifests, ``report.json``, batch rows).
    """
    if isinstance(value, Mapping):
        return {str(key): to_jsonable(item, f"{where}.{key}") for key, item in value.items()}
    if is_dataclass(value) and not isinstance(value, type):
        return to_jsonable(asdict(value), where)
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist(), where)
    if isinstance(value, np.generic):
        return to_jsonable(value.item(), where)
    if isinstance(value, (list, tuple)):
        return [to_jsonable(item, f"{where}[{index}]") for index, item in enumerate(value)]
    if isinstance(value, (set, frozenset)):
        return sorted(to_jsonable(item, where) for item in value)
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{where}: cannot store a {type(value).__name__} in JSON")
