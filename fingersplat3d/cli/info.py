"""``fs3d info``: what a capture folder, a dataset folder or a set of images holds."""
from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np

__all__ = ["add", "run", "describe", "describe_reconstruction"]

NAME = "info"
HELP = "describe a capture, dataset or reconstruction folder"

RECONSTRUCTION_FILES = ("fused.ply", "gaussians.ply", "mesh.ply", "depth", "report.json", "overview.png", "views")


def add(commands) -> None:
    """``fs3d info``: its arguments."""
    info = commands.add_parser(NAME, help=HELP,
                               description="Print what a capture folder (or a UWA / CFPose / plain image folder) holds, "
                                           "or what a reconstruction folder from 'fs3d fuse' says of its views: "
                                           "registered or not, focal, the share of each view backed by a second one, "
                                           "each pair's turn and how sure it is, the run's warnings; of a folder of "
                                           "reconstructions ('fs3d batch -o'), a line each and the median of the "
                                           "focals their photos held, to fuse them all with (--focal-px).")
    info.add_argument("path", type=Path, nargs="+", help="capture folder, dataset folder, reconstruction folder or image files")
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


def describe_reconstruction(folder: Path) -> dict:
    """What a reconstruction folder says of itself: its cameras (``cameras.json``) and what its ``report.json``
    recorded (registration, how sure, warnings), and which outputs it holds."""
    from ..eval.poses import view_turn_deg
    from ..io.reconstruction_folder import ReconstructionFolder

    folder_read = ReconstructionFolder(folder)
    cameras, report = folder_read.cameras, folder_read.report
    problems = (["report.json could not be read (not a JSON object); only the cameras are described"]
                if not report and (folder / "report.json").is_file() else [])
    alignment = report.get("alignment", {}) if isinstance(report.get("alignment"), dict) else {}
    aligned, backed = alignment.get("aligned", {}), alignment.get("backed_by_two_views", {})
    views = [{"name": name, "size": f"{camera.width}x{camera.height}", "focal_px": round(float(camera.K[0, 0]), 1),
              "registered": aligned.get(name), "backed_by_two_views": backed.get(name)}
             for name, camera in cameras.cameras.items()]
    uncertainty = alignment.get("turn_uncertainty_deg") or {}
    sensitivity = alignment.get("turn_sensitivity_deg") or {}
    names = cameras.names
    pairs = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if aligned and not (aligned.get(a) and aligned.get(b)):
                continue
            turn, roll = view_turn_deg(cameras.cameras[a].rotation, cameras.cameras[b].rotation)
            pairs.append({"pair": f"{a}-{b}", "turn_deg": round(turn, 2), "roll_deg": round(roll, 2),
                          "uncertainty_deg": uncertainty.get(f"{a}-{b}"), "moves_with_focal_deg": sensitivity.get(f"{a}-{b}"),
                          "held_at_least_turn": f"{a}-{b}" in (alignment.get("turn_held_at_bound") or [])})
    splat = report.get("splat") if isinstance(report.get("splat"), dict) else {}
    shading = splat.get("shading") if isinstance(splat.get("shading"), dict) else {}
    described = {"path": str(folder), "kind": "reconstruction folder", "mode": alignment.get("mode"),
                 "registered": f"{sum(bool(v['registered']) for v in views)} of {len(views)}" if aligned else None,
                 "residual_px": None if alignment.get("residual_px") is None else round(float(alignment["residual_px"]), 3),
                 "units": cameras.units, "scale_mm_per_unit": cameras.scale_mm_per_unit, "points": report.get("points"),
                 "focal_held_by_photos": (alignment.get("focal_probe") or {}).get("held"),
                 "psnr_in_mask_db": splat.get("psnr_in_mask_db"), "shading_exponent": shading.get("facing_exponent"),
                 "version": report.get("version"),
                 "files": [name for name in RECONSTRUCTION_FILES if (folder / name).exists()]}
    return {**{k: v for k, v in described.items() if v is not None}, "views": views, "pairs": pairs,
            "warnings": problems + [str(w) for w in report.get("warnings", []) if isinstance(report.get("warnings"), list)]}


def _print_reconstruction(described: dict) -> None:
    from ..eval.poses import ROLL_NOTED_DEG

    head = {k: v for k, v in described.items() if k not in ("views", "pairs", "warnings", "psnr_in_mask_db")}
    print(", ".join(f"{k}: {', '.join(v) if isinstance(v, list) else v}" for k, v in head.items()))
    psnr = described.get("psnr_in_mask_db") or {}
    for view in described["views"]:
        state = "" if view["registered"] is None else "registered" if view["registered"] else "not registered"
        backed = "" if view["backed_by_two_views"] is None else f", {view['backed_by_two_views']:.0%} backed by a second view"
        fit = f", splat PSNR {psnr[view['name']]:.1f} dB" if view["name"] in psnr else ""
        print(f"  {view['name']}: {view['size']}, focal {view['focal_px']:.0f} px" + (f", {state}" if state else "")
              + backed + fit)
    for pair in described["pairs"]:
        sure = "" if pair["uncertainty_deg"] is None else f", ±{pair['uncertainty_deg']:.2f}°"
        off = "10 % off" if described.get("focal_held_by_photos") is not False else "held shorter"
        moves = "" if pair["moves_with_focal_deg"] is None else f", moves {pair['moves_with_focal_deg']:.2f}° with the focal {off}"
        held = ", held at the least turn its silhouettes allow (it may be larger)" if pair.get("held_at_least_turn") else ""
        rolled = (f" (and rolled {pair['roll_deg']:.0f}° about the optical axis, as a photo turned in its plane)"
                  if abs(pair["roll_deg"]) >= ROLL_NOTED_DEG else "")
        print(f"  turn {pair['pair']}: {pair['turn_deg']:.2f}°" + rolled + sure + moves + held)
    for warning in described["warnings"]:
        print(f"  warning: {warning}")


