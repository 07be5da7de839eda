"""The experiments' result tables on disk: one CSV writer for all of them."""
from __future__ import annotations

import csv
from pathlib import Path

__all__ = ["write_rows"]


def write_rows(path: Path, columns: tuple[str, ...], rows: list[dict]) -> Path:
    """``rows`` as a CSV with ``columns`` (in that order; a key a row lacks is an empty cell, a key
    not in ``columns`` is left out)."""
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows({k: row.get(k, "") for k in columns} for row in rows)
    return path
