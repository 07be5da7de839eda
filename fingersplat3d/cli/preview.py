"""``fs3d preview``: a contact-sheet picture of a capture."""
from __future__ import annotations

import argparse
from pathlib import Path

from .types import number

__all__ = ["add", "run"]

NAME = "preview"
HELP = "save a contact-sheet picture of a capture"


def add(commands) -> None:
    """``fs3d preview``: its arguments."""
    preview = commands.add_parser(NAME, help=HELP,
                                  description="Save a PNG with, for each view, the photo (ground-truth minutiae drawn: "
                                              "endings red, bifurcations blue), the mask and the depth map.")
    preview.add_argument("capture", type=Path, help="capture folder")
    preview.add_argument("-o", "--output", type=Path, help="PNG to write (default: CAPTURE/preview.png)")
    preview.add_argument("--tile-width", type=number(int, 16, 8192), default=480, help="width of each tile in pixels")
    preview.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..io.capture import capture_files, read_capture
    from ..io.images import write_image
    from ..io.minutiae import read_minutiae
    from ..viz import contact_sheet

    capture = read_capture(args.capture)
    files = capture_files(args.capture)
    minutiae = read_minutiae(files.minutiae) if files.minutiae is not None else None
    sheet = contact_sheet(capture, minutiae, tile_width=args.tile_width)
    output = args.output or args.capture / "preview.png"
    write_image(output, sheet.astype("float32") / 255.0)
    print(f"wrote {output}")
    return 0
