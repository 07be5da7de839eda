"""Helpers of several commands: exit statuses of experiments, NIST tools present, inputs there, captures named from inputs."""
from __future__ import annotations

import sys
from pathlib import Path

from ..errors import EXIT_INCOMPLETE, InputError

__all__ = ["finished", "nbis_needed", "refuse_missing", "named_captures"]


def finished(command: str, failed: int, total: int, what: str, output: Path) -> int:
    """Exit status of an experiment that wrote its results: 0, or 4 with one line when some failed."""
    if failed:
        print(f"{command}: {failed} of {total} {what} (see {output / 'summary.md'})", file=sys.stderr)
        return EXIT_INCOMPLETE
    return 0


def nbis_needed(command: str) -> None:
    from ..eval.fingerprint import nbis_available

    if not nbis_available():
        raise InputError(f"'{command}' needs NIST's tools from the nbis-py package: pip install nbis-py==0.1.3")


def refuse_missing(paths: list[Path]) -> None:
    """One sentence naming the first of ``paths`` that is not there (and how many more are not): bad input, said before a
    command loads torch or makes anything."""
    missing = [path for path in paths if not Path(path).exists()]
    if missing:
        more = f" (and {len(missing) - 1} more inputs)" if len(missing) > 1 else ""
        raise InputError(f"{missing[0]}: no such file or folder{more}")


def named_captures(inputs: list[Path]) -> list[tuple[str, object]]:
    """``(name, capture)`` for everything the inputs hold (a capture folder is named after it)."""
    from ..io.capture import is_capture_folder
    from ..io.datasets import load_any

    folders = [p for p in inputs if p.is_dir()]
    files = [p for p in inputs if not p.is_dir()]
    named = []
    for folder in folders:
        captures = load_any(folder)
        for index, capture in enumerate(captures):
            name = capture.metadata.get("name") or (folder.name if len(captures) == 1 else f"{folder.name}_{index}")
            named.append((folder.name if is_capture_folder(folder) else name, capture))
    if files:
        captures = load_any(files)
        for index, capture in enumerate(captures):
            named.append((capture.metadata.get("name") or (files[0].stem if len(captures) == 1 else f"{files[0].stem}_{index}"),
                          capture))
    return named