def _reconstructions_in(folder: Path) -> list[Path]:
    """The reconstruction folders directly inside ``folder`` (what ``fs3d batch -o`` writes), when it holds no images
    of its own; else none."""
    from ..io.datasets import _image_files
    from ..io.reconstruction_folder import is_reconstruction_folder

    if not folder.is_dir() or _image_files(folder, recursive=False)[0]:
        return []
    from ..io.datasets import natural_key

    return sorted((p for p in folder.iterdir() if p.is_dir() and is_reconstruction_folder(p)), key=lambda p: natural_key(p.name))


def shared_focal(described: list[dict]) -> dict | None:
    """The focal a batch's captures could share (``--focal-px``): the median of the focals fitted by the reconstructions
    with three views or more, all registered, whose photos held their focal (the report's focal probe; a focal given
    or taken from a rig has none), among those of the most common first-view size, either way round (a focal is in its
    photo's pixels); None with fewer than two. Three cameras on a ring see their focal weakly, and it is what varies
    most from capture to capture: held alike, the real dev captures' turns agree within 0.5-0.9 degrees per pair,
    0.7-1.25 fitted one by one (docs/measurements.md, "The rig's remaining error is the focal's spread")."""
    fitted = [one for one in described
              if one.get("focal_held_by_photos") is True and len(one["views"]) >= 3
              and all(view["registered"] for view in one["views"])]
    if len(fitted) < 2:
        return None
    # the photo's size, long side first: a camera stored portrait has the same focal in pixels
    sizes = ["x".join(sorted(one["views"][0]["size"].split("x"), key=int, reverse=True)) for one in fitted]
    size = Counter(sizes).most_common(1)[0][0]  # a tie goes to the size met first, the same on every run
    focals = np.array([one["views"][0]["focal_px"] for one, own in zip(fitted, sizes) if own == size])
    if len(focals) < 2:
        return None
    median = float(np.median(focals))
    return {"size": size, "count": len(focals), "median_px": median, "min_px": float(focals.min()),
            "max_px": float(focals.max()), "spread": float((focals.max() - focals.min()) / median)}


def _name_every_unreadable(paths: list[Path], named: int = 8) -> None:
    """When more than one of the images ``paths`` names (files, or the images of folders, as ``load_any`` takes them)
    cannot be read, an ``InputError`` naming each (``named`` of them at most): reading stops at the first, and a user
    checking a dataset wants to know all. Returns when at most one is unreadable (the caller's error says which)."""
    from ..errors import InputError
    from ..io.datasets import _image_files
    from ..io.images import read_image

    files = []
    for path in paths:
        if path.is_dir():
            files += _image_files(path, recursive=False)[0]  # the files load_any reads of a folder
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
    from ..io.reconstruction_folder import is_reconstruction_folder

    paths = args.path
    if len(paths) == 1 and not is_capture_folder(paths[0]) and is_reconstruction_folder(paths[0]):
        described = describe_reconstruction(paths[0])
        if args.json:
            print(json.dumps([described], indent=2))
        else:
            _print_reconstruction(described)
        return 0
    inner = _reconstructions_in(paths[0]) if len(paths) == 1 and not is_capture_folder(paths[0]) else []
    if inner:  # a folder of reconstructions ('fs3d batch -o OUT'): one line each
        described = [describe_reconstruction(folder) for folder in inner]
        if args.json:
            print(json.dumps(described, indent=2))
        else:
            print(f"{paths[0]}: {len(described)} reconstruction folders")
            for one in described:
                warnings = f", {len(one['warnings'])} warning(s)" if one["warnings"] else ""
                focal = f", focal {one['views'][0]['focal_px']:.0f} px" if one["views"] else ""
                print(f"  {Path(one['path']).name}: registered {one.get('registered', '?')}, residual "
                      f"{one.get('residual_px', '?')} px{focal}{warnings}")
            shared = shared_focal(described)
            if shared is not None:
                median, low, high = shared["median_px"], shared["min_px"], shared["max_px"]
                print(f"focal fitted by {shared['count']} of them ({shared['size']}, three views or more, all "
                      f"registered): median {median:.0f} px, {low:.0f}-{high:.0f} px (spread {100 * shared['spread']:.0f} "
                      f"%); photos of one camera fuse alike with --focal-px {median:.0f}")
        return 0
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
