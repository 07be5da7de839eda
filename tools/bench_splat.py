"""Benchmark the Gaussian-splat stage of ``fs3d fuse`` against synthetic ground truth.

    python tools/bench_splat.py [--seeds 5] [--presets fast,balanced] [--out FILE.md] [--quick] [--bound]

For every seed, ``fs3d synth``'s generator photographs one finger with a ring of five cameras at
-45, -22.5, 0, +22.5 and +45 degrees (640x512, grayscale; the same finger and light as the ``uwa``
rig). The three uwa views (-45, 0, +45) are fused (images and ground-truth masks only, no cameras);
the two views at +-22.5 degrees are held out. Per preset (each in a fresh process, imports off the
clock) it reports:

* training views: PSNR and SSIM inside the finger mask, renders from the refined cameras;
* held-out views: the camera the tool itself would use (``cameras_at_angles(+-22.5)`` about the rig
  axis, relative to the middle camera), then aligned to the held-out photo with the model frozen
  (``fit_camera``, as pose-free 3DGS evaluations do); PSNR/SSIM inside the mask before and after;
* depth MAE (mm, scale+shift aligned inside the GT mask) of the Gaussians' rendered depth and of the
  fused geometry's depth, on the training views;
* fraction of rendered alpha outside the finger mask before and after the mask cleaning;
* Gaussians (budget, fitted, after cleaning), whole-fuse wall time and the process's peak RSS.

``--bound`` runs the same fit on exact geometry instead (ground-truth cameras, initial cloud from
the ground-truth depth, no pose refinement) and scores the held-out views at their ground-truth
cameras: what the splat stage reaches when the geometry is not the limit.
"""
from __future__ import annotations

import argparse
import json
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fingersplat3d.errors import run_script
from fingersplat3d.eval.machine import machine
from fingersplat3d.experiments.bench import HELD_OUT
from fingersplat3d.experiments.geometry import RING_VIEWS, synth_captures
from fingersplat3d.experiments.process import peak_rss_mb

TRAIN = RING_VIEWS[3]


def run_preset(preset_name: str, captures: list[str], overrides: dict) -> list[dict]:
    from fingersplat3d.eval import depth_errors
    from fingersplat3d.eval.image import masked_psnr, masked_ssim
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.scene import Capture
    from fingersplat3d.splat.camera_path import cameras_at_angles
    from fingersplat3d.splat.config import preset
    from fingersplat3d.splat.fit import fit_camera
    from fingersplat3d.splat.novel import render_views

    rows = []
    for path in captures:
        capture = pickle.loads(Path(path).read_bytes())
        views = {view.name: view for view in capture.views}
        blind = Capture(tuple(views[n].with_(camera=None, depth=None) for n in TRAIN), capture.metadata)
        config = FuseConfig(splat=preset(preset_name, **overrides))
        started, cpu = time.perf_counter(), time.process_time()
        result = fuse(blind, config)
        wall, cpu = time.perf_counter() - started, time.process_time() - cpu
        splat = result.report["splat"]
        model = result.gaussians
        row = {"capture": Path(path).stem, "wall_s": wall, "cpu_s": cpu, "gaussians": len(model),
               "budget": splat["budget"], "fitted": splat["fitted_gaussians"], "fit_s": splat["fit_seconds"],
               "alpha_outside_before": splat["alpha_outside_mask"]["before"],
               "alpha_outside_after": splat["alpha_outside_mask"]["after"]}
        train = render_views(model, [(n, c) for n, c in zip(TRAIN, result.cameras)])
        row["train_psnr"] = [masked_psnr(v.image, views[v.name].image, views[v.name].mask) for v in train]
        row["train_ssim"] = [masked_ssim(v.image, views[v.name].image, views[v.name].mask) for v in train]
        row["depth_mae_splat"] = [depth_errors(d, views[n].depth, views[n].mask).mae
                                  for n, d in zip(TRAIN, result.splat_depths)]
        row["depth_mae_fused"] = [depth_errors(d, views[n].depth, views[n].mask).mae
                                  for n, d in zip(TRAIN, result.depths)]
        held = {}
        for name, angle in HELD_OUT.items():
            target = views[name]
            placed = cameras_at_angles(result.cameras, [angle])[0]
            before = render_views(model, [(name, placed)])[0]
            aligned_camera = fit_camera(model, placed, target.image, target.mask)
            after = render_views(model, [(name, aligned_camera)])[0]
            held[name] = {"psnr_placed": masked_psnr(before.image, target.image, target.mask),
                          "ssim_placed": masked_ssim(before.image, target.image, target.mask),
                          "psnr": masked_psnr(after.image, target.image, target.mask),
                          "ssim": masked_ssim(after.image, target.image, target.mask)}
        row["held_out"] = held
        row["peak_rss_mb"] = peak_rss_mb()
        rows.append(row)
        print(json.dumps({k: v for k, v in row.items()}, default=float), file=sys.stderr, flush=True)
    return rows


