"""Pixel positions in CSV: ``x,y`` columns (any others are carried through), one point per row.

Read by ``fs3d register --points`` (minutiae or any landmarks of view A) and written back with the
positions in view B and each point's status (:mod:`fingersplat3d.align.transfer`).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..atomic import atomic_path
from ..errors import input_error

__all__ = ["read_points_csv", "write_points_csv"]


def read_points_csv(path: str | Path) -> tuple[list[dict], np.ndarray]:
    """``(rows as read, xy [N, 2])``; the ``x`` and ``y`` columns are found case-insensitively."""
    path = Path(path)
    if not path.is_file():
        raise input_error(path, "file not found")
    try:
        with open(path, newline="") as handle:
            reader = csv.DictReader(handle)
            fields = {name.strip().lower(): name for name in reader.fieldnames or []}
            if "x" not in fields or "y" not in fields:
                raise input_error(path, f"needs x and y columns, has {', '.join(reader.fieldnames or []) or 'none'}")
            rows = list(reader)
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise input_error(path, f"not a readable CSV file ({error})") from None
    xy = np.empty((len(rows), 2))
    for i, row in enumerate(rows):
        try:
            xy[i] = float(row[fields["x"]]), float(row[fields["y"]])
        except (TypeError, ValueError):
            raise input_error(path, f"line {i + 2}: x and y must be numbers, got {row[fields['x']]!r}, "
                                    f"{row[fields['y']]!r}") from None
    if not np.isfinite(xy).all():
        raise input_error(path, "x and y must be finite")
    return rows, xy


def write_points_csv(path: str | Path, rows: list[dict], uv_b: np.ndarray, status: np.ndarray) -> Path:
    """The rows with ``x_b``, ``y_b`` (empty where not carried) and ``status`` appended."""
    fields = list(rows[0]) if rows else ["x", "y"]
    with atomic_path(path) as temporary, open(temporary, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fields + ["x_b", "y_b", "status"])
        writer.writeheader()
        for row, (u, v), state in zip(rows, uv_b, status):
            writer.writerow({**row, "x_b": "" if not np.isfinite(u) else f"{u:.3f}",
                             "y_b": "" if not np.isfinite(v) else f"{v:.3f}", "status": state})
    return Path(path)
