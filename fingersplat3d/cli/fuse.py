"""``fs3d fuse``: a 3D finger from 2-N uncalibrated photos."""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from ..atomic import check_free
from ..errors import EXIT_NOT_REGISTERED, InputError
from .options import (add_registration_arguments, add_splat_arguments, photometric_config, read_rig, ridge_px, splat_config,
                      splat_ridge_px)
from .types import COUNT, FINGER_MM, POSITIVE, PX_PER_MM, STEPS

__all__ = ["add", "run"]

NAME = "fuse"
HELP = "3D finger from 2-N uncalibrated photos: cameras, fused point cloud, Gaussians, depth maps, mesh"


def add(commands) -> None:
    """``fs3d fuse``: its arguments."""
    from ..align.solve.settings import GlobalAlignConfig

    fuse = commands.add_parser(
        NAME, help=HELP,
        description="Recover the cameras and one fused 3D finger surface from photos with no camera "
                    "parameters: per-view pointmaps, pairwise registration on ridge-texture correspondences, "
                    "joint global alignment (poses, focal, depth), optional ICP, then a Gaussian-splat fit to the "
                    "photos cleaned with the finger masks. Writes OUT/fused.ply, gaussians.ply (3DGS layout), "
                    "cameras.json, depth/<view>.npy (+ .png previews), report.json and, with --mesh, mesh.ply. "
                    "Without a metric hint the units are arbitrary (and say so).")
    fuse.add_argument("inputs", type=Path, nargs="+",
                      help="a capture folder, a folder of images, or image files (2-3 views of one finger)")
    fuse.add_argument("-o", "--output", type=Path, required=True, help="reconstruction folder to write")
    fuse.add_argument("--backend", default="prior", choices=("prior", "dust3r"),
                      help="pointmap backend: prior (default, needs no weights) or dust3r (needs --checkpoint)")
    fuse.add_argument("--checkpoint", type=Path,
                      help="dust3r backend: DUSt3R checkpoint file, e.g. DUSt3R_ViTLarge_BaseDecoder_512_dpt.pth "
                           "(nothing is downloaded)")
    fuse.add_argument("--device", default="auto",
                      help="where the dust3r backend and the splat fit run: auto (CUDA when available, default), cpu, "
                           "cuda or cuda:N")
    fuse.add_argument("--pair-batch", type=COUNT, default=4, help="dust3r backend: image pairs per network batch (default 4)")
    add_registration_arguments(fuse)
    hint = fuse.add_mutually_exclusive_group()
    hint.add_argument("--px-per-mm", type=PX_PER_MM, help="metric hint: pixels per millimetre at the finger")
    hint.add_argument("--finger-width-mm", type=FINGER_MM, help="metric hint: the finger's width in millimetres")
    fuse.add_argument("--mesh", action="store_true", help="also write mesh.ply (Poisson, cleaned)")
    add_splat_arguments(fuse)
    fuse.add_argument("--icp", action="store_true",
                      help="refine poses with Open3D ICP (guarded; off by default: on near-cylindrical fingers "
                           "it slides about the axis, see the README)")
    fuse.add_argument("--polish-iterations", "--alignment-iterations", type=STEPS, dest="polish_iterations",
                      default=GlobalAlignConfig.polish_iterations,
                      help=f"with --alignment-solver lbfgs: L-BFGS iterations of each global alignment round (default "
                           f"{GlobalAlignConfig.polish_iterations}; --alignment-iterations: its former name)")
    fuse.add_argument("--alignment-solver", choices=("lm", "lbfgs"), default=GlobalAlignConfig.solver,
                      help="global alignment solver: lm (Levenberg-Marquardt, default) or lbfgs (slower to converge; "
                           "measured in docs/measurements.md)")
    fuse.add_argument("--focal-px", type=POSITIVE,
                      help="the cameras' focal length in the photos' pixels (the largest photo's, where one is "
                           "another's shrunk), when known: kept instead of fitted (two views cannot fix it, and their "
                           "turn follows it; see docs/measurements.md)")
    fuse.add_argument("--no-exif-focal", dest="exif_focal", action="store_false",
                      help="fit the focal even when the photos' EXIF records one (by default a focal every photo's EXIF "
                           "agrees on is kept, as --focal-px, and photos of other zooms keep each its own; report.json "
                           "exif_focal says what was found)")
    fuse.add_argument("--rig", type=Path, help="rig.json from 'fs3d rig calibrate': keep its camera poses and focal fixed "
                                               "(the views are its cameras in order)")
    fuse.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    fuse.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..align.registration_config import RegistrationConfig
    from ..align.solve.settings import GlobalAlignConfig
    from ..io.datasets import load_any

    check_free(args.output, args.overwrite)
    if args.backend == "dust3r" and args.checkpoint is None:
        raise InputError("--backend dust3r needs --checkpoint PATH (a DUSt3R .pth file; nothing is downloaded)")
    if args.backend != "dust3r" and args.checkpoint is not None:
        raise InputError(f"--checkpoint is only used by --backend dust3r (the {args.backend} backend has no weights)")
    captures = load_any(args.inputs)
    if len(captures) != 1:
        raise InputError(f"{args.inputs[0]}: holds {len(captures)} captures; fuse one at a time (pass one capture's files)")
    rig = read_rig(args.rig)
    # Torch is loaded from here on (~2 s): a wrong path or option above has been said without waiting for it.
    from ..device import resolve_device
    from ..pipeline import FuseConfig, fuse, write_reconstruction

    resolve_device(args.device)  # an unusable device is an error before any work
    registration = RegistrationConfig(matcher=args.matcher, guided_rounds=args.guided_rounds, seed=args.seed,
                                      photometric=photometric_config(args), global_align=GlobalAlignConfig(polish_iterations=args.polish_iterations,
                                                                     solver=args.alignment_solver))
    config = FuseConfig(backend=args.backend, checkpoint=None if args.checkpoint is None else str(args.checkpoint),
                        device=args.device, pair_batch=args.pair_batch, registration=registration, icp=args.icp,
                        focal_px=args.focal_px, exif_focal=args.exif_focal, px_per_mm=args.px_per_mm, finger_width_mm=args.finger_width_mm, mesh=args.mesh,
                        splat=splat_config(args), ridge_px=ridge_px(args), splat_ridge_px=splat_ridge_px(args))
    start = time.perf_counter()
    result = fuse(captures[0], config, progress=True, rig=rig)
    write_reconstruction(result, args.output, overwrite=args.overwrite)
    alignment = result.report["alignment"]
    value = alignment["residual_px"]
    residual = "one view: nothing to align" if len(result.capture) == 1 else (
        "identical images: monocular mode" if alignment["mode"] == "monocular" else
        f"alignment residual {value:.2f} px" if value is not None and math.isfinite(value) else "no two views aligned")
    print(f"wrote {args.output}: {len(result.capture)} views, {result.report['points']} points, units {result.units}, "
          f"{residual}, {time.perf_counter() - start:.1f} s")
    exif = result.report.get("exif_focal", {})
    if exif.get("used") and exif.get("focal_px") is not None:
        print(f"  focal {exif['focal_px']:.0f} px from the photos' EXIF, kept (--no-exif-focal fits it)")
    elif exif.get("used"):
        focals = ", ".join(f"{name} {value:.0f}" for name, value in exif["focals_px"].items())
        print(f"  focals from the photos' EXIF, another zoom in each, kept (px: {focals}; --no-exif-focal fits one)")
    if "splat" in result.report:
        splat = result.report["splat"]
        psnr = ", ".join(f"{name} {value:.1f}" for name, value in splat["psnr_in_mask_db"].items())
        print(f"  {splat['gaussians']} Gaussians ({args.splat_preset}); PSNR in the finger mask (dB): {psnr}")
    if not result.registered:
        missing = alignment.get("not_registered")
        what = f"view(s) {', '.join(missing)} could not be registered" if missing else "the views were not registered reliably"
        print(f"fs3d fuse: {what} ({alignment['reason']}); the outputs in {args.output} hold each such view "
              "apart, with depth from its pointmap alone", file=sys.stderr)
        return EXIT_NOT_REGISTERED
    return 0