def run_bound(preset_name: str, captures: list[str], overrides: dict) -> list[dict]:
    """The same fit on exact geometry: ground-truth cameras and a cloud from ground-truth depth."""
    import numpy as np
    import open3d as o3d

    from fingersplat3d.eval.image import masked_psnr, masked_ssim
    from fingersplat3d.geometry import points_to_cloud
    from fingersplat3d.splat.config import preset
    from fingersplat3d.splat.fit import fit_gaussians, gaussian_budget
    from fingersplat3d.splat.novel import render_views
    from fingersplat3d.splat.stage import _initial_gaussians

    rows = []
    for path in captures:
        capture = pickle.loads(Path(path).read_bytes())
        views = {view.name: view for view in capture.views}
        train = [views[n] for n in TRAIN]
        points, colours = [], []
        for view in train:
            valid = view.mask & np.isfinite(view.depth)
            points.append(view.camera.unproject(np.argwhere(valid)[:, ::-1].astype(float), view.depth[valid]))
            colours.append(view.image[valid])
        cloud = points_to_cloud(np.concatenate(points), np.concatenate(colours))
        extent = float(np.linalg.norm(cloud.get_max_bound() - cloud.get_min_bound()))
        cloud = cloud.voxel_down_sample(0.002 * extent)
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.02 * extent, max_nn=30))
        config = preset(preset_name, refine_poses=False, **overrides)
        budget = gaussian_budget(train, config)
        started = time.perf_counter()
        fit = fit_gaussians(_initial_gaussians(cloud, 1, budget, config, config.seed), train,
                            [v.camera for v in train], config, budget=budget, device="cpu")
        row = {"capture": Path(path).stem, "fit_s": time.perf_counter() - started}
        rendered = render_views(fit.gaussians, [(n, views[n].camera) for n in (*TRAIN, *HELD_OUT)])
        scores = {v.name: (masked_psnr(v.image, views[v.name].image, views[v.name].mask),
                           masked_ssim(v.image, views[v.name].image, views[v.name].mask)) for v in rendered}
        row["train_psnr"] = [scores[n][0] for n in TRAIN]
        row["held_out_psnr"] = [scores[n][0] for n in HELD_OUT]
        row["held_out_ssim"] = [scores[n][1] for n in HELD_OUT]
        rows.append(row)
        print(json.dumps(row, default=float), file=sys.stderr, flush=True)
    return rows


def bound_table(results: dict[str, list[dict]]) -> str:
    lines = ["| preset, exact geometry | train PSNR dB | held-out PSNR dB (GT cameras) | held-out SSIM | fit time s |",
             "|---|---|---|---|---|"]
    for name, rows in results.items():
        train = [p for r in rows for p in r["train_psnr"]]
        psnr = [p for r in rows for p in r["held_out_psnr"]]
        ssim = [p for r in rows for p in r["held_out_ssim"]]
        lines.append(f"| {name} | {_median(train):.1f} ({min(train):.1f}) | {_median(psnr):.1f} ({min(psnr):.1f}) | "
                     f"{_median(ssim):.3f} ({min(ssim):.3f}) | {_median([r['fit_s'] for r in rows]):.1f} |")
    return "\n".join(lines)


