"""``fs3d synth``: synthetic 3D fingers photographed by a rig, with exact ground truth."""
from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

from ..atomic import check_free
from .types import COUNT, POSITIVE, SEED, angles, number, size

DISTANCE = number(float, 30.0, 2000.0)

__all__ = ["add", "run"]

NAME = "synth"
HELP = "generate synthetic 3D fingers photographed by a rig, with exact ground truth"


def add(commands) -> None:
    """``fs3d synth``: its arguments."""
    from ..synth.rigs import CAMERA_DISTANCE_MM
    from ..synth.shape import SHAPES

    synth = commands.add_parser(
        NAME, help=HELP,
        description="Generate procedural 3D fingertips with fingerprint ridges and photograph them with a "
                    "capture rig. Writes one capture folder per finger: images/, masks/, depth/ (camera-frame "
                    "z in mm), cameras.json, minutiae.json (3D, per-view pixels and on the rolled print), mesh.ply, "
                    "rolled_print.png (the true rolled print, 500 ppi), manifest.json. "
                    "Deterministic in --seed.")
    synth.add_argument("output", type=Path, help="capture folder to write (with --count > 1: a parent folder)")
    synth.add_argument("--rig", default="uwa", choices=("uwa", "cfpose", "ring"),
                       help="uwa: 3 cameras at -45/0/+45 deg, finger horizontal, gray 1280x1024; "
                            "cfpose: one camera, finger rolled/pitched per shot, RGB 1024x1280; "
                            "ring: cameras at --angles (default: uwa)")
    synth.add_argument("--seed", type=SEED, default=0, help="random seed of the first finger (default 0)")
    synth.add_argument("--count", type=COUNT, default=1, help="number of fingers (seeds seed..seed+count-1)")
    synth.add_argument("--size", type=size, help="image size WxH (default: the rig's)")
    synth.add_argument("--focal", type=POSITIVE, help="focal length in pixels (default: ~36 mm of finger across the long side)")
    synth.add_argument("--distance-mm", type=DISTANCE, default=CAMERA_DISTANCE_MM,
                       help=f"camera to finger in mm, the framing kept (default {CAMERA_DISTANCE_MM:g}; 50: a wide-angle "
                            "close-up like a phone's, 400: nearly orthographic)")
    synth.add_argument("--angles", type=angles, help="ring rig: camera angles in degrees around the finger axis, written with = when the first is negative: --angles=-60,-20,20,60")
    synth.add_argument("--poses", type=COUNT, default=10, help="cfpose rig: number of shots (default 10)")
    synth.add_argument("--shapes", default="adult", choices=SHAPES,
                       help="finger shapes: adult (human ranges, the pad a half ellipse) or wide (beyond them: pads "
                            "flatter or more pointed than an ellipse, deeper or flatter sections, stronger bends and tapers)")
    synth.add_argument("--pattern", default="random", choices=("random", "arch", "loop", "whorl"), help="fingerprint class")
    colour = synth.add_mutually_exclusive_group()
    colour.add_argument("--rgb", dest="gray", action="store_false", default=None, help="colour images")
    colour.add_argument("--gray", dest="gray", action="store_true", help="grayscale images")
    synth.add_argument("--bits", type=int, default=8, choices=(8, 16), help="image bit depth (default 8)")
    synth.add_argument("--no-noise", action="store_true", help="no sensor noise and no blur")
    synth.add_argument("--specular", type=float, help="highlight strength (default 0.12; 0 = matte)")
    synth.add_argument("--overwrite", action="store_true", help="replace existing output folders")
    synth.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ..io.capture import write_capture
    from ..synth import Appearance, SynthConfig, synthesize

    appearance = Appearance()
    if args.no_noise:
        appearance = replace(appearance, noise=0.0, blur_px=0.0)
    if args.specular is not None:
        appearance = replace(appearance, specular=args.specular)
    config = SynthConfig(rig=args.rig, size=args.size, focal=args.focal, angles=args.angles, poses=args.poses,
                         pattern=args.pattern, appearance=appearance, gray=args.gray, distance_mm=args.distance_mm,
                         shapes=args.shapes)
    seeds = range(args.seed, args.seed + args.count)
    targets = [args.output] if args.count == 1 else [args.output / f"{args.rig}_{seed:05d}" for seed in seeds]
    for target in targets:
        check_free(target, args.overwrite)
    progress = tqdm(list(zip(seeds, targets)), desc="fs3d synth", unit="finger", disable=None if args.count == 1 else False)  # one finger: only on a terminal
    for seed, target in progress:
        start = time.perf_counter()
        result = synthesize(seed, config)
        write_capture(result.capture, target, minutiae=result.minutiae, mesh=result.surface.to_open3d(),
                      rolled_print=result.rolled.image, overwrite=args.overwrite, image_bits=args.bits,
                      extra_manifest={"timing_s": {**result.seconds, "total": time.perf_counter() - start}})
        if args.count == 1:
            visible = {name: sum(m["visible"] for m in entries) for name, entries in result.minutiae["views"].items()}
            print(f"wrote {target}: {len(result.capture)} views, {result.capture.metadata['pattern_class']}, "
                  f"{len(result.minutiae['minutiae_3d'])} minutiae (visible per view: {visible}) "
                  f"in {time.perf_counter() - start:.1f} s")
    return 0
