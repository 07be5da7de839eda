"""``fs3d info``: what a capture folder, a dataset folder or a set of images holds."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["add", "run", "describe"]


def add(commands) -> None:
    """``fs3d info``: its arguments."""
    info = commands.add_parser("info", help="describe a capture folder or a dataset folder",
                               description="Print what a capture folder (or a UWA / CFPose / plain image folder) holds.")
    info.add_argument("path", type=Path, nargs="+", help="capture folder, dataset folder or image files")
    info.add_argument("--json", action="store_true", help="machine-readable output")
    info.set_defaults(run=run)


def describe(capture) -> dict:
    exif = capture.metadata.get("exif_focal", {})
    views = [{"name": v.name, "size": f"{v.width}x{v.height}", "channels": v.channels,
              "mask": v.mask is not None, "camera": v.camera is not None, "depth": v.depth is not None,
              "exif_focal_px": exif.get(v.name, {}).get("focal_px")}
             for v in capture.views]
    keys = ("dataset", "rig", "seed", "pattern_class", "ridge_period_mm", "units", "subject", "finger", "capture")
    return {"views": views, **{k: capture.metadata[k] for k in keys if k in capture.metadata}}


def _name_every_unreadable(paths: list[Path], named: int = 8) -> None:
    """When more than one of the images ``paths`` names (files, or the images of folders, as ``load_any`` takes them)
    cannot be read, an ``InputError`` naming each (``named`` of them at most): reading stops at the first, and a user
    checking a dataset wants to know all. Returns when at most one is unreadable (the caller's error says which)."""
    from ..errors import InputError
    from ..io.images import IMAGE_SUFFIXES, read_image

    files = []
    for path in paths:
        if path.is_dir():
            files += sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
        elif path.is_file():
            files.append(path)
    problems = []
    for file in files:
        try:
            read_image(file)
        except InputError as error:
            problems.append(str(error))
    if len(problems) > 1:
        more = f"; and {len(problems) - named} more" if len(problems) > named else ""
        raise InputError(f"{len(problems)} of {len(files)} images cannot be read: " + "; ".join(problems[:named]) + more)


def run(args: argparse.Namespace) -> int:
    from ..io.capture import capture_files, is_capture_folder, read_capture
    from ..io.minutiae import read_minutiae

    paths = args.path
    if len(paths) == 1 and is_capture_folder(paths[0]):
        capture = read_capture(paths[0])
        report = {"path": str(paths[0]), "kind": "capture folder", **describe(capture)}
        files = capture_files(paths[0])
        if files.minutiae is not None:
            minutiae = read_minutiae(files.minutiae)
            report["minutiae"] = len(minutiae.get("minutiae_3d", []))
            report["visible_minutiae"] = {k: sum(e["visible"] for e in v) for k, v in minutiae.get("views", {}).items()}
        captures = [report]
    else:
        from ..errors import InputError
        from ..io.datasets import load_any

        try:
            loaded = load_any(paths)
        except InputError:
            _name_every_unreadable(paths)
            raise
        captures = [{"kind": "dataset capture", **describe(c)} for c in loaded]
    if args.json:
        print(json.dumps(captures, indent=2))
    else:
        for report in captures:
            head = {k: v for k, v in report.items() if k != "views"}
            print(", ".join(f"{k}: {v}" for k, v in head.items()))
            for view in report["views"]:
                flags = [k for k in ("mask", "camera", "depth") if view[k]]
                focal = "" if view["exif_focal_px"] is None else f", EXIF focal {view['exif_focal_px']:.0f} px"
                print(f"  {view['name']}: {view['size']}, {'gray' if view['channels'] == 1 else 'RGB'}"
                      + (f", with {', '.join(flags)}" if flags else "") + focal)
    return 0