def _median(values) -> float:
    return float(statistics.median(values)) if values else float("nan")


def table(results: dict[str, list[dict]], info: dict, seeds: int) -> str:
    lines = [f"Machine: {info['cpu']}, {info['cores']} cores, load {info['load'][0]:.1f}; torch {info['torch']}.",
             f"{seeds} seeds, uwa ring 640x512; medians over seeds (and views); min in brackets.", "",
             "| preset | train PSNR dB | train SSIM | held-out PSNR dB (placed -> aligned) | held-out SSIM | "
             "depth MAE mm splat / fused | alpha outside mask before -> after | Gaussians | fuse time s | peak RSS GB |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, rows in results.items():
        train_psnr = [p for r in rows for p in r["train_psnr"]]
        train_ssim = [p for r in rows for p in r["train_ssim"]]
        held = [h for r in rows for h in r["held_out"].values()]
        lines.append(
            f"| {name} | {_median(train_psnr):.1f} ({min(train_psnr):.1f}) | {_median(train_ssim):.3f} | "
            f"{_median([h['psnr_placed'] for h in held]):.1f} -> {_median([h['psnr'] for h in held]):.1f} "
            f"({min(h['psnr'] for h in held):.1f}) | {_median([h['ssim_placed'] for h in held]):.3f} -> "
            f"{_median([h['ssim'] for h in held]):.3f} ({min(h['ssim'] for h in held):.3f}) | "
            f"{_median([m for r in rows for m in r['depth_mae_splat']]):.3f} / "
            f"{_median([m for r in rows for m in r['depth_mae_fused']]):.3f} | "
            f"{_median([r['alpha_outside_before'] for r in rows]):.4f} -> {_median([r['alpha_outside_after'] for r in rows]):.4f} | "
            f"{_median([r['gaussians'] for r in rows]):.0f} | {_median([r['wall_s'] for r in rows]):.1f} "
            f"(max {max(r['wall_s'] for r in rows):.1f}) | {max(r['peak_rss_mb'] for r in rows) / 1024:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--presets", default="fast,balanced")
    parser.add_argument("--set", action="append", default=[], help="override a SplatConfig field: NAME=VALUE (JSON)")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--quick", action="store_true", help="one seed")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--bound", action="store_true",
                        help="instead: fit on exact geometry (GT cameras, cloud from GT depth), held-out at GT cameras")
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    overrides = {k: json.loads(v) for k, v in (item.split("=", 1) for item in args.set)}
    if args.worker:
        run = run_bound if args.bound else run_preset
        rows = run(args.worker[0], json.loads(args.worker[1]), overrides)
        print(json.dumps(rows, default=float))
        return 0
    seeds = list(range(args.first_seed, args.first_seed + (1 if args.quick else args.seeds)))
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        captures = [str(p) for p in synth_captures(seeds, Path(folder), (640, 512), "ring")]
        for name in args.presets.split(","):
            command = [sys.executable, __file__, "--worker", name, json.dumps(captures)]
            command += [f"--set={item}" for item in args.set] + (["--bound"] if args.bound else [])
            done = subprocess.run(command, check=True, stdout=subprocess.PIPE, text=True)
            results[name] = json.loads(done.stdout.strip().splitlines()[-1])
    text = bound_table(results) if args.bound else table(results, machine(), len(seeds))
    if overrides:
        text += f"\n\nOverrides: {overrides}"
    print(text)
    if args.out:
        args.out.write_text(text + "\n\n```json\n" + json.dumps(results, default=float, indent=1) + "\n```\n")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
