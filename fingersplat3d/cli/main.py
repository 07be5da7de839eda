"""``fs3d``: the command line. Thin: parses arguments, calls the library, reports errors in one line.

Each command's arguments and runner live in a module of their own (``add(commands)`` registers the
arguments and sets ``run``; ``NAME`` and ``HELP`` are its name and its line in ``fs3d --help``, and its module
imports nothing heavy at the top, so that listing it costs nothing); this one only assembles them (the arguments of
the command run only, :func:`build_parser`) and turns errors into exit statuses.
"""
from __future__ import annotations

import argparse
import sys
import warnings

from .. import __version__
from ..errors import EXIT_INPUT, FS3DError, InputNote
from ..geometry import skip_open3d_web_viewer
from . import (
    batch,
    bench,
    eval_depth,
    eval_match,
    eval_quality,
    eval_register,
    fuse,
    info,
    preview,
    prints,
    register,
    render,
    rig,
    synth,
)

__all__ = ["main", "build_parser", "command_of"]

COMMANDS = (synth, fuse, info, preview, render, prints, batch, rig)
EVAL_ACTIONS = (eval_depth, eval_match, eval_register, eval_quality)


class _Parser(argparse.ArgumentParser):
    """Argument errors as one sentence (``fs3d fuse: error: ...``), exit status 2; ``--help`` shows the usage."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message}\n")


EVAL_HELP = "the paper's experiments: depth error, matching, view registration, image quality"


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``fs3d`` parser. ``command``: the one command whose arguments are built; the others are listed by name and
    help line only, so that ``fs3d --help`` does not wait for torch (the commands' defaults live in modules that load
    it: 5 s on 2 cores) and a command does not load the others' libraries. None: every command in full."""
    parser = _Parser(
        prog="fs3d",
        description="fingersplat3d: 3D fingerprints from 2-3 uncalibrated photos of a finger.",
        epilog="Run 'fs3d COMMAND --help' for the options of each command.",
    )
    parser.add_argument("--version", action="version", version=f"fingersplat3d {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def add(module, into) -> None:
        if command is None or command == module.NAME:
            module.add(into)
        else:
            into.add_parser(module.NAME, help=module.HELP)

    for module in COMMANDS:
        add(module, commands)
    if command in (None, "eval"):
        evaluate = commands.add_parser("eval", help=EVAL_HELP, description="Evaluate reconstructions against ground truth.")
        actions = evaluate.add_subparsers(dest="action", metavar="ACTION", required=True)
        for action in EVAL_ACTIONS:
            action.add(actions)
    else:
        commands.add_parser("eval", help=EVAL_HELP)
    add(register, commands)
    add(bench, commands)
    return parser


def command_of(argv: list[str]) -> str | None:
    """The command ``argv`` names (its first word not an option), or None."""
    return next((word for word in argv if not word.startswith("-")), None)


def _note_printer(command: str):
    """``warnings.showwarning`` that prints an :class:`InputNote` as one line, once (a file read twice gives the
    same note twice), other warnings as Python does."""
    default, shown = warnings.showwarning, set()

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, InputNote):
            if str(message) not in shown:
                shown.add(str(message))
                print(f"fs3d {command}: note: {message}", file=sys.stderr)
        else:
            default(message, category, filename, lineno, file, line)
    return show


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(command_of(argv) or "")
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # --help and --version exit 0 as argparse does; argument errors return 2
        if stop.code == EXIT_INPUT:
            return EXIT_INPUT
        raise
    skip_open3d_web_viewer()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", InputNote)
            warnings.showwarning = _note_printer(args.command)
            return args.run(args)
    except (FS3DError, FileExistsError, FileNotFoundError) as error:
        print(f"fs3d {args.command}: error: {error}", file=sys.stderr)
        return EXIT_INPUT
    except BrokenPipeError:  # output piped into head & co.
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print("fs3d: interrupted", file=sys.stderr)
        return 130
