"""Reading JSON files with one clear error sentence naming the file."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..errors import input_error

__all__ = ["read_json"]


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
