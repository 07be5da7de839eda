"""Benchmark ``fs3d fuse`` geometry (default ``FuseConfig``: backend ``prior``, ICP off) against ground truth.

    python tools/bench_fuse.py [--seeds 5] [--big-seeds 3] [--settings KEY,...] [--out FILE.md] [--quick]

Settings (rows), each fused with the default ``FuseConfig()`` unless it is an ablation:

* ``uwa3-640``: uwa rig, 3 views (left, center, right at -45/0/+45 degrees), 640x512;
* ``uwa2-640``: uwa rig, 2 views (left + center), 640x512;
* ``cfpose3-512``: cfpose rig at 512x640, generated with 10 poses; the fused views are the one with
  the most negative roll, the frontal ``p1`` and the one with the most positive roll, in that order
  (the paper picks the smallest and the two largest angles);
* ``uwa3-1280``: uwa rig, 3 views, 1280x1024 (``--big-seeds`` seeds, default 3: the slow row);
* ablations on ``uwa3-640`` (same captures): ``icp=True``, the ``minutiae`` matcher as the first guess
  instead of ``surface``, and no guided rounds.

The views handed to ``fuse`` keep the image and the ground-truth mask (as a ``fs3d synth`` capture
folder ships them) and lose their camera and depth; the ground truth is used only to score:

* relative rotation error (deg, :func:`relative_rotation_errors`) over every view pair, and over the
  pairs of adjacent views (the two ~45 degree pairs of a 3-view setting, the single pair of the
  2-view one), and the baseline direction error (:func:`translation_direction_errors`);
* depth MAE (mm) per input view after a least-squares scale-and-shift fit inside the GT mask
  (:func:`depth_errors`), split frontal (``center`` / ``p1``) vs oblique, and the same for a
  "prior only" baseline: the ``prior`` backend's own depth, no alignment;
* registered pairs, ``report["alignment"]["ok"]``, ICP acceptance;
* wall and CPU time of the ``fuse`` call and the per-stage medians of ``report["stages"]``, and
  the peak RSS of the fusing process.

Captures are synthesised in a separate process and handed over as pickles, so the fusing process's
peak RSS is that of the fuse runs (plus imports and the few captures loaded); each setting is fused
in a fresh process, imports (Open3D, PyTorch, OpenCV, SciPy) off the clock. Seeds are 0..N-1 for
every rig. ``--quick`` is a smoke run: one seed everywhere.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import pickle
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path
from fingersplat3d.eval.machine import machine

# Synthetic captures: key -> (SynthConfig keyword arguments, view selection)
SYNTH = {
    "uwa-640": {"rig": "uwa", "size": (640, 512)},
    "cfpose-512": {"rig": "cfpose", "size": (512, 640), "poses": 10},
    "uwa-1280": {"rig": "uwa", "size": (1280, 1024)},
}

# Settings: key -> label, synth key, views ("all", a tuple of names, or "cfpose-extremes"), FuseConfig kwargs,
# big (uses --big-seeds), ablation (no prior baseline, listed in the ablation table).
SETTINGS = {
    "uwa3-640": dict(label="uwa 3 views 640x512", synth="uwa-640", views="all", fuse={}, big=False, ablation=False),
    "uwa2-640": dict(label="uwa 2 views (left+center) 640x512", synth="uwa-640", views=("left", "center"), fuse={},
                     big=False, ablation=False),
    "cfpose3-512": dict(label="cfpose 3 views 512x640", synth="cfpose-512", views="cfpose-extremes", fuse={},
                        big=False, ablation=False),
    "uwa3-1280": dict(label="uwa 3 views 1280x1024", synth="uwa-1280", views="all", fuse={}, big=True, ablation=False),
    "uwa3-640-icp": dict(label="uwa 3 views 640x512, ICP on", synth="uwa-640", views="all", fuse={"icp": True},
                           big=False, ablation=True),
    "uwa3-640-minutiae": dict(label="uwa 3 views 640x512, minutiae matcher first", synth="uwa-640", views="all",
                              fuse={"registration": {"matcher": "minutiae"}}, big=False, ablation=True),
    "uwa3-640-noguided": dict(label="uwa 3 views 640x512, no guided rounds", synth="uwa-640", views="all",
                              fuse={"registration": {"guided_rounds": 0}}, big=False, ablation=True),
}
FRONTAL = {"uwa": "center", "cfpose": "p1"}
STAGES = ("pointmaps", "registration", "icp", "fusion")

# The targets
TARGET_ROT_DEG = 2.0
TARGET_DEPTH_MM = 0.2
TARGET_SPEED_S = {"uwa3-640": 15.0, "uwa3-1280": 60.0}


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def select_views(capture, how):
    """The capture restricted to the setting's views, in the setting's order."""
    from fingersplat3d.scene import Capture

    if how == "all":
        return capture
    if how == "cfpose-extremes":
        poses = capture.metadata["poses"]
        if len(capture) == 3 and capture.names[1] == "p1":  # already selected
            return capture
        others = [name for name in capture.names if name != "p1"]
        negative = min(others, key=lambda name: poses[name]["roll_deg"])
        positive = max(others, key=lambda name: poses[name]["roll_deg"])
        names = (negative, "p1", positive)
    else:
        names = tuple(how)
    return Capture(tuple(capture[name] for name in names), capture.metadata)


# ----------------------------------------------------------------------------------------------
# Worker 1: synthesise captures (own process) -> pickles
# ----------------------------------------------------------------------------------------------

def run_synth_worker(key: str, seeds: list[int], folder: Path) -> None:
    from fingersplat3d.synth import SynthConfig, synthesize

    config = SynthConfig(**SYNTH[key])
    for seed in seeds:
        capture = synthesize(seed, config).capture
        if config.rig == "cfpose":
            capture = select_views(capture, "cfpose-extremes")
        with open(folder / f"{key}-{seed}.pkl", "wb") as handle:
            pickle.dump(capture, handle, protocol=pickle.HIGHEST_PROTOCOL)


# ----------------------------------------------------------------------------------------------
# Worker 2: fuse one setting, all seeds (own process)
# ----------------------------------------------------------------------------------------------

def _finite(value):
    return None if value is None or (isinstance(value, float) and not math.isfinite(value)) else value


def run_fuse_worker(key: str, seeds: list[int], folder: Path) -> dict:
    clock = time.perf_counter()
    import open3d  # noqa: F401  (imports off the clock)
    import scipy.spatial  # noqa: F401
    import torch  # noqa: F401
    import tqdm  # noqa: F401

    import fingersplat3d.align.correspond.features  # noqa: F401
    import fingersplat3d.align.solve.icp  # noqa: F401
    import fingersplat3d.align.solve.pairwise  # noqa: F401
    import fingersplat3d.segment.masks  # noqa: F401
    from fingersplat3d.eval import depth_errors, relative_rotation_errors, translation_direction_errors
    from fingersplat3d.eval.poses import view_pairs
    from fingersplat3d.align.register import RegistrationConfig
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.pointmaps import get_backend
    from fingersplat3d.scene import Capture
    import_s = time.perf_counter() - clock
    rss_after_import = peak_rss_mib()

    setting = SETTINGS[key]
    options = dict(setting["fuse"])
    if "registration" in options:
        options["registration"] = RegistrationConfig(**options["registration"])
    config = FuseConfig(**{"splat": None, **options})  # geometry only; tools/bench_splat.py measures the fit
    captures = {}
    for seed in seeds:
        with open(folder / f"{setting['synth']}-{seed}.pkl", "rb") as handle:
            captures[seed] = select_views(pickle.load(handle), setting["views"])
    rss_before_fuse = peak_rss_mib()

    records = []
    for seed in seeds:
        truth = captures[seed]
        rig = truth.metadata["rig"]
        frontal = FRONTAL[rig]
        names = truth.names
        pairs = [(names[i], names[j]) for i, j in view_pairs(len(names))]
        # adjacent = pairs that include the frontal view (the ~45 degree pairs); the outer pair is ~90 degrees
        adjacent = [frontal in pair for pair in pairs]
        blind = Capture(tuple(view.with_(camera=None, depth=None) for view in truth.views), truth.metadata)
        record = {"seed": seed, "views": names, "frontal": frontal, "pairs": [list(p) for p in pairs],
                  "adjacent": adjacent, "pattern_class": truth.metadata.get("pattern_class"),
                  "rolls": {n: truth.metadata["poses"][n].get("roll_deg") for n in names}}
        load = os.getloadavg()[0]
        usage = resource.getrusage(resource.RUSAGE_SELF)
        clock = time.perf_counter()
        try:
            result = fuse(blind, config)
        except Exception as error:  # a failure is a figure, not a crash of the benchmark
            record.update(failed=f"{type(error).__name__}: {error}", trace=traceback.format_exc(limit=3),
                          load1=load, fuse_s=time.perf_counter() - clock)
            records.append(record)
            continue
        fuse_s = time.perf_counter() - clock
        after = resource.getrusage(resource.RUSAGE_SELF)
        report = result.report
        gt_poses = [view.camera.world_to_cam for view in truth.views]
        pred_poses = [camera.world_to_cam for camera in result.cameras]
        depth = {}
        for view, pred in zip(truth.views, result.depths):
            errors = depth_errors(pred, view.depth, view.mask)
            depth[view.name] = {"mae": errors.mae, "coverage": errors.coverage, "scale": errors.scale}
        record.update(
            failed=None, load1=load, fuse_s=fuse_s,
            cpu_s=(after.ru_utime - usage.ru_utime) + (after.ru_stime - usage.ru_stime),
            stages={name: entry["seconds"] for name, entry in report["stages"].items()},
            stage_peak_rss_mb=max(entry["peak_rss_mb"] for entry in report["stages"].values()),
            rot_deg=[float(x) for x in relative_rotation_errors(pred_poses, gt_poses)],
            tdir_deg=[_finite(float(x)) for x in translation_direction_errors(pred_poses, gt_poses)],
            depth=depth,
            pair_reports=[{k: _finite(v) if isinstance(v, float) else v for k, v in p.items()}
                          for p in report.get("pairs", [])],
            alignment_ok=bool(report["alignment"].get("ok", False)),
            aligned=report["alignment"].get("aligned", {}),
            residual_px=_finite(report["alignment"].get("residual_px")),
            relief_scale=report["alignment"].get("relief_scale"),
            spanning_tree=report["alignment"].get("spanning_tree"),
            icp={name: {"accepted": bool(v["accepted"]), "note": v.get("note", "")}
                 for name, v in report.get("icp", {}).items()},
            warnings=list(report.get("warnings", [])),
        )
        del result
        if not setting["ablation"]:  # prior-only baseline (off the clock): the backend's own depth, no alignment
            pointmaps = get_backend("prior").predict_views(blind.views)
            record["prior_depth"] = {view.name: depth_errors(pm.depth, view.depth, view.mask).mae
                                     for view, pm in zip(truth.views, pointmaps)}
            del pointmaps
        records.append(record)
    return {"key": key, "label": setting["label"], "import_s": import_s, "rss_after_import_mib": rss_after_import,
            "rss_before_fuse_mib": rss_before_fuse, "peak_rss_mib": peak_rss_mib(), "records": records,
            "torch_threads": __import__("torch").get_num_threads()}


# ----------------------------------------------------------------------------------------------
# Tables
# ----------------------------------------------------------------------------------------------

def med(values):
    values = [v for v in values if v is not None and math.isfinite(v)]
    return statistics.median(values) if values else math.nan


def mx(values):
    values = [v for v in values if v is not None and math.isfinite(v)]
    return max(values) if values else math.nan


def f(value, digits=2) -> str:
    return "–" if value is None or (isinstance(value, float) and not math.isfinite(value)) else f"{value:.{digits}f}"


def verdict(value, limit) -> str:
    if value is None or not math.isfinite(value):
        return "not met (no figure)"
    return "**met**" if value <= limit else "**not met**"


def summarise(res: dict) -> dict:
    """Pooled figures of one setting."""
    ok = [r for r in res["records"] if not r.get("failed")]
    rot = [x for r in ok for x in r["rot_deg"]]
    rot_adjacent = [x for r in ok for x, a in zip(r["rot_deg"], r["adjacent"]) if a]
    rot_outer = [x for r in ok for x, a in zip(r["rot_deg"], r["adjacent"]) if not a]
    tdir = [x for r in ok for x in r["tdir_deg"]]
    depth = [d["mae"] for r in ok for d in r["depth"].values()]
    frontal = [r["depth"][r["frontal"]]["mae"] for r in ok if r["frontal"] in r["depth"]]
    oblique = [d["mae"] for r in ok for n, d in r["depth"].items() if n != r["frontal"]]
    prior = [x for r in ok for x in r.get("prior_depth", {}).values()]
    prior_frontal = [r["prior_depth"][r["frontal"]] for r in ok if "prior_depth" in r]
    prior_oblique = [x for r in ok for n, x in r.get("prior_depth", {}).items() if n != r["frontal"]]
    pair_reports = [p for r in ok for p in r["pair_reports"]]
    n_pairs = sum(len(r["pairs"]) for r in res["records"])
    return {
        "seeds": len(res["records"]), "failures": len(res["records"]) - len(ok),
        "rot_med": med(rot), "rot_adj_med": med(rot_adjacent), "rot_outer_med": med(rot_outer), "rot_max": mx(rot),
        "tdir_med": med(tdir),
        "depth_med": med(depth), "depth_max": mx(depth), "frontal_med": med(frontal), "oblique_med": med(oblique),
        "frontal_max": mx(frontal), "oblique_max": mx(oblique),
        "prior_med": med(prior), "prior_max": mx(prior), "prior_frontal_med": med(prior_frontal),
        "prior_oblique_med": med(prior_oblique), "has_prior": bool(prior),
        "coverage_min": min((d["coverage"] for r in ok for d in r["depth"].values()), default=math.nan),
        "pairs_ok": sum(bool(p.get("ok")) for p in pair_reports), "pairs_total": n_pairs,
        "align_ok": sum(r["alignment_ok"] for r in ok),
        "icp_accepted": sum(v["accepted"] for r in ok for n, v in r["icp"].items() if v["note"] != "reference"),
        "icp_total": sum(1 for r in ok for n, v in r["icp"].items() if v["note"] != "reference"),
        "fuse_med": med([r["fuse_s"] for r in ok]), "fuse_max": mx([r["fuse_s"] for r in ok]),
        "cpu_med": med([r["cpu_s"] for r in ok]),
        "stages": {s: med([r["stages"].get(s) for r in ok]) for s in STAGES},
        "load": (min((r["load1"] for r in res["records"]), default=math.nan),
                 max((r["load1"] for r in res["records"]), default=math.nan)),
        "n_views": len(res["records"][0]["views"]) if res["records"] else 0,
    }


def ab(name: str) -> str:
    """Short view name for the per-seed table: uwa left/center/right -> le/ce/ri; cfpose names stay."""
    return name[:2] if name in ("left", "center", "right") else name


def clean_note(note: str, limit: int = 90) -> str:
    """One-line, ANSI-free, shortened pipeline note (Open3D errors carry colour codes and newlines)."""
    import re

    note = " ".join(re.sub(r"\x1b\[[0-9;]*m", "", note).split()).replace("|", "/")
    return note if len(note) <= limit else note[:limit - 1] + "…"


def adjacent_text(res: dict) -> str:
    if not res["records"]:
        return "–"
    r = res["records"][0]
    return ", ".join(f"{a}–{b}" for (a, b), adj in zip(r["pairs"], r["adjacent"]) if adj)


def tables(results: list[dict], info: dict, args, wall_s: float, load_end) -> str:
    lines = []
    load = ", ".join(f"{x:.2f}" for x in info["load"])
    torch_threads = results[0].get("torch_threads") if results else "?"
    lines += ["# fs3d fuse benchmark (geometry vs synthetic ground truth)", "",
              f"Machine: {info['cpu']}, {info['cores']} CPU cores (os.cpu_count()), shared with another user; load "
              f"average at start {load} (1/5/15 min), at end {', '.join(f'{x:.2f}' for x in load_end)}; "
              f"Python {info['python']}, NumPy {info['numpy']}, Open3D {info['open3d']}, PyTorch {info['torch']} "
              f"({torch_threads} threads), Linux {info['kernel']}.",
              "", f"Command: `{' '.join(['python', 'tools/bench_fuse.py'] + sys.argv[1:])}` — total wall time "
              f"{wall_s:.0f} s. Seeds 0..N-1 for every rig; captures synthesised in their own process, each "
              "setting fused in a fresh process. `fuse` gets images + ground-truth masks, no cameras, no depth.", ""]
    seeds = 1 if args.quick else args.seeds
    reduced = [r for r in results if SETTINGS[r["key"]]["big"] and len(r["records"]) < seeds]
    if reduced:
        lines += ["Note: " + ", ".join(f"{r['label']} ran {len(r['records'])} seeds instead of {seeds}" for r in reduced)
                  + " (`--big-seeds`), the slowest setting, to keep the whole run within ~15 minutes.", ""]
    summaries = {r["key"]: summarise(r) for r in results}
    main_rows = [r for r in results if not SETTINGS[r["key"]]["ablation"]]
    ablations = [r for r in results if SETTINGS[r["key"]]["ablation"]]

    # --- accuracy ---
    lines += ["## Accuracy (default `FuseConfig()`: backend `prior`, `surface` matcher, 2 guided rounds, ICP off)", "",
              "| setting | seeds (failed) | rot. err. median, all pairs (°) | adjacent pairs | median, adjacent (°) | "
              "median, outer pair (°) | max (°) | baseline dir. err. median (°) | depth MAE median (mm) | max (mm) | "
              "frontal median / max (mm) | oblique median / max (mm) | pairs registered | alignment ok | "
              "ICP accepted (non-reference views) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for res in main_rows:
        s = summaries[res["key"]]
        lines.append(
            f"| {res['label']} | {s['seeds']} ({s['failures']}) | {f(s['rot_med'])} | {adjacent_text(res)} | "
            f"{f(s['rot_adj_med'])} | {f(s['rot_outer_med'])} | {f(s['rot_max'])} | {f(s['tdir_med'])} | "
            f"{f(s['depth_med'], 3)} | {f(s['depth_max'], 3)} | {f(s['frontal_med'], 3)} / {f(s['frontal_max'], 3)} | "
            f"{f(s['oblique_med'], 3)} / {f(s['oblique_max'], 3)} | {s['pairs_ok']}/{s['pairs_total']} | "
            f"{s['align_ok']}/{s['seeds'] - s['failures']} | {s['icp_accepted']}/{s['icp_total']} |")
        if s["has_prior"]:
            lines.append(
                f"| ↳ prior only (no alignment) | {s['seeds']} | – | – | – | – | – | – | {f(s['prior_med'], 3)} | "
                f"{f(s['prior_max'], 3)} | {f(s['prior_frontal_med'], 3)} / – | {f(s['prior_oblique_med'], 3)} / – | – | – | – |")
    lines += ["", "Rotation: angle between predicted and true relative rotation `R_i R_j^T`, pooled over the pairs "
              "and seeds. Adjacent pairs: those that contain the frontal view (uwa `center`, cfpose `p1`): the two "
              "~45° pairs of a 3-view setting (uwa left–center and center–right; cfpose most-negative-roll–p1 and "
              "p1–most-positive-roll, roll ±39..45° plus random pitch ≤15° and yaw ≤8°), the one pair of the 2-view "
              "setting; the outer pair is the ~90° one. Depth: MAE in mm of each input view's depth after a "
              "least-squares scale-and-shift fit to the ground truth inside the GT mask, pooled over views × seeds "
              "(frontal = uwa `center` / cfpose `p1`). Prior only: `get_backend(\"prior\").predict_views(views)` "
              "depth, the monocular starting point of the alignment. Pairs registered: `report[\"pairs\"][k][\"ok\"]`; "
              "alignment ok: `report[\"alignment\"][\"ok\"]`. Minimum depth coverage over all views: "
              + ", ".join(f"{r['label']} {f(summaries[r['key']]['coverage_min'], 3)}" for r in main_rows) + ".", ""]

    # --- targets ---
    lines += ["## Targets (from the issue)", "", "| target | setting | figure | verdict |", "|---|---|---|---|"]
    for res in main_rows:
        s = summaries[res["key"]]
        lines.append(f"| relative camera rotation error median ≤ {TARGET_ROT_DEG:g}° | {res['label']} ({s['seeds']} seed(s)) "
                     f"| {f(s['rot_med'])}° | {verdict(s['rot_med'], TARGET_ROT_DEG)} |")
        lines.append(f"| depth MAE median ≤ {TARGET_DEPTH_MM:g} mm | {res['label']} ({s['seeds']} seed(s)) "
                     f"| {f(s['depth_med'], 3)} mm | {verdict(s['depth_med'], TARGET_DEPTH_MM)} |")
    for key, limit in TARGET_SPEED_S.items():
        if key in summaries:
            s = summaries[key]
            lines.append(f"| geometry ≤ {limit:g} s on 2 cores | {SETTINGS[key]['label']} ({s['seeds']} seed(s)) | "
                         f"median {f(s['fuse_med'], 1)} s (max {f(s['fuse_max'], 1)} s; load {s['load'][0]:.2f}–"
                         f"{s['load'][1]:.2f}) | {verdict(s['fuse_med'], limit)} "
                         f"{'(max too)' if math.isfinite(s['fuse_max']) and s['fuse_max'] <= limit else '(not the max)'} |")
    main_ok = summaries.get("uwa3-640")
    lines += ["", "Figures are medians over all pairs (rotation) or all views (depth) of all seeds; the issue's "
              "accuracy targets are stated for uwa, 3 views, 640x512, ≥5 seeds"
              + (f" (this run: {main_ok['seeds']} seed(s))" if main_ok else "")
              + "; the same thresholds are applied to the other rows. Speed: wall time of the `fuse` call (geometry "
              "only: masks given, no mesh, no writing), median over seeds.", ""]

    # --- speed ---
    lines += ["## Speed and memory per `fuse` call", "",
              "| setting | seeds | wall median (s) | wall max (s) | CPU time median (s) | "
              + " | ".join(STAGES) + " | peak RSS (MiB) | RSS before first fuse (MiB) | load 1-min during |",
              "|---|---|---|---|---|" + "---|" * len(STAGES) + "---|---|---|"]
    for res in results:
        s = summaries[res["key"]]
        lines.append(f"| {res['label']} | {s['seeds']} | {f(s['fuse_med'])} | {f(s['fuse_max'])} | {f(s['cpu_med'])} | "
                     + " | ".join(f(s["stages"][st]) for st in STAGES)
                     + f" | {res['peak_rss_mib']:.0f} | {res['rss_before_fuse_mib']:.0f} | "
                     f"{s['load'][0]:.2f}–{s['load'][1]:.2f} |")
    lines += ["", "Stage columns: medians of `report[\"stages\"][name][\"seconds\"]` (the `masks` stage is ~0: masks "
              "are given). CPU time: user + system time of the process during the call (all threads). Peak RSS: "
              "`ru_maxrss` of the setting's process after all its fuse calls (imports + loaded captures are the "
              "'before' column). Imports off the clock: "
              + ", ".join(f"{r['label']} {r['import_s']:.1f} s" for r in results) + ".", ""]

    # --- ablations ---
    if ablations and "uwa3-640" in summaries:
        lines += ["## Ablations (uwa 3 views 640x512, same captures)", "",
                  "| variant | seeds (failed) | rot. err. median, all (°) | median, adjacent (°) | max (°) | "
                  "depth MAE median (mm) | max (mm) | frontal / oblique median (mm) | pairs registered | alignment ok | "
                  "wall median (s) | icp stage median (s) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for res in [r for r in results if r["key"] == "uwa3-640"] + ablations:
            s = summaries[res["key"]]
            name = "default" if res["key"] == "uwa3-640" else res["label"].split(", ", 1)[1]
            lines.append(f"| {name} | {s['seeds']} ({s['failures']}) | {f(s['rot_med'])} | {f(s['rot_adj_med'])} | "
                         f"{f(s['rot_max'])} | {f(s['depth_med'], 3)} | {f(s['depth_max'], 3)} | "
                         f"{f(s['frontal_med'], 3)} / {f(s['oblique_med'], 3)} | {s['pairs_ok']}/{s['pairs_total']} | "
                         f"{s['align_ok']}/{s['seeds'] - s['failures']} | {f(s['fuse_med'])} | {f(s['stages']['icp'])} |")
        lines += [""]

    # --- per seed ---
    lines += ["## Per seed", "",
              "| setting | seed | class | views (roll °) | rot. err. per pair (°) | depth MAE per view (mm) | "
              "prior only per view (mm) | pairs: matches/inliers (ok) | align ok | residual (px) | spanning tree | "
              "ICP | wall (s) | load |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for res in results:
        for r in res["records"]:
            views = ", ".join(f"{n} ({r['rolls'][n]:+.0f})" if r["rolls"].get(n) is not None else n for n in r["views"])
            if r.get("failed"):
                lines.append(f"| {res['label']} | {r['seed']} | {r['pattern_class']} | {views} | FAILED: "
                             f"{clean_note(r['failed'], 200)} | – | – | – | – | – | – | – | {f(r['fuse_s'])} | {r['load1']:.2f} |")
                continue
            rot = ", ".join(f"{ab(a)}–{ab(b)} {x:.2f}" for (a, b), x in zip(r["pairs"], r["rot_deg"]))
            depth = ", ".join(f"{ab(n)} {d['mae']:.3f}" for n, d in r["depth"].items())
            prior = ", ".join(f"{ab(n)} {x:.3f}" for n, x in r.get("prior_depth", {}).items()) or "–"
            pairs = ", ".join(f"{p['matches'] if 'matches' in p else '–'}/{p['inliers'] if 'inliers' in p else '–'}"
                              f" ({'ok' if p.get('ok') else 'no'})" for p in r["pair_reports"])
            tree = ", ".join(f"{ab(a)}–{ab(b)}" for a, b in (r["spanning_tree"] or [])) or "–"
            icp = "; ".join(f"{ab(n)}: {'acc' if v['accepted'] else 'rej'}"
                            + (f" ({clean_note(v['note'])})" if v["note"] and not v["accepted"] else "")
                            for n, v in r["icp"].items() if v["note"] != "reference") or "off"
            unaligned = [n for n, a in r["aligned"].items() if not a]
            lines.append(f"| {res['label']} | {r['seed']} | {r['pattern_class']} | {views} | {rot} | {depth} | {prior} | "
                         f"{pairs} | {'yes' if r['alignment_ok'] else 'no'}"
                         f"{' (unaligned: ' + ', '.join(unaligned) + ')' if unaligned else ''} | "
                         f"{f(r['residual_px'])} | {tree} | {icp} | {f(r['fuse_s'])} | {r['load1']:.2f} |")
    lines += ["", "uwa view names abbreviated (le/ce/ri). ICP: per non-reference view accepted or "
              "rejected, with the pipeline's note. Residual: `report[\"alignment\"][\"residual_px\"]`.", ""]
    failures = [(res["label"], r) for res in results for r in res["records"] if r.get("failed")]
    if failures:
        lines += ["### Failures", ""]
        for label, r in failures:
            lines += [f"- {label}, seed {r['seed']}: `{r['failed']}`", "", "```", r["trace"].rstrip(), "```", ""]
    warnings = [(res["label"], r["seed"], w) for res in results for r in res["records"] if not r.get("failed")
                for w in r["warnings"]]
    if warnings:
        lines += ["### Warnings from `fuse`", ""] + [f"- {label}, seed {seed}: {w}" for label, seed, w in warnings] + [""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# Driver
# ----------------------------------------------------------------------------------------------

def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per 640x512 setting (default 5)")
    parser.add_argument("--big-seeds", type=int, default=3, help="seeds for the 1280x1024 setting (default 3)")
    parser.add_argument("--settings", default=",".join(SETTINGS), help=f"comma-separated subset of {','.join(SETTINGS)}")
    parser.add_argument("--quick", action="store_true", help="smoke run: 1 seed per setting")
    parser.add_argument("--out", type=Path, default=None, help="also write the markdown here")
    parser.add_argument("--json", type=Path, default=None, help="also write the raw per-seed records here")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--synth-worker", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--folder", type=Path, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--result", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.synth_worker:  # internal: synthesise captures
        run_synth_worker(args.synth_worker, list(range(args.seeds)), args.folder)
        return 0
    if args.worker:  # internal: one setting in its own process
        args.result.write_text(json.dumps(run_fuse_worker(args.worker, list(range(args.seeds)), args.folder)))
        return 0

    keys = [k.strip() for k in args.settings.split(",") if k.strip()]
    unknown = [k for k in keys if k not in SETTINGS]
    if unknown:
        parser.error(f"unknown setting(s) {unknown}; choose from {list(SETTINGS)}")
    if args.seeds < 1 or args.big_seeds < 1:
        parser.error("--seeds and --big-seeds must be >= 1")
    seeds = 1 if args.quick else args.seeds
    big_seeds = 1 if args.quick else min(args.big_seeds, seeds)
    count = {k: big_seeds if SETTINGS[k]["big"] else seeds for k in keys}
    info = machine()
    start = time.perf_counter()
    results = []
    me = str(Path(__file__).resolve())
    with tempfile.TemporaryDirectory(prefix="bench_fuse_") as tmp:
        folder = Path(tmp)
        synthesised: dict[str, int] = {}
        for key in keys:
            synth_key = SETTINGS[key]["synth"]
            need = max(count[k] for k in keys if SETTINGS[k]["synth"] == synth_key)
            if synthesised.get(synth_key, 0) < need:
                print(f"[bench_fuse] synthesising {synth_key}: {need} seed(s) ...", file=sys.stderr, flush=True)
                clock = time.perf_counter()
                subprocess.run([sys.executable, me, "--synth-worker", synth_key, "--seeds", str(need),
                                "--folder", str(folder)], check=True)
                synthesised[synth_key] = need
                print(f"[bench_fuse] synthesised {synth_key} in {time.perf_counter() - clock:.0f} s",
                      file=sys.stderr, flush=True)
            out = folder / f"result-{key}.json"
            print(f"[bench_fuse] {SETTINGS[key]['label']}: {count[key]} seed(s) ... (load {os.getloadavg()[0]:.2f})",
                  file=sys.stderr, flush=True)
            clock = time.perf_counter()
            subprocess.run([sys.executable, me, "--worker", key, "--seeds", str(count[key]), "--folder", str(folder),
                            "--result", str(out)], check=True)
            results.append(json.loads(out.read_text()))
            print(f"[bench_fuse] {SETTINGS[key]['label']}: done in {time.perf_counter() - clock:.0f} s",
                  file=sys.stderr, flush=True)
    text = tables(results, info, args, time.perf_counter() - start, os.getloadavg())
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
