"""Errors raised at the public boundary.

Every bad-input problem surfaces as an :class:`InputError` whose message is one sentence that
names the file (when there is one) and the problem. The CLI prints that sentence and exits 2.

Exit statuses of ``fs3d`` (documented in the README):

* 0: done;
* 2 (:data:`EXIT_INPUT`): bad input or arguments, one sentence on stderr, nothing written;
* 3 (:data:`EXIT_NOT_REGISTERED`): ``fs3d fuse`` wrote its outputs but some views could not be
  registered with the others (``report.json`` says which and why); not used when the images are
  identical or there is one view (the paper's monocular mode); ``fs3d rig calibrate`` when fewer
  than two captures registered with all their views;
* 4 (:data:`EXIT_INCOMPLETE`): ``fs3d batch`` finished but some captures failed or were not
  registered (``results.csv`` says which and why); the others are complete; likewise an evaluation or benchmark
  with failed rows, and ``fs3d print`` when an input gave no print or a print too small for NFIQ2 (``prints.csv``);
* 130: interrupted.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable

__all__ = ["FS3DError", "InputError", "InputNote", "input_error", "run_script", "EXIT_INPUT", "EXIT_NOT_REGISTERED",
           "EXIT_INCOMPLETE"]

EXIT_INPUT = 2
EXIT_NOT_REGISTERED = 3
EXIT_INCOMPLETE = 4


class FS3DError(Exception):
    """Base class of the errors fingersplat3d raises on purpose."""


class InputError(FS3DError, ValueError):
    """Bad input: a missing, unreadable, empty, mismatched or malformed file or argument."""


class InputNote(UserWarning):
    """Something about the input was set aside and the run went on (a foreign ``manifest.json``, say).

    Issued with :func:`warnings.warn`; ``fs3d`` prints it as one line, ``fs3d CMD: note: ...``.
    """


def input_error(path: str | Path | None, problem: str) -> InputError:
    """Build an :class:`InputError` reading ``"<path>: <problem>"`` (or just the problem)."""
    return InputError(f"{path}: {problem}" if path is not None else problem)


def run_script(main: Callable[[], int | None]) -> int:
    """A tool script's ``main()`` ended as ``fs3d``'s commands end: bad input (an :class:`FS3DError`, a missing file)
    is one sentence on stderr and exit 2, not a traceback; Ctrl-C is 130."""
    name = Path(sys.argv[0]).stem
    try:
        return int(main() or 0)
    except (FS3DError, FileNotFoundError, FileExistsError) as error:
        print(f"{name}: error: {error}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
