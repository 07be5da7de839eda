"""``fs3d bench``: the speed / accuracy trade, measured in one run.

Synthetic captures (``fs3d synth``'s ring rig at -45, -22.5, 0, +22.5 and +45 degrees, varied
finger shapes by seed) are fused under a baseline setting (a preset) and under a sweep that turns
one knob at a time:

* ``preset``: the splat presets (``fast``, ``balanced``, ``accurate``);
* ``resolution``: the photos resized before fusing (0.5x, 0.75x): how cost grows with image size;
* ``iterations``: the fit's steps (0.5x, 2x the preset's);
* ``gaussians``: the Gaussian budget density (0.5x, 2x);
* ``views``: 2 (-45, 0) or all 5 views instead of 3 (-45, 0, +45): how cost grows with views.

Every run is a fresh process (its peak memory is its own). Measured per run: wall time of each
stage (``report["stages"]``), peak RSS, depth error of the fused surface (mean absolute error after
scale + shift, mm, over the fused views), relative rotation error (degrees, every pair of fused
views) and the held-out PSNR (views at -22.5 and +22.5 left out of the fit, placed from the rig
and aligned to the photo). With real captures (``--real``), the rig consistency of every geometry
setting (:mod:`fingersplat3d.eval.rig_consistency`): the median deviation of each capture's
relative camera rotations from their robust mean over the captures, in degrees.

Writes ``bench.csv``, ``summary.md`` (tables, machine named) and ``trade_depth.png`` /
``trade_psnr.png`` (time against error, one curve per knob).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .geometry import RING_ANGLES, RING_VIEWS, score_geometry, synth_captures
from .process import in_fresh_process, peak_rss_mb
from .tables import write_rows

__all__ = ["Setting", "sweep", "run_bench", "RING_ANGLES"]

HELD_OUT = {"v1": -22.5, "v3": 22.5}
STAGES = ("pointmaps", "registration", "icp", "fusion", "splat")


@dataclass(frozen=True)
class Setting:
    """One point of the sweep: the knob it turns and everything a run needs."""

    knob: str  # "baseline" | "preset" | "resolution" | "iterations" | "gaussians" | "views"
    label: str
    preset: str
    scale: float = 1.0
    iterations: int | None = None
    gaussians_per_cell: float | None = None
    views: int = 3

    @property
    def geometry_key(self) -> tuple:
        """What the fused geometry depends on (real captures are fused once per key)."""
        return (self.scale,)


def sweep(preset_name: str = "fast", presets: tuple[str, ...] = ("fast", "balanced"),
          knobs: tuple[str, ...] = ("preset", "resolution", "iterations", "gaussians", "views")) -> list[Setting]:
    """The baseline and one setting per knob value (see the module docstring)."""
    from ..splat.config import preset

    base = preset(preset_name)
    settings = [Setting("baseline", preset_name, preset_name)]
    if "preset" in knobs:
        settings += [Setting("preset", name, name) for name in presets if name != preset_name]
    if "resolution" in knobs:
        settings += [Setting("resolution", f"{s:g}x", preset_name, scale=s) for s in (0.5, 0.75)]
    if "iterations" in knobs:
        settings += [Setting("iterations", f"{int(base.iterations * f)} it", preset_name,
                             iterations=int(base.iterations * f)) for f in (0.5, 2.0)]
    if "gaussians" in knobs:
        settings += [Setting("gaussians", f"{base.gaussians_per_cell * f:g}/cell", preset_name,
                             gaussians_per_cell=base.gaussians_per_cell * f) for f in (0.5, 2.0)]
    if "views" in knobs:
        settings += [Setting("views", f"{n} views", preset_name, views=n) for n in (2, 5)]
    return settings


def _resized(view, scale: float):
    import cv2

    if scale == 1.0:
        return view
    size = (max(8, int(round(view.width * scale))), max(8, int(round(view.height * scale))))
    image = cv2.resize(view.image, size, interpolation=cv2.INTER_AREA)
    mask = None if view.mask is None else cv2.resize(view.mask.astype(np.uint8), size,
                                                      interpolation=cv2.INTER_NEAREST).astype(bool)
    depth = None if view.depth is None else cv2.resize(view.depth, size, interpolation=cv2.INTER_NEAREST)
    camera = None if view.camera is None else view.camera.scaled(scale)
    return view.with_(image=image, mask=mask, depth=depth, camera=camera)


def run_synthetic(setting: Setting, capture_path: str, device: str = "auto") -> dict:
    """One fuse of one synthetic capture under ``setting`` (runs in its own process)."""
    import pickle

    from ..eval.image import masked_psnr
    from ..pipeline import FuseConfig, fuse
    from ..scene import Capture
    from ..splat.camera_path import cameras_at_angles
    from ..splat.config import preset
    from ..splat.fit import fit_camera
    from ..splat.novel import render_views

    capture = pickle.loads(Path(capture_path).read_bytes())
    views = {view.name: _resized(view, setting.scale) for view in capture.views}
    names = RING_VIEWS[setting.views]
    blind = Capture(tuple(views[n].with_(camera=None, depth=None) for n in names), capture.metadata)
    overrides = {k: v for k, v in (("iterations", setting.iterations), ("gaussians_per_cell", setting.gaussians_per_cell))
                 if v is not None}
    config = FuseConfig(splat=preset(setting.preset, **overrides), device=device)
    started = time.perf_counter()
    result = fuse(blind, config)
    wall = time.perf_counter() - started
    row = {"wall_s": wall, "registered": int(sum(result.report["alignment"]["aligned"].values())),
           "views_fused": len(names), "gaussians": len(result.gaussians) if result.gaussians is not None else 0}
    for stage in STAGES:
        row[f"{stage}_s"] = result.report["stages"].get(stage, {}).get("seconds", 0.0)
    scores = score_geometry(result, {n: views[n] for n in names})
    row.update(depth_mae_mm=scores["depth_mae_mm"], rotation_error_deg=scores["rotation_mean_deg"])
    held = [n for n in HELD_OUT if n not in names]
    psnrs = []
    if held and result.gaussians is not None:
        reference = names.index("v2")
        for name in held:
            placed = cameras_at_angles(result.cameras, [HELD_OUT[name]], reference=reference)[0]
            target = views[name]
            aligned = fit_camera(result.gaussians, placed, target.image, target.mask)
            psnrs.append(masked_psnr(render_views(result.gaussians, [(name, aligned)])[0].image, target.image, target.mask))
    row["held_out_psnr_db"] = float(np.mean(psnrs)) if psnrs else float("nan")
    row["peak_rss_mb"] = peak_rss_mb()
    return row


def run_real(scale: float, data: str) -> dict:
    """Geometry-only fuses of every real capture at ``scale``: rig consistency (own process)."""
    from ..io.datasets import load_any
    from ..scene import Capture
    from .real import measure_real, summarize_real

    records = [measure_real(Capture(tuple(_resized(v, scale) for v in capture.views), capture.metadata))
               for capture in load_any(data)]
    return {k: v for k, v in summarize_real(records).items() if k != "rig"}


def run_bench(settings: list[Setting], seeds: list[int], out: Path, *, size: tuple[int, int] = (640, 512),
              real: Path | None = None, device: str = "auto", progress: bool = True) -> dict:
    """Every setting on every seed (and the real captures per geometry setting); writes the files."""
    import tempfile

    from tqdm import tqdm

    from ..eval.machine import machine

    rows, real_rows = [], {}
    with tempfile.TemporaryDirectory() as scratch:
        captures = synth_captures(seeds, Path(scratch), size, "ring")
        jobs = [(s, seed, path) for s in settings for seed, path in zip(seeds, captures)]
        for setting, seed, path in tqdm(jobs, desc="fs3d bench", unit="fuse", disable=not progress):
            row = {**asdict(setting), "seed": seed}
            try:
                row.update(in_fresh_process(run_synthetic, setting, str(path), device), status="done")
            except Exception as error:  # a failed run is a row, not the end of the sweep
                row.update(status="failed", reason=f"{type(error).__name__}: {error}")
            rows.append(row)
    if real is not None:
        for key in tqdm(sorted({s.geometry_key for s in settings}), desc="fs3d bench (real)", unit="setting",
                        disable=not progress):
            try:
                real_rows[key] = in_fresh_process(run_real, key[0], str(real))
            except Exception as error:  # a failed setting is a row, not the end of the bench
                real_rows[key] = {"failed": f"{type(error).__name__}: {error}"}
    from ..device import resolve_device

    info = dict(machine(), device=str(resolve_device(device)))
    _write(out, rows, real_rows, settings, info, seeds, size)
    return {"rows": rows, "real": real_rows, "machine": info}


COLUMNS = ("knob", "label", "preset", "scale", "iterations", "gaussians_per_cell", "views", "seed", "status",
           "reason", "wall_s") + tuple(f"{s}_s" for s in STAGES) + (
    "peak_rss_mb", "registered", "gaussians", "depth_mae_mm", "rotation_error_deg", "held_out_psnr_db")


def _aggregate(rows: list[dict], setting: Setting) -> dict | None:
    mine = [r for r in rows if r["label"] == setting.label and r["knob"] == setting.knob and r["status"] == "done"]
    if not mine:
        return None
    keys = ["wall_s", "peak_rss_mb", "depth_mae_mm", "rotation_error_deg", "held_out_psnr_db"] + [f"{s}_s" for s in STAGES]
    result = {}
    for k in keys:
        values = [r[k] for r in mine if np.isfinite(r[k])]
        result[k] = float(np.median(values)) if values else float("nan")
    result["runs"] = len(mine)
    return result


def _write(out: Path, rows, real_rows, settings, info, seeds, size) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_rows(out / "bench.csv", COLUMNS, rows)
    machine_line = (f"{info.get('cpu', '?')}, {info.get('cores', '?')} cores, torch {info.get('torch', '?')}, "
                    f"device {info.get('device', 'cpu')}")
    lines = ["# Speed / accuracy trade", "", f"Machine: {machine_line}.", "",
             f"Synthetic ring captures at {size[0]}x{size[1]}, seeds {', '.join(map(str, seeds))}; medians over seeds. "
             "Times in seconds, memory in MB, depth error in mm (scale + shift), rotation error in degrees, "
             "held-out PSNR in dB (aligned camera).", "",
             "| knob | setting | wall | pointmaps | registration | fusion | splat | peak RSS | depth MAE | rot. err. | held-out PSNR |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    aggregates = {}
    for setting in settings:
        a = _aggregate(rows, setting)
        aggregates[setting] = a
        if a is None:
            lines.append(f"| {setting.knob} | {setting.label} | failed | | | | | | | | |")
            continue
        lines.append(f"| {setting.knob} | {setting.label} | {a['wall_s']:.1f} | {a['pointmaps_s']:.1f} | "
                     f"{a['registration_s']:.1f} | {a['fusion_s']:.1f} | {a['splat_s']:.1f} | {a['peak_rss_mb']:.0f} | "
                     f"{a['depth_mae_mm']:.3f} | {a['rotation_error_deg']:.2f} | {a['held_out_psnr_db']:.2f} |")
    if real_rows:
        lines += ["", "Real captures, geometry only (rig consistency: deviation of each capture's relative camera "
                  "rotations from their robust mean over the captures):", "",
                  "| resolution | captures | all views registered | median deviation ° | max deviation ° | fuse s (median) | peak RSS MB |",
                  "|---|---|---|---|---|---|---|"]
        for key, r in sorted(real_rows.items()):
            if "failed" in r:
                lines.append(f"| {key[0]:g}x | failed: {r['failed']} | | | | | |")
                continue
            lines.append(f"| {key[0]:g}x | {r['captures']} | {r['registered_all']} | {r['rig_deviation_median_deg']:.2f} | "
                         f"{r['rig_deviation_max_deg']:.2f} | {r['fuse_s_median']:.1f} | {r['peak_rss_mb']:.0f} |")
    failed = [r for r in rows if r["status"] != "done"]
    if failed:
        lines += ["", "Failed runs:", ""] + [f"- {r['knob']} {r['label']} seed {r['seed']}: {r['reason']}" for r in failed]
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    from .plots import trade_picture

    for metric, label, name in (("depth_mae_mm", "depth error (mm, scale + shift)", "trade_depth.png"),
                                ("held_out_psnr_db", "held-out PSNR (dB)", "trade_psnr.png")):
        curves: dict[str, list] = {}
        baseline = next((s for s in settings if s.knob == "baseline"), None)
        for setting, a in aggregates.items():
            if a is None or setting.knob == "baseline" or not np.isfinite(a[metric]):
                continue
            curves.setdefault(setting.knob, [])
            curves[setting.knob].append((a["wall_s"], a[metric], setting.label))
        if baseline is not None and aggregates.get(baseline) and np.isfinite(aggregates[baseline][metric]):
            for knob in curves:
                curves[knob].append((aggregates[baseline]["wall_s"], aggregates[baseline][metric], baseline.label))
        if curves:
            trade_picture(out / name, curves, "wall time of a fuse (s)", label, f"{label} against time, one knob at a time",
                          note=machine_line)

