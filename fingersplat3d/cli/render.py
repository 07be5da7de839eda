"""``fs3d render``: novel views of a fitted finger."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..atomic import check_free
from ..errors import InputError
from .types import angles, number

__all__ = ["add", "run"]

NAME = "render"
HELP = "render novel views of a fitted finger (gaussians.ply) at any angle"


def add(commands) -> None:
    """``fs3d render``: its arguments."""
    render = commands.add_parser(
        NAME, help=HELP,
        description="Render new views of the Gaussian-splat model of a reconstruction folder written by "
                    "'fs3d fuse': by default COUNT views at equal steps on the arc from the leftmost through "
                    "the front to the rightmost input camera (the paper's 12), or the views at --angles "
                    "(degrees about the finger axis, relative to the middle input camera). Writes "
                    "renders/<name>.png, <name>_alpha.png, depth/<name>.npy (+ previews), cameras.json and "
                    "contact_sheet.png.")
    render.add_argument("reconstruction", type=Path, help="reconstruction folder (holds gaussians.ply and cameras.json)")
    render.add_argument("-o", "--output", type=Path, help="folder to write (default: RECONSTRUCTION/renders)")
    render.add_argument("--count", type=number(int, 1, 1000), default=12, help="views on the arc (default 12)")
    render.add_argument("--angles", type=angles, help="render at these angles instead, written with = when the first "
                                                       "is negative: --angles=-22.5,22.5")
    render.add_argument("--scale", type=number(float, 0.01, 8.0), default=1.0, help="image size relative to the input views (default 1)")
    render.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    render.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    folder = args.reconstruction
    for needed in ("gaussians.ply", "cameras.json"):
        if not (folder / needed).is_file():
            hint = " (fuse it without --no-splat)" if needed == "gaussians.ply" else ""
            raise InputError(f"{folder / needed}: missing; 'fs3d render' needs a reconstruction folder from 'fs3d fuse'{hint}")
    output = args.output or folder / "renders"
    check_free(output, args.overwrite)
    from ..device import resolve_device  # torch from here on (~2 s): a wrong folder is said without it
    from ..io.cameras import read_cameras
    from ..io.gaussians_ply import read_gaussians_ply
    from ..io.renders import write_renders
    from ..splat.camera_path import cameras_at_angles
    from ..splat.novel import arc_views, render_views

    cameras = read_cameras(folder / "cameras.json")
    gaussians = read_gaussians_ply(folder / "gaussians.ply").to(resolve_device("auto"))
    if len(gaussians) == 0:  # blank views would say nothing of why
        raise InputError(f"{folder / 'gaussians.ply'}: holds no Gaussians: nothing to render (fuse the photos again "
                         "without --no-splat)")
    inputs = [c.scaled(args.scale) if args.scale != 1 else c for c in cameras.cameras.values()]
    start = time.perf_counter()
    try:
        if args.angles:
            names = [f"angle_{a:+07.2f}".replace(".", "p") for a in args.angles]
            views = render_views(gaussians, list(zip(names, cameras_at_angles(inputs, args.angles))))
        else:
            views = arc_views(gaussians, inputs, args.count)
    except ValueError as error:  # one camera, or cameras that did not align: no rig axis to turn about
        raise InputError(f"{folder / 'cameras.json'}: cannot place novel views: {error}") from None
    write_renders(output, views, cameras.units, cameras.scale_mm_per_unit, overwrite=args.overwrite)
    print(f"wrote {output}: {len(views)} views of {len(gaussians)} Gaussians in {time.perf_counter() - start:.1f} s")
    return 0
