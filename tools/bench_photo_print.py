"""Photos' prints against true rolled prints: the photo scaled and turned (``--flat``) or unrolled (the default).

    python3 tools/bench_photo_print.py [--seeds 0 1 ... 9] [--size 1280x1024] [--impose ../shared/data/impose-dev] [--out DIR]
                                       [--minutiae mindtct|leader]

Per seed: an ``fs3d synth`` finger on the uwa rig (``--size``, default 1280x1024); the front photo's print made both ways
(:func:`fingersplat3d.eval.contact.contact_like`, :func:`fingersplat3d.prints.make.unrolled_photo`; the photo and its
found mask alone, scaled by the ridge period) and scored against the finger's true rolled print: *placed*, the true
minutiae the photo shows, carried to the print by its map back to the photo, within 8 px of their true place after one
similarity fit (the print's geometry alone); *located*, the true minutiae inside the print that mindtct (or LEADER) finds within
8 px after one similarity fit (:mod:`fingersplat3d.eval.rolled_truth`); bozorth3 against the true print (genuine) and
the other seeds' (impostors). With ``--impose``, every render of another
group's finger (IMPOSE, nine rolls) printed both ways against its rolled print, impostors the synthetic true prints.
Prints the markdown tables of docs/measurements.md and the machine.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script

DEFAULT_IMPOSE = Path(__file__).resolve().parents[2] / "shared" / "data" / "impose-dev"
KINDS = ("flat", "unrolled")


def _prints(gray: np.ndarray, mask: np.ndarray) -> dict:
    """``{kind: (print image, skin mask, seconds, [H, W, 3] photo pixel (u, v, 0) of each print pixel, NaN off the
    skin)}`` for both kinds."""
    from fingersplat3d.eval.contact import contact_like
    from fingersplat3d.prints.make import photo_pixels, unrolled_photo

    made = {}
    started = time.perf_counter()
    flat = contact_like(gray, mask)
    seconds = time.perf_counter() - started
    made["flat"] = (flat.image, flat.image < 255, seconds, _on_photo(flat.photo_pixels(), flat.image < 255))
    started = time.perf_counter()
    unrolled, camera = unrolled_photo(gray, mask)
    seconds = time.perf_counter() - started
    made["unrolled"] = (unrolled.image, unrolled.mask, seconds, _on_photo(photo_pixels(unrolled, camera), unrolled.mask))
    return made


def _on_photo(photo_uv: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``[H, W, 3]``: ``(u, v, 0)`` per print pixel, NaN off ``mask`` (what
    :func:`~fingersplat3d.eval.rolled_truth.placed_minutiae` takes as the print's points)."""
    return np.where(mask[..., None], np.concatenate([photo_uv, np.zeros(mask.shape + (1,))], -1), np.nan)


