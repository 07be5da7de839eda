"""Errors raised at the public boundary.

Every bad-input problem surfaces as an :class:`InputError` whose message is one sentence that
names the file (when there is one) and the problem. The CLI prints that sentence and exits 2.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["FS3DError", "InputError", "input_error"]


class FS3DError(Exception):
    """Base class of the errors fingersplat3d raises on purpose."""


class InputError(FS3DError, ValueError):
    """Bad input: a missing, unreadable, empty, mismatched or malformed file or argument."""


def input_error(path: str | Path | None, problem: str) -> InputError:
    """Build an :class:`InputError` reading ``"<path>: <problem>"`` (or just the problem)."""
    return InputError(f"{path}: {problem}" if path is not None else problem)
