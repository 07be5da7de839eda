"""Fingers lit from one side: masks, rotation and depth when the skin darkens toward one flank.

    python3 tools/bench_lighting.py [--seeds 3] [--low 1,0.3,0.15]

Per seed, a uwa capture (640x512, three views) has every view's skin dimmed across the finger, from 1 on one flank to
``low`` on the other (the background as it was), then is fused from the images alone (geometry only). Prints, per
setting, each view's mask IoU against the true mask and the rotation and depth errors
(:func:`~fingersplat3d.experiments.geometry.score_geometry`), with the machine.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from fingersplat3d.errors import run_script


def shaded(view, low: float) -> np.ndarray:
    """The view's image with its skin dimmed across the finger (image rows) from 1 to ``low``."""
    rows = np.nonzero(view.mask.any(1))[0]
    ramp = np.clip((np.arange(view.height) - rows.min()) / max(np.ptp(rows), 1), 0, 1)
    gain = np.where(view.mask, (low + (1 - low) * ramp)[:, None], 1.0)
    return (view.image * (gain if view.image.ndim == 2 else gain[..., None])).astype(np.float32)


def main() -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.experiments.geometry import score_geometry
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.scene import Capture, View
    from fingersplat3d.segment import finger_mask, mask_iou
    from fingersplat3d.synth import SynthConfig, synthesize

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--low", default="1,0.3,0.15", help="the far flank's brightness, as shares of the lit one's")
    args = parser.parse_args()
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores; geometry only.\n")
    print("| far flank | seed | mask IoU per view | rotation ° (max) | depth MAE mm (worst view) |\n|---|---|---|---|---|")
    for low in (float(x) for x in args.low.split(",")):
        for seed in range(args.seeds):
            truth = synthesize(seed, SynthConfig(size=(640, 512))).capture
            images = [shaded(view, low) for view in truth.views]
            ious = [mask_iou(finger_mask(image), view.mask) for image, view in zip(images, truth.views)]
            result = fuse(Capture(tuple(View(v.name, image) for v, image in zip(truth.views, images)), {}),
                          FuseConfig(splat=None))
            score = score_geometry(result, {view.name: view for view in truth.views})
            print(f"| {low:g} | {seed} | {' / '.join(f'{iou:.3f}' for iou in ious)} | {score['rotation_error_deg']:.2f} "
                  f"({score['rotation_max_deg']:.2f}) | {score['depth_mae_mm']:.3f} ({score['depth_worst_view_mm']:.3f}) |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