def main() -> int:
    from fingersplat3d.align.correspond.texture import as_gray
    from fingersplat3d.eval.contact import ContactImage
    from fingersplat3d.eval.fingerprint import MINUTIAE_EXTRACTORS, analyse, match_score, nbis_available
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.eval.rolled_truth import START_PEAKS, located_minutiae, placed_minutiae, template_shift
    from fingersplat3d.io.images import read_image
    from fingersplat3d.segment.masks import finger_mask
    from fingersplat3d.synth import SynthConfig, synthesize

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    parser.add_argument("--size", default="1280x1024", help="the photos' size, WxH")
    parser.add_argument("--impose", type=Path, nargs="?", const=DEFAULT_IMPOSE, help="the IMPOSE sample's folder")
    parser.add_argument("--out", type=Path, help="folder to keep the prints in")
    parser.add_argument("--minutiae", choices=MINUTIAE_EXTRACTORS, default="mindtct",
                        help="the minutiae located and compared by bozorth3 (on every print alike)")
    args = parser.parse_args()
    if not nbis_available():
        print("bench_photo_print: needs nbis-py (mindtct, bozorth3)", file=sys.stderr)
        return 2
    if args.impose is not None and not (args.impose / "sample2_rolled.png").is_file():
        print(f"bench_photo_print: {args.impose}: no sample2_rolled.png (the IMPOSE sample's folder)", file=sys.stderr)
        return 2

    def found_in(image):
        return analyse(ContactImage.of_print(image, 9.0), nfiq2=False, extractor=args.minutiae)

    size = tuple(int(v) for v in args.size.lower().split("x"))
    truths, found, rows = {}, {kind: {} for kind in KINDS}, []
    for seed in args.seeds:
        synth = synthesize(seed, SynthConfig(rig="uwa", size=size))
        view = next(v for v in synth.capture.views if v.name == "center")
        gray = as_gray(view.image)
        made = _prints(gray, finger_mask(gray, name=f"seed {seed}"))
        rolled = synth.rolled
        truths[seed] = found_in(rolled.image)
        true_xy = np.array([m["xy"] for m in rolled.minutiae]).reshape(-1, 2)
        true_deg = np.array([m["angle_deg"] for m in rolled.minutiae])
        row = {"seed": seed}
        rolled_xy = {m["id"]: m["xy"] for m in synth.minutiae["rolled_print"]["minutiae"]}
        shown = [m for m in synth.minutiae["views"]["center"] if m["visible"] and m["id"] in rolled_xy]
        shown_uv = np.array([[*m["uv"], 0.0] for m in shown]).reshape(-1, 3)
        shown_xy = np.array([rolled_xy[m["id"]] for m in shown]).reshape(-1, 2)
        for kind, (image, mask, seconds, on_photo) in made.items():
            minutiae = found[kind][seed] = found_in(image)
            shift = template_shift(image, rolled.image, count=START_PEAKS)
            if shift is None:
                shift = np.array([image.shape[1] - rolled.image.shape[1], 0.0]) / 2.0
            score = located_minutiae(true_xy, true_deg, minutiae.minutiae[:, :2], minutiae.minutiae[:, 2], mask, shift)
            placed = placed_minutiae(on_photo, mask, shown_uv, shown_xy, max_gap=1.5)
            row[kind] = {"inside": score.inside, "located": score.located_share, "width": image.shape[1],
                         "seconds": seconds, "placed": placed.located_share, "shown": placed.inside}
            if args.out:
                import cv2

                args.out.mkdir(parents=True, exist_ok=True)
                cv2.imwrite(str(args.out / f"seed{seed}_{kind}.png"), image)
        rows.append(row)
        print(f"seed {seed}: " + ", ".join(f"{k} placed {row[k]['placed']:.0%} of {row[k]['shown']}, located "
                                           f"{row[k]['located']:.0%} of {row[k]['inside']}" for k in KINDS),
              file=sys.stderr, flush=True)
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores; uwa rig {args.size}, the front photo alone; minutiae "
          f"{args.minutiae}.\n")
    print("| seed | placed within 8 px: flat / unrolled | located within 8 px: flat / unrolled | bozorth3 genuine: flat / "
          "unrolled | print width px | s |")
    print("|---|---|---|---|---|---|")
    for row in rows:
        seed = row["seed"]
        genuine = [match_score(found[k][seed], truths[seed]) for k in KINDS]
        row["genuine"] = genuine
        print(f"| {seed} | {row['flat']['placed']:.0%} of {row['flat']['shown']} / {row['unrolled']['placed']:.0%} of "
              f"{row['unrolled']['shown']} | {row['flat']['located']:.0%} of {row['flat']['inside']} / "
              f"{row['unrolled']['located']:.0%} of "
              f"{row['unrolled']['inside']} | {genuine[0]} / {genuine[1]} | {row['flat']['width']} / "
              f"{row['unrolled']['width']} | {row['flat']['seconds']:.1f} / {row['unrolled']['seconds']:.1f} |")
    for k, kind in enumerate(KINDS):
        impostors = [match_score(found[kind][s], truths[t]) for s in truths for t in truths if s != t]
        print(f"\n{kind}: placed median {np.median([r[kind]['placed'] for r in rows]):.0%}, located median "
              f"{np.median([r[kind]['located'] for r in rows]):.0%}, genuine median "
              f"{np.median([r['genuine'][k] for r in rows]):.0f} (lowest {min(r['genuine'][k] for r in rows)}), "
              + (f"impostors median {np.median(impostors):.0f} (highest {max(impostors)}) of {len(impostors)}" if impostors
                 else "no impostors (one finger)"))
    if args.impose is not None:
        truth = found_in((255 * read_image(args.impose / "sample2_rolled.png")).round().astype(np.uint8))
        print("\n| IMPOSE render (roll °) | bozorth3 genuine: flat / unrolled | impostors (synthetic true prints), highest: "
              "flat / unrolled |")
        print("|---|---|---|")
        renders = sorted(args.impose.glob("sample2_*.png"), key=lambda p: (not p.stem[8:].lstrip("-").isdigit(), p.stem))
        for path in [p for p in renders if p.stem[8:].lstrip("-").isdigit()]:
            gray = as_gray(read_image(path))
            made = _prints(gray, finger_mask(gray, name=path.name))
            scores = {kind: found_in(made[kind][0]) for kind in KINDS}
            genuine = [match_score(scores[k], truth) for k in KINDS]
            impostor = [max([match_score(scores[k], t) for t in truths.values()], default=0) for k in KINDS]
            print(f"| {path.stem[8:]} | {genuine[0]} / {genuine[1]} | {impostor[0]} / {impostor[1]} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
