"""Fingers of another make: a photographed skin texture on a finger shaped apart from ``fs3d synth``'s, fused blind.

    python3 tools/bench_textured.py [--texture PNG] [--seeds 8] [--first-seed 0] [--size 640x512] [--views 3] [--spread 45]
                                    [--distance 54] [--field 41.6] [--background KIND]
                                    [--crop [WIDTHS]] [--focal-given] [--pitch DEG] [--along DEG]
                                    [--front-zoom Z] [--k1 K] [--nearer MM]
                                    [--relief MM] [--specular S] [--json OUT]

Each seed draws a finger (:func:`~fingersplat3d.experiments.textured_finger.random_finger`: its section, cap, taper,
bend, pose and light), wraps the texture round it (by default another group's, IMPOSE's ``sample2_texture.png``, read
from ``../shared/data/impose-dev/`` at run time) and renders it from cameras on a ring round the finger (2 views:
-45 / 0; 3: -45 / 0 / +45; 5: -45 / -22.5 / 0 / +22.5 / +45, by default). The photos alone (no masks, cameras or depth) are fused
(geometry only) and scored against the truth: rotation error of every pair, whole-view depth MAE after scale and
shift (mm), the focal's error. ``--crop`` cuts every photo about its centre to a length along the finger, so that
neither the tip nor the crease is in frame (the principal point stays at the centre). Prints a markdown table
with the machine.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script

RINGS = {2: (-1.0, 0.0), 3: (-1.0, 0.0, 1.0), 5: (-1.0, -0.5, 0.0, 0.5, 1.0)}  # in units of --spread
SKIN_RGB = (1.15, 0.9, 0.78)
DEFAULT_TEXTURE = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "impose-dev" / "sample2_texture.png"


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give the size as WIDTHxHEIGHT, e.g. 640x512") from None
    if min(width, height) < 64:
        raise argparse.ArgumentTypeError(f"{text!r}: at least 64 px a side")
    return width, height


def _cropped(capture, widths: float):
    """Every view cut about its centre to ``widths`` of the front view's finger width along the image rows (the finger
    runs along them), the principal point moved with the cut: no tip and no crease in frame."""
    from fingersplat3d.experiments.geometry import columns_cropped
    from fingersplat3d.segment.silhouette import widest_disc

    front = capture.views[len(capture.views) // 2]
    centre = (front.width - 1) / 2.0
    half = 0.5 * widths * widest_disc(front.mask)
    return columns_cropped(capture, int(np.ceil(centre - half)), int(np.floor(centre + half)))


def _on_background(capture, kind: str, seed: int):
    """Every view's gray finger in a skin's colour (as a phone sees one) composited on a background of ``kind``, drawn
    from ``seed`` + 1000 view after view; the true masks kept."""
    from fingersplat3d.experiments.backgrounds import background, on_background
    from fingersplat3d.scene import Capture

    scenes = np.random.default_rng(seed + 1000)
    skin = np.array(SKIN_RGB, np.float32)
    return Capture(tuple(v.with_(image=on_background(np.clip(v.image[..., None] * skin, 0, 1), v.mask,
                                                     background(kind, v.image.shape, scenes)))
                         for v in capture.views), capture.metadata)


def _distorted(capture, k1: float):
    """Every view as seen through a lens with radial distortion ``x_d = x_u (1 + k1 r_u^2)`` (``r`` in units of the
    focal from the principal point; k1 < 0 barrel): images resampled bilinearly, masks and depth by the nearest pixel
    (the depth stays the undistorted ray's, where that pixel's skin is)."""
    import cv2

    from fingersplat3d.scene import Capture

    views = []
    for view in capture.views:
        K = view.camera.K
        u, v = np.meshgrid(np.arange(view.width, dtype=np.float64), np.arange(view.height, dtype=np.float64))
        x, y = (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]
        scale = np.ones_like(x)
        for _ in range(8):  # the undistorted point whose distortion lands on this pixel (fixed point)
            scale = 1.0 / (1.0 + k1 * (x * x + y * y) * scale * scale)
        map_u = (K[0, 2] + K[0, 0] * x * scale).astype(np.float32)
        map_v = (K[1, 2] + K[1, 1] * y * scale).astype(np.float32)
        image = cv2.remap(view.image, map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        mask = cv2.remap(view.mask.astype(np.uint8), map_u, map_v, cv2.INTER_NEAREST) > 0
        depth = cv2.remap(np.nan_to_num(view.depth, nan=-1.0), map_u, map_v, cv2.INTER_NEAREST)
        views.append(view.with_(image=image, mask=mask, depth=np.where(mask & (depth > 0), depth, np.nan).astype(np.float32)))
    return Capture(tuple(views), capture.metadata)


def main() -> int:
    from fingersplat3d.errors import InputError
    from fingersplat3d.experiments.geometry import score_geometry
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.experiments.backgrounds import BACKGROUNDS
    from fingersplat3d.experiments.textured_finger import (DISTANCE_MM, FIELD_MM, random_finger, skin_texture,
                                                           textured_capture)
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.scene import Capture

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--texture", type=Path, default=DEFAULT_TEXTURE, help="a finger's texture photo, tip up, on black")
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--first-seed", type=int, default=0, help="the first seed (seeds FIRST..FIRST+SEEDS-1)")
    parser.add_argument("--size", type=_size, default=(640, 512))
    parser.add_argument("--views", type=int, choices=sorted(RINGS), default=3)
    parser.add_argument("--spread", type=float, default=45.0, metavar="DEG",
                        help="the outer cameras' turn from the front one (2 views: -DEG / 0)")
    parser.add_argument("--distance", type=float, default=DISTANCE_MM, help="camera to finger, mm (the framing kept)")
    parser.add_argument("--field", type=float, default=FIELD_MM, metavar="MM",
                        help="what the image's long side holds at the finger (a phone 100 mm away: ~140)")
    parser.add_argument("--background", choices=BACKGROUNDS,
                        help="the finger composited on this background (a phone photo's), its true mask kept")
    parser.add_argument("--crop", type=float, nargs="?", const=1.0, metavar="WIDTHS",
                        help="cut every photo about its centre to WIDTHS (default 1) of the finger's width along it: "
                             "no tip, no crease (the real crops of bench_real.py --crop-tip keep 0.5-0.8)")
    parser.add_argument("--focal-given", action="store_true", help="the cameras' true focal given, as --focal-px")
    parser.add_argument("--relief", type=float, default=0.0, metavar="MM",
                        help="ridges this high (e.g. 0.08), lit from one side: a ridge's look moves with the view")
    parser.add_argument("--specular", type=float, default=0.0, help="a highlight's strength (e.g. 0.15)")
    parser.add_argument("--along", type=float, metavar="DEG",
                        help="the first camera also turned DEG along the finger and the last -0.7 DEG: the cameras' "
                             "optical axes out of one plane")
    parser.add_argument("--front-zoom", type=float, default=1.0, metavar="Z",
                        help="the front camera's focal Z times the others' (the real rig's calibration: ~0.95)")
    parser.add_argument("--k1", type=float, default=0.0,
                        help="the photos seen through a lens of this radial distortion (e.g. -0.05: barrel)")
    parser.add_argument("--nearer", type=float, default=0.0, metavar="MM",
                        help="every finger moved MM toward the front camera (negative: away), off the ring's centre")
    parser.add_argument("--pitch", type=float, metavar="DEG",
                        help="every finger pitched by DEG (odd seeds -DEG: tip toward / away from the cameras) instead "
                             "of the drawn -5..5 degrees: a finger not along the ring's axis")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if not args.texture.is_file():
        raise InputError(f"{args.texture}: no texture photo there (IMPOSE's sample2_texture.png: --texture PATH)")
    if not 1 <= args.seeds <= 100 or args.first_seed < 0 or not 20.0 <= args.distance <= 2000.0 or not 0.2 <= (args.crop or 1.0) <= 3.0 \
            or not 5.0 <= args.spread <= 80.0 or not 10.0 <= args.field <= 1000.0 \
            or not 0.0 <= args.relief <= 0.5 or not 0.0 <= args.specular <= 1.0 or not -0.5 <= args.k1 <= 0.5 \
            or not -20.0 <= args.nearer <= 20.0:
        raise InputError("--seeds must lie in 1..100, --first-seed be 0 or more, --spread in 5..80°, --field in 10..1000 mm, --distance in 20..2000 mm, "
                         "--crop in 0.2..3 widths, --relief in "
                         "0..0.5 mm, --specular in 0..1, --k1 in -0.5..0.5 and --nearer in -20..20 mm")
    texture = skin_texture(args.texture)
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        finger = random_finger(np.random.default_rng(seed))
        if args.pitch is not None:
            finger = replace(finger, pitch_deg=args.pitch * (-1) ** seed)
        shift = np.asarray(finger.offset_mm) - [0.0, 0.0, args.nearer]
        finger = replace(finger, relief_mm=args.relief, specular=args.specular, offset_mm=tuple(shift))
        capture = textured_capture(finger, texture, size=args.size,
                                   ring_deg=[args.spread * k for k in RINGS[args.views]], distance_mm=args.distance,
                                   field_mm=args.field, seed=seed,
                                   along_deg=None if args.along is None else
                                   [args.along] + [0.0] * (args.views - 2) + [-0.7 * args.along],
                                   zooms=[args.front_zoom if k == args.views // 2 else 1.0 for k in range(args.views)])
        if args.k1:
            capture = _distorted(capture, args.k1)
        if args.background is not None:
            capture = _on_background(capture, args.background, seed)
        if args.crop is not None:
            capture = _cropped(capture, args.crop)
        truth = {view.name: view for view in capture.views}
        blind = Capture(tuple(v.with_(camera=None, depth=None, mask=None) for v in capture.views), capture.metadata)
        row = {"seed": seed}
        started = time.perf_counter()
        try:
            focal = float(np.exp(np.mean([np.log(view.camera.K[0, 0]) for view in capture.views]))) if args.focal_given else None
            result = fuse(blind, FuseConfig(splat=None, focal_px=focal))
        except InputError as error:  # a capture the fuse refuses is a row, not the end of the benchmark
            rows.append({**row, "status": "failed", "reason": str(error)})
            print(f"seed {seed}: failed, {error}", file=sys.stderr, flush=True)
            continue
        true_focal = np.exp(np.mean([np.log(view.camera.K[0, 0]) for view in capture.views]))
        try:
            scores = score_geometry(result, truth)
        except ValueError:  # a view's depth nowhere on the true finger: its mask found something else
            unregistered = [n for n, ok in result.report["alignment"]["aligned"].items() if not ok]
            reason = (f"views {', '.join(unregistered)} not registered" if unregistered else "a view registered on "
                      "something else") + " (its mask missed the finger)"
            rows.append({**row, "status": "failed", "reason": reason})
            print(f"seed {seed}: failed, {reason}", file=sys.stderr, flush=True)
            continue
        row.update(scores, status="done", seconds=time.perf_counter() - started,
                   focal_error=float(result.cameras[0].K[0, 0] / true_focal - 1.0),
                   warned=bool(result.report.get("warnings")))
        rows.append(row)
        print(f"seed {seed}: {json.dumps({k: v for k, v in row.items() if k != 'seed'})}", file=sys.stderr, flush=True)
    done = [r for r in rows if r["status"] == "done"]
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores, load {info['load'][0]:.2f}. Texture {args.texture.name}; "
          f"{args.views} views on a ring ±{args.spread:g}°, {args.size[0]}x{args.size[1]}, {args.distance:g} mm, "
          f"{args.field:g} mm across{'' if args.background is None else f', on a {args.background}'}"
          f"{'' if args.crop is None else f', cropped to {args.crop:g} finger widths about the centre'}; the photos alone"
          f"{', the true focal given' if args.focal_given else ''}"
          f"{'' if args.pitch is None else f', pitched ±{args.pitch:g}°'}"
          f"{'' if args.along is None else f', the outer cameras turned {args.along:g} / {-0.7 * args.along:g}° along it'}"
          f"{'' if args.front_zoom == 1 else f', the front focal {args.front_zoom:g}x the others'}"
          f"{f', lens distortion k1 {args.k1:g}' if args.k1 else ''}"
          f"{f', {args.nearer:g} mm nearer the front camera' if args.nearer else ''}"
          f"{f', ridges {args.relief:g} mm high' if args.relief else ''}{f', highlight {args.specular:g}' if args.specular else ''}.\n")
    print("| seed | all registered | rotation median (max) ° | depth MAE (worst view) mm | skin two views see / one view "
          "alone sees mm | focal error | warned | s |\n|---|---|---|---|---|---|---|---|")
    for r in rows:
        if r["status"] != "done":
            print(f"| {r['seed']} | failed: {r['reason']} | | | | | | |")
            continue
        print(f"| {r['seed']} | {'yes' if r['registered_all'] else 'no'} | {r['rotation_error_deg']:.2f} "
              f"({r['rotation_max_deg']:.2f}) | {r['depth_mae_mm']:.3f} ({r['depth_worst_view_mm']:.3f}) | "
              f"{r['depth_two_views_mm']:.3f} / {r['depth_one_view_mm']:.3f} | "
              f"{100 * r['focal_error']:+.1f} % | {'yes' if r['warned'] else 'no'} | {r['seconds']:.1f} |")
    if done:
        print(f"| **median** | {sum(r['registered_all'] for r in done)}/{len(rows)} | "
              f"**{np.median([r['rotation_error_deg'] for r in done]):.2f}** "
              f"({max(r['rotation_max_deg'] for r in done):.2f}) | "
              f"**{np.median([r['depth_mae_mm'] for r in done]):.3f}** "
              f"({max(r['depth_worst_view_mm'] for r in done):.3f}) | "
              f"{np.nanmedian([r['depth_two_views_mm'] for r in done]):.3f} / "
              f"{np.nanmedian([r['depth_one_view_mm'] for r in done]):.3f} | "
              f"{100 * np.median([abs(r['focal_error']) for r in done]):.1f} % (abs) | "
              f"{sum(r['warned'] for r in done)} | |")
    if args.json:
        args.json.write_text(json.dumps({"machine": info, "args": {k: str(v) for k, v in vars(args).items()},
                                         "rows": rows}, indent=1))
    return 0 if len(done) == len(rows) else 4


if __name__ == "__main__":
    sys.exit(run_script(main))
