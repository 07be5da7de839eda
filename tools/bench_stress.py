"""A generalisation sweep: fingers of another make under settings drawn at random, several stressors at once.

    python3 tools/bench_stress.py [--count 28] [--seed 1] [--fingers 2] [--jobs 2] [--size 640x512] [--json OUT]
                                  [--picture PNG]

Draws ``--count`` settings (:func:`fingersplat3d.experiments.stress.draw_settings`: views, spread, distance, pitch,
crop, lens distortion, the finger off centre, ridges in relief with a highlight, the front camera zoomed, a phone's
background, the focal given or fitted) and fuses ``--fingers`` fingers under each with ``tools/bench_textured.py`` (its
own process, the photos alone, geometry only). Prints each setting's row and the summary by kind of capture
(:func:`~fingersplat3d.experiments.stress.sweep_summary`), with the machine; ``--picture``: every capture by its worst
pair's turn error and its depth error, warned or not. ``--jobs 2`` runs two settings side by side, each on one thread.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from bench_textured import _size
from fingersplat3d.errors import run_script

TEXTURED = Path(__file__).resolve().with_name("bench_textured.py")


def _run(setting, fingers: int, size: str, jobs: int, scratch: Path, index: int) -> list[dict]:
    out = scratch / f"setting_{index}.json"
    env = dict(os.environ, **({"FS3D_THREADS": "1"} if jobs > 1 else {}))
    proc = subprocess.run([sys.executable, str(TEXTURED), *setting.arguments(fingers), "--size", size, "--json", str(out)],
                          capture_output=True, text=True, env=env)
    if not out.is_file():  # exit 4 (a finger failed) still writes its rows; anything else did not run
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return [{"seed": setting.first_seed + k, "status": "failed", "reason": f"bench_textured.py exit {proc.returncode}: {last}"}
                for k in range(fingers)]
    return json.loads(out.read_text())["rows"]


def main() -> int:
    from fingersplat3d.errors import InputError
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.experiments.plots import sweep_picture
    from fingersplat3d.experiments.stress import (DEPTH_TARGET_MM, WARN_ABOVE_DEG, draw_settings, sweep_points,
                                                  sweep_summary)
    from tqdm import tqdm

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=28, help="settings drawn (default 28)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the draw (default 1)")
    parser.add_argument("--fingers", type=int, default=2, help="fingers fused under each setting (default 2)")
    parser.add_argument("--jobs", type=int, default=2, help="settings run side by side (default 2)")
    parser.add_argument("--size", default="640x512", help="photo size WIDTHxHEIGHT (default 640x512)")
    parser.add_argument("--json", type=Path, help="write every setting and row here")
    parser.add_argument("--picture", type=Path, help="draw every capture's turn and depth errors here (PNG)")
    args = parser.parse_args()
    if not 1 <= args.count <= 1000 or not 1 <= args.fingers <= 20 or not 1 <= args.jobs <= 16:
        raise InputError("--count must lie in 1..1000, --fingers in 1..20 and --jobs in 1..16")
    try:
        _size(args.size)  # bench_textured.py's own reading of it, before any fuse runs
    except argparse.ArgumentTypeError as error:
        raise InputError(f"--size {error}") from None
    settings = draw_settings(args.seed, args.count)
    with tempfile.TemporaryDirectory() as scratch, ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(_run, s, args.fingers, args.size, args.jobs, Path(scratch), i) for i, s in enumerate(settings)]
        results = [future.result() for future in tqdm(futures, desc="stress", unit="setting")]
    records = [(setting, row) for setting, rows in zip(settings, results) for row in rows]
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores, load {info['load'][0]:.2f}. {args.count} settings drawn "
          f"from seed {args.seed}, {args.fingers} fingers each, {args.size}; the photos alone, geometry only.\n")
    print("| setting | finger | registered | worst pair ° | depth mm | focal error | warned |\n|---|---|---|---|---|---|---|")
    for setting, row in records:
        if row.get("status") != "done":
            print(f"| {setting.label()} | {row['seed']} | failed: {row.get('reason', '')} | | | | |")
            continue
        print(f"| {setting.label()} | {row['seed']} | {'yes' if row['registered_all'] else 'no'} | "
              f"{row['rotation_max_deg']:.2f} | {row['depth_mae_mm']:.3f} | {100 * row['focal_error']:+.1f} % | "
              f"{'yes' if row['warned'] else 'no'} |")
    print(f"\n| kind | fuses | failed | all registered | worst pair median (max) ° | within 1° / {WARN_ABOVE_DEG:g}° | "
          f"depth median (max) mm | depth ≤ {DEPTH_TARGET_MM:g} mm | over {WARN_ABOVE_DEG:g}° unwarned |\n"
          "|---|---|---|---|---|---|---|---|---|")
    summary = sweep_summary(records)
    for s in summary:
        print(f"| {s['kind']} | {s['fuses']} | {s['failed']} | {s['registered_all']} | {s['worst_pair_median_deg']:.2f} "
              f"({s['worst_pair_max_deg']:.2f}) | {s['within_1_deg']} / {s['within_2_deg']} | {s['depth_median_mm']:.3f} "
              f"({s['depth_max_mm']:.3f}) | {s['depth_within_target']} | **{s['off_unwarned']}** |")
    if args.picture:
        sweep_picture(args.picture, sweep_points(records), WARN_ABOVE_DEG, DEPTH_TARGET_MM,
                      f"{args.count} settings drawn at random, {args.fingers} fingers each (bench_stress.py --seed {args.seed})",
                      f"{info['cpu']}, {info['cores']} cores; {args.size}; fingers of another make, the photos alone")
    if args.json:
        args.json.write_text(json.dumps({"machine": info, "args": {k: str(v) for k, v in vars(args).items()},
                                         "records": [{"setting": vars(s), "row": r} for s, r in records],
                                         "summary": summary}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
