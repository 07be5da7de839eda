"""A finger that fills the frame across its width (a dataset's or a phone's tight crop): the masks of the real dev views
cut that way, on their dark background and composited onto each of
:data:`~fingersplat3d.experiments.backgrounds.BACKGROUNDS`.

    python3 tools/bench_filled_frame.py [--real ../shared/data/uwa-real-dev] [--every 4] [--across 0.6 0.8 1.0]

Each view (frames 0-2 of every capture, every ``--every``-th) is cut by
:func:`~fingersplat3d.experiments.real_crops.filling_window` to ``--across`` times the finger's width (both flanks cut
under 1), from 0.3 widths past the tip to 1.6 behind it; its true mask is the whole view's dark-background mask cut
the same way. Per background and width: mask IoU median (min) and the seconds per view. A markdown table.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script

DEFAULT_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "uwa-real-dev"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--real", type=Path, default=DEFAULT_REAL, help="the real dev captures' folder")
    parser.add_argument("--every", type=int, default=4, help="every this many-th view of the folder")
    parser.add_argument("--across", type=float, nargs="+", default=[0.6, 0.8, 1.0],
                        help="the crop's height across the finger, in finger widths")
    args = parser.parse_args(argv)
    from fingersplat3d.experiments.backgrounds import BACKGROUNDS, background, on_background
    from fingersplat3d.experiments.real_crops import filling_window
    from fingersplat3d.io.images import read_image
    from fingersplat3d.segment.masks import finger_mask, mask_iou

    paths = sorted(args.real.glob("*_[012].jpg"))[::args.every]
    if not paths:
        print(f"no real dev views in {args.real}", file=sys.stderr)
        return 2
    kinds = ("dark",) + BACKGROUNDS
    ious: dict = {}
    seconds: dict = {}
    for index, path in enumerate(paths):
        image = read_image(path)
        whole = finger_mask(image, name=path.name)
        for kind_index, kind in enumerate(kinds):
            rng = np.random.default_rng([index, kind_index])
            photo = image if kind == "dark" else on_background(image, whole, background(kind, image.shape, rng))
            for across in args.across:
                window = filling_window(whole, across)
                start = time.perf_counter()
                try:
                    found = finger_mask(photo[window], name=path.name)
                    iou = mask_iou(found, whole[window])
                except Exception as error:  # noqa: BLE001 - a view with no finger found is a row's failure
                    print(f"  {path.name} {kind} {across}: {error}", file=sys.stderr)
                    iou = 0.0
                ious.setdefault((kind, across), []).append(iou)
                seconds.setdefault((kind, across), []).append(time.perf_counter() - start)
        print(f"{index + 1}/{len(paths)} {path.name}", file=sys.stderr, flush=True)
    print(f"{len(paths)} real dev views, IoU median (min), seconds a view median\n")
    print("| background | " + " | ".join(f"{a:g} of the width" for a in args.across) + " |")
    print("|---|" + "---|" * len(args.across))
    for kind in kinds:
        cells = [f"{np.median(ious[kind, a]):.3f} ({min(ious[kind, a]):.3f}), {np.median(seconds[kind, a]):.1f} s"
                 for a in args.across]
        print(f"| {kind} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    run_script(main)
