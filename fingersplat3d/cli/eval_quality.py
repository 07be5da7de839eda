"""``fs3d eval quality``: leave-one-view-out renders against the photos."""
from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from ..atomic import atomic_dir, check_free
from .common import finished, named_captures, nbis_needed
from .types import STEPS

__all__ = ["add", "run"]

NAME = "quality"
HELP = "leave-one-view-out renders against the real views: PSNR, SSIM, NFIQ2"


def add(actions) -> None:
    from ..splat.config import PRESETS

    quality = actions.add_parser(
        NAME, help=HELP,
        description="Register every view of each capture, then for each view fit Gaussians to the other views only, "
                    "render the left-out view at its camera (placed, and aligned to the photo with the model frozen) "
                    "and score it against the photo inside the finger mask: PSNR, SSIM, and NFIQ2 of the photo and "
                    "of the render as contact-like prints; the PSNR also apart on the skin the fitted views saw and on "
                    "the skin none of them saw, which the model completes with a guess (columns psnr_seen, "
                    "psnr_unseen, unseen_share). Writes quality.csv, views/ and summary.md.")
    quality.add_argument("inputs", nargs="+", type=Path,
                         help="capture folders, folders of UWA / CFPose images, or image files of one capture")
    quality.add_argument("--splat-preset", choices=sorted(PRESETS), default="fast",
                         help="Gaussian fit preset for the left-out fits (default fast)")
    quality.add_argument("--splat-iterations", type=STEPS, help="override the preset's optimisation steps")
    quality.add_argument("--no-nfiq2", action="store_true", help="PSNR and SSIM only")
    quality.add_argument("--device", default="auto", help="where the fits run: auto (CUDA when available), cpu, cuda")
    quality.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    quality.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    quality.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if not args.no_nfiq2:
        nbis_needed("fs3d eval quality (or give --no-nfiq2)")
    check_free(args.output, args.overwrite)
    captures = named_captures(args.inputs)  # a wrong path is said before torch loads (~2 s)
    from ..experiments.quality import run_quality_evaluation
    from ..pipeline import FuseConfig
    from ..splat.config import preset

    config = FuseConfig(splat=preset(args.splat_preset, iterations=args.splat_iterations), device=args.device)
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        rows = run_quality_evaluation(captures, folder, config, nfiq2=not args.no_nfiq2)
    done = [r for r in rows if r["status"] == "done"]
    if done:
        print(f"{len(done)} views: mean PSNR {statistics.mean(r['psnr'] for r in done):.2f} dB, "
              f"SSIM {statistics.mean(r['ssim'] for r in done):.3f} (aligned)")
    print(f"wrote {args.output}")
    return finished("fs3d eval quality", len(rows) - len(done), len(rows), "views could not be scored", args.output)
