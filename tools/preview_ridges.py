"""Save a PNG of the three ridge-pattern classes side by side, with their ground truth drawn.

    python tools/preview_ridges.py [--seed 0] [--out /tmp/ridges_preview.png] [--zoom 1.5]

Ridges are white. Ridge endings are red dots and bifurcations blue dots, each with a tick along
its angle (pointing away from the stem); cores are green circles, deltas magenta triangles.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from fingersplat3d.errors import run_script
from fingersplat3d.synth.ridges import BIFURCATION, PATTERN_CLASSES, RidgePattern, make_ridge_pattern

ENDING_BGR, BIFURCATION_BGR = (40, 40, 230), (230, 120, 20)
CORE_BGR, DELTA_BGR = (30, 170, 30), (200, 40, 200)


def render_panel(pattern: RidgePattern, zoom: float, title: str) -> np.ndarray:
    """The ridge field as a BGR image ([H*zoom, W*zoom, 3] uint8) with the ground truth on top."""
    gray = np.round((pattern.ridges + 1.0) * 127.5).astype(np.uint8)
    gray = cv2.resize(gray, None, fx=zoom, fy=zoom, interpolation=cv2.INTER_LINEAR)
    image = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
    scale = zoom / pattern.spacing_mm  # pixels per mm

    def to_px(a_mm: float, b_mm: float) -> tuple[int, int]:
        return int(round((b_mm + pattern.half_width_mm) * scale)), int(round(a_mm * scale))

    tick = 1.2 * pattern.period_mm
    for a, b, angle, kind in pattern.minutiae:
        colour = BIFURCATION_BGR if kind == BIFURCATION else ENDING_BGR
        start = to_px(a, b)
        end = to_px(a + tick * np.cos(angle), b + tick * np.sin(angle))
        cv2.line(image, start, end, colour, 2, cv2.LINE_AA)
        cv2.circle(image, start, 3, colour, -1, cv2.LINE_AA)
    for a, b in pattern.cores:
        cv2.circle(image, to_px(a, b), 9, CORE_BGR, 2, cv2.LINE_AA)
    for a, b in pattern.deltas:
        x, y = to_px(a, b)
        triangle = np.array([[x, y - 10], [x - 9, y + 7], [x + 9, y + 7]], np.int32)
        cv2.polylines(image, [triangle], True, DELTA_BGR, 2, cv2.LINE_AA)
    banner = np.full((28, image.shape[1], 3), 255, np.uint8)
    cv2.putText(banner, title, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([banner, image])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("/tmp/ridges_preview.png"))
    parser.add_argument("--zoom", type=float, default=1.5, help="display pixels per grid cell")
    parser.add_argument("--length", type=float, default=26.0, help="length_mm")
    parser.add_argument("--half-width", type=float, default=15.0, help="half_width_mm")
    parser.add_argument("--period", type=float, default=0.45, help="period_mm")
    args = parser.parse_args()

    panels = []
    for pattern_class in PATTERN_CLASSES:
        start = time.perf_counter()
        pattern = make_ridge_pattern(np.random.default_rng(args.seed), args.length, args.half_width,
                                     period_mm=args.period, pattern_class=pattern_class)
        seconds = time.perf_counter() - start
        kinds = pattern.minutiae[:, 3]
        title = (f"{pattern_class}  seed {args.seed}: {int((kinds == 0).sum())} endings, "
                 f"{int((kinds == 1).sum())} bifurcations  ({seconds:.2f} s)")
        print(title)
        panels.append(render_panel(pattern, args.zoom, title))
    gap = np.full((panels[0].shape[0], 12, 3), 255, np.uint8)
    sheet = np.hstack([panels[0], gap, panels[1], gap, panels[2]])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(args.out), sheet):
        raise SystemExit(f"{args.out}: could not write the PNG")
    print(f"wrote {args.out} ({sheet.shape[1]}x{sheet.shape[0]})")


if __name__ == "__main__":
    sys.exit(run_script(main))
