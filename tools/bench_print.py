"""Rolled-equivalent prints of synthetic fingers against their true rolled prints (issue 23's targets).

    python3 tools/bench_print.py [--seeds 0 1 2 3 4] [--rig uwa] [--size 1280x1024] [--scale truth|ridge]
                                 [--enhance gabor|snfen|gbfen] [--minutiae mindtct|leader] [--work FOLDER]

Per seed: ``fs3d synth`` (three views at -45/0/+45 degrees on the uwa rig), a geometry-only fuse of the
photos alone (no cameras; with the photos' true pixels per mm at the finger when ``--scale truth``, as a
calibrated rig knows it, else the print is scaled by the ridge period), ``fs3d print`` of the
reconstruction, then against the finger's true ``rolled_print.png``: the share of true minutiae inside the
print that mindtct (or LEADER, ``--minutiae leader``) finds within 8 px after a similarity fit, and those the print's geometry alone puts within 8 px
(*placed*: carried through its map of 3D points; :mod:`fingersplat3d.eval.rolled_truth`),
bozorth3 against its own true print (genuine) and the other seeds' (impostor), the coverage in degrees
of roll, NFIQ2, and the print's time. Prints a markdown table; ``--out`` keeps the prints.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script


def main() -> int:
    from fingersplat3d.eval.contact import ContactImage
    from fingersplat3d.eval.fingerprint import MINUTIAE_EXTRACTORS, analyse, match_score
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.eval.rolled_truth import START_PEAKS, located_minutiae, template_shift
    from fingersplat3d.io.capture import read_capture, write_capture
    from fingersplat3d.pipeline import FuseConfig, fuse, write_reconstruction
    from fingersplat3d.prints.make import nfiq2_region, print_reconstruction
    from fingersplat3d.scene import Capture
    from fingersplat3d.synth import SynthConfig, synthesize

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    parser.add_argument("--rig", default="uwa")
    parser.add_argument("--size", default="1280x1024")
    parser.add_argument("--scale", choices=("truth", "ridge"), default="truth")
    parser.add_argument("--out", type=Path, help="folder to keep the prints in")
    parser.add_argument("--enhance", default="gabor", help="the print's enhancer: gabor (default), or pyfing's snfen / gbfen")
    parser.add_argument("--minutiae", choices=MINUTIAE_EXTRACTORS, default="mindtct",
                        help="the minutiae located and compared by bozorth3 (on the print and the true print alike)")
    parser.add_argument("--work", type=Path, help="folder to keep captures and reconstructions in, and reuse")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    info = machine()
    rows, truths, prints = [], {}, {}
    with tempfile.TemporaryDirectory() as scratch:
        work = args.work or Path(scratch)
        for seed in args.seeds:
            synth = synthesize(seed, SynthConfig(rig=args.rig, size=size))
            folder = work / f"{args.rig}-{args.size}-capture{seed}"
            reconstruction = work / f"{args.rig}-{args.size}-{args.scale}-rec{seed}"
            if not reconstruction.is_dir():
                write_capture(synth.capture, folder, minutiae=synth.minutiae, rolled_print=synth.rolled.image, overwrite=True)
                capture = read_capture(folder)
                blind = Capture(tuple(v.with_(camera=None, depth=None) for v in capture.views), capture.metadata)
                px_per_mm = float(np.median([v.camera.K[0, 0] / np.nanmedian(v.depth) for v in capture.views]))
                config = FuseConfig(splat=None, px_per_mm=px_per_mm if args.scale == "truth" else None)
                write_reconstruction(fuse(blind, config), reconstruction)
            started = time.perf_counter()
            result, scale_from, _ = print_reconstruction(reconstruction, enhancer=args.enhance)
            seconds = time.perf_counter() - started
            found = analyse(ContactImage.of_print(result.image, result.period_px), nfiq2=False, extractor=args.minutiae)
            quality = analyse(ContactImage.of_print(nfiq2_region(result.image, result.origin_px[0]), 9.0)).nfiq2
            rolled = synth.rolled
            truth = analyse(ContactImage.of_print(rolled.image, 9.0), nfiq2=False, extractor=args.minutiae)
            true_xy = np.array([m["xy"] for m in rolled.minutiae]).reshape(-1, 2)
            true_deg = np.array([m["angle_deg"] for m in rolled.minutiae])
            half_width_px = rolled.image.shape[1] / 2.0
            shift = template_shift(result.image, rolled.image, count=START_PEAKS)
            if shift is None:
                shift = np.array(result.origin_px) - np.array([half_width_px, 0.0])
            score = located_minutiae(true_xy, true_deg, found.minutiae[:, :2], found.minutiae[:, 2], result.mask, shift)
            placed = _placed(synth, reconstruction, result)
            truths[seed], prints[seed] = truth, found
            rows.append({"seed": seed, "located": score.located_share, "placed": placed.located_share,
                         "inside": score.inside, "scale": score.scale, "turn": score.turn_deg,
                         "residual": score.residual_px, "coverage": result.coverage_deg,
                         "nfiq2": quality, "found": found.count, "seconds": seconds, "scale_from": scale_from})
            if args.out:
                args.out.mkdir(parents=True, exist_ok=True)
                import cv2
                cv2.imwrite(str(args.out / f"print{seed}.png"), result.image)
                cv2.imwrite(str(args.out / f"truth{seed}.png"), rolled.image)
            print(f"seed {seed}: {rows[-1]}", file=sys.stderr, flush=True)
    for row in rows:
        row["genuine"] = match_score(prints[row["seed"]], truths[row["seed"]])
        row["impostors"] = [match_score(prints[row["seed"]], truths[s]) for s in truths if s != row["seed"]]
        row["impostor"] = max(row["impostors"], default=0)
    print(f"Machine: {info['cpu']}, {info['cores']} cores; {args.rig} rig {args.size}, scale from {args.scale}; "
          f"enhancer {args.enhance}; minutiae {args.minutiae}.\n")
    print("| seed | true minutiae inside | located within 8 px | placed within 8 px | fit scale | bozorth3 genuine "
          "| bozorth3 impostor (max) | coverage ° | NFIQ2 | minutiae found | print s |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['seed']} | {r['inside']} | {100 * r['located']:.0f} % | {100 * r['placed']:.0f} % "
              f"| {r['scale']:.3f} "
              f"| {r['genuine']} | {r['impostor']} | {r['coverage']:.0f} "
              f"| {r['nfiq2'] if r['nfiq2'] is None else round(r['nfiq2'])} | {r['found']} | {r['seconds']:.1f} |")
    median = lambda key: float(np.median([r[key] for r in rows]))  # noqa: E731
    impostors = [score for r in rows for score in r["impostors"]]
    print(f"| median | {median('inside'):.0f} | {100 * median('located'):.0f} % | {100 * median('placed'):.0f} % "
          f"| {median('scale'):.3f} | {median('genuine'):.0f} "
          f"| {float(np.median(impostors)) if impostors else float('nan'):.0f} (all {len(impostors)}) "
          f"| {median('coverage'):.0f} | | | {median('seconds'):.1f} |")
    return 0


def _placed(synth, reconstruction: Path, result):
    """The print's geometry against the truth (``placed_minutiae``): the true minutiae carried into the model's frame by
    the similarity between its cameras and the true ones."""
    from fingersplat3d.eval.poses import world_similarity
    from fingersplat3d.eval.rolled_truth import placed_minutiae
    from fingersplat3d.io.cameras import read_cameras

    model = read_cameras(reconstruction / "cameras.json").cameras
    names = [view.name for view in synth.capture.views if view.name in model]
    to_truth = world_similarity([model[name].world_to_cam for name in names],
                                [synth.capture[name].camera.world_to_cam for name in names])
    xy = {m["id"]: m["xy"] for m in synth.rolled.minutiae}
    both = [m for m in synth.minutiae["minutiae_3d"] if m["id"] in xy]
    true_xyz = to_truth.inverse().apply(np.array([m["xyz"] for m in both]).reshape(-1, 3))
    true_xy = np.array([xy[m["id"]] for m in both]).reshape(-1, 2)
    return placed_minutiae(result.points, result.mask, true_xyz, true_xy, max_gap=1.0 / to_truth.scale)  # 1 mm


if __name__ == "__main__":
    sys.exit(run_script(main))
