"""Contactless against contact on synthetic fingers: photos and rolled-equivalent prints against true rolled prints.

    python3 tools/bench_contact.py [--seeds 0 1 ... 9] [--work DIR] [--flat] [--inked] [--zoom F] [--gallery-as-is]
                                   [--mirror auto|yes|no]

Per seed: an ``fs3d synth`` finger on the uwa rig (1280x1024), its three photos renamed in the UWA naming
(finger ``<seed>_1``, frame 0 the front camera), a geometry-only fuse of the photos alone (no cameras, no
scale: prints are scaled by the ridge period, as a phone user's would be), and its true rolled print in a
gallery named by finger. Then ``fs3d eval match`` with ``--gallery`` and ``--rolled``: the front photos'
contact-like prints (unrolled through the surface their silhouettes give; ``--flat``: scaled and turned alone)
and the models' rolled prints against every finger's true rolled print (genuine: the
same finger). Prints the summary table.
"""
from __future__ import annotations

import argparse
import csv
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script

FRAMES = {"center": 0, "left": 1, "right": 2}


def main() -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.experiments.match import (MIRROR_CHOICES, parse_samples, read_gallery, run_match_evaluation,
                                                 summary_markdown)
    from fingersplat3d.io.capture import write_capture
    from fingersplat3d.io.images import read_image, write_image
    from fingersplat3d.sampling import resized_image
    from fingersplat3d.io.datasets import load_any
    from fingersplat3d.pipeline import FuseConfig, fuse, write_reconstruction
    from fingersplat3d.synth import SynthConfig, synthesize

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    parser.add_argument("--work", type=Path, help="folder to keep captures and reconstructions in, and reuse")
    parser.add_argument("--flat", action="store_true", help="the photos' prints scaled and turned, not unrolled")
    parser.add_argument("--inked", action="store_true",
                        help="the gallery's prints mirrored left-right, as inked or live-scan contact prints are of a "
                             "photo of the pad (the true rolled prints keep a photo's handedness)")
    parser.add_argument("--zoom", type=float, default=1.0,
                        help="the gallery's prints resized by this factor: fingers whose ridges are finer or coarser "
                             "than the probes' 9 px a ridge, or prints scanned at another resolution")
    parser.add_argument("--gallery-as-is", action="store_true",
                        help="the gallery compared at its own scale (fs3d eval match --gallery-as-is)")
    parser.add_argument("--mirror", choices=MIRROR_CHOICES, default="auto",
                        help="how the probes are turned for the gallery (fs3d eval match: auto, --mirror, --no-mirror)")
    args = parser.parse_args()
    info = machine()
    with tempfile.TemporaryDirectory() as scratch:
        work = args.work or Path(scratch)
        probes, gallery, reconstructions = work / "contact-probes", work / "contact-gallery", []
        probes.mkdir(parents=True, exist_ok=True)
        gallery.mkdir(exist_ok=True)
        for seed in args.seeds:
            finger = f"{seed}_1"
            rec = work / f"contact-rec-{finger}"
            files = [probes / f"{finger}_1_1_{frame}.png" for frame in FRAMES.values()]
            if not rec.is_dir():
                synth = synthesize(seed, SynthConfig(rig="uwa"))
                capture_folder = work / f"contact-capture-{finger}"
                write_capture(synth.capture, capture_folder, minutiae=synth.minutiae, rolled_print=synth.rolled.image,
                              overwrite=True)
                for name, frame in FRAMES.items():
                    shutil.copy(capture_folder / "images" / f"{name}.png", probes / f"{finger}_1_1_{frame}.png")
                shutil.copy(capture_folder / "rolled_print.png", gallery / f"{finger}.png")
                write_reconstruction(fuse(load_any(files)[0], FuseConfig(splat=None)), rec)
            reconstructions.append(rec)
        if args.inked or args.zoom != 1.0:  # a copy of the gallery the other way round, or resized
            changed = work / f"contact-gallery-{'inked' if args.inked else 'as-made'}-{args.zoom:g}"
            changed.mkdir(exist_ok=True)
            for path in sorted(gallery.glob("*.png")):
                image = read_image(path)[:, ::-1] if args.inked else read_image(path)
                write_image(changed / path.name, resized_image(image, (round(image.shape[1] * args.zoom),
                                                                        round(image.shape[0] * args.zoom))))
            gallery = changed
        samples, _ = parse_samples(sorted(probes.glob("*.png")), views={"0"})
        out = Path(scratch) / "match"
        summary = run_match_evaluation(samples, out, rolled=reconstructions, gallery=read_gallery([gallery]),
                                       flat=args.flat, mirror=args.mirror,
                                       gallery_about_period=not args.gallery_as_is)
        scores = list(csv.DictReader((out / "scores.csv").open()))
        spread = []
        for protocol in ("photos vs gallery", "rolled prints vs gallery"):
            genuine = [int(r["score"]) for r in scores if r["protocol"] == protocol and r["genuine"] == "1"]
            impostor = [int(r["score"]) for r in scores if r["protocol"] == protocol and r["genuine"] == "0"]
            if genuine and impostor:
                spread.append(f"| {protocol} | {np.median(genuine):.0f} ({min(genuine)}) | {np.median(impostor):.0f} "
                              f"({max(impostor)}) |")
    print(f"Machine: {info['cpu']}, {info['cores']} cores; {len(args.seeds)} synthetic fingers, uwa rig 1280x1024; "
          f"photos' prints {'flat' if args.flat else 'unrolled'}; "
          f"gallery {'mirrored (inked)' if args.inked else 'as made'}, zoom {args.zoom:g}, "
          f"{'at its own scale' if args.gallery_as_is else 'at scales about the probes ridge period'}, "
          f"probes turned: {args.mirror}.\n")
    print(summary_markdown(summary))
    print("| protocol | genuine median (lowest) | impostor median (highest) |\n|---|---|---|")
    print("\n".join(spread))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
