"""``fs3d register``: pixels and photo A carried into view B through the 3D model."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..atomic import atomic_dir
from ..errors import InputError

__all__ = ["add", "run"]

NAME = "register"
HELP = "carry pixel positions (minutiae) and image A into view B through the 3D model"


def add(commands) -> None:
    """``fs3d register``: its arguments."""
    register = commands.add_parser(
        NAME, help=HELP,
        description="Lift pixels of view A onto the reconstructed surface (A's depth and camera) and project them "
                    "into view B; points off the surface, outside B or hidden in B are marked, not dropped. Also "
                    "warps image A into B's frame. Writes points.csv (with --points) and warp.png.")
    register.add_argument("reconstruction", type=Path, help="a reconstruction folder from 'fs3d fuse'")
    register.add_argument("view_a", help="the view the points and the image come from")
    register.add_argument("view_b", help="the view to carry them into")
    register.add_argument("--points", type=Path, help="CSV with x,y columns (pixels of view A); other columns are kept")
    register.add_argument("--image", type=Path,
                          help="view A's photo (default: the path in cameras.json, absolute or relative to the folder)")
    register.add_argument("-o", "--output", type=Path, help="folder to write (default: REC/register_A_to_B)")
    register.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    register.set_defaults(run=run)


def _find_image(folder: Path, listed: str, given: Path | None) -> Path | None:
    if given is not None:
        return given
    for candidate in (Path(listed), folder / listed, folder.parent / listed):
        if candidate.is_file():
            return candidate
    return None


def run(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from ..align.transfer import STATUSES, transfer_points, warp_image
    from ..io.cameras import read_cameras
    from ..io.depth import read_depth
    from ..io.images import read_image
    from ..io.points_csv import read_points_csv, write_points_csv

    folder = args.reconstruction
    if not (folder / "cameras.json").is_file():
        raise InputError(f"{folder}: not a reconstruction folder (no cameras.json; make one with 'fs3d fuse')")
    cameras = read_cameras(folder / "cameras.json")
    for name in (args.view_a, args.view_b):
        if name not in cameras.cameras:
            raise InputError(f"{folder / 'cameras.json'}: no view named {name!r}; views: {', '.join(cameras.names)}")
    if args.view_a == args.view_b:
        raise InputError("view A and view B are the same view")
    cam_a, cam_b = cameras.cameras[args.view_a], cameras.cameras[args.view_b]
    depth_a = read_depth(folder / "depth" / f"{args.view_a}.npy", (cam_a.height, cam_a.width))
    depth_b = read_depth(folder / "depth" / f"{args.view_b}.npy", (cam_b.height, cam_b.width))
    points = read_points_csv(args.points) if args.points is not None else None
    image_path = _find_image(folder, cameras.images[args.view_a], args.image)
    if points is None and image_path is None:
        raise InputError(f"nothing to carry: give --points CSV, or --image (view {args.view_a!r}'s photo "
                         f"{cameras.images[args.view_a]!r} was not found)")
    output = args.output or folder / f"register_{args.view_a}_to_{args.view_b}"
    with atomic_dir(output, overwrite=args.overwrite) as temporary:
        if points is not None:
            rows, xy = points
            uv_b, status = transfer_points(xy, depth_a, cam_a, depth_b, cam_b)
            write_points_csv(temporary / "points.csv", rows, uv_b, status)
            counts = ", ".join(f"{int((status == s).sum())} {s}" for s in STATUSES)
            print(f"{len(xy)} points from {args.view_a} to {args.view_b}: {counts}")
        if image_path is not None:
            image = read_image(image_path)
            if image.shape[:2] != (cam_a.height, cam_a.width):
                raise InputError(f"{image_path}: {image.shape[1]}x{image.shape[0]}, but view {args.view_a!r} is "
                                 f"{cam_a.width}x{cam_a.height}")
            warped, valid = warp_image(image, depth_a, cam_a, depth_b, cam_b)
            picture = np.clip(np.rint(warped * 255.0), 0, 255).astype(np.uint8)  # read_image gives [0, 1]
            if picture.ndim == 3:
                picture = picture[..., ::-1]
            cv2.imwrite(str(temporary / "warp.png"), picture)
            print(f"warped {args.view_a} into {args.view_b}'s frame: {valid.mean():.0%} of its pixels")
    print(f"wrote {output}")
    return 0
