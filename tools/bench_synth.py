"""Benchmark ``fs3d synth``: speed and memory per capture, and sample statistics per rig.

    python tools/bench_synth.py [--seeds 5] [--cfpose-seeds N] [--rigs uwa-640,uwa-1280,cfpose] [--out FILE.md] [--quick]

Prints markdown tables (and writes them to ``--out``):

1. Speed: wall time of one full capture (``synthesize`` + ``write_capture`` of images, masks,
   depth, cameras, minutiae and mesh into a temporary folder), median / max over the seeds,
   with the per-stage medians from ``SynthResult.seconds`` and the peak RSS of the process.
   Each rig runs in a fresh Python process (so peak RSS is per rig); imports, Open3D
   included, happen before the clock starts and are reported separately.
2. Sample statistics per rig: pattern classes, minutiae per finger, visible minutiae per view,
   ridge period at the pad in pixels, predicted (``period_mm * focal / median depth in the mask``)
   and measured on the rendered image (peak of the radially averaged power spectrum of a
   Hann-windowed patch of ~10 periods at the interior centre of the ridge area of the frontal
   view), and the image-minutiae match rate on a noise-free rendering (1280x1024 rigs only).

Per-seed figures follow in a third table. Seeds are 0..N-1. ``--quick`` is a smoke run: one seed,
cfpose with 3 poses.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fingersplat3d.errors import run_script
from fingersplat3d.eval.machine import machine
from fingersplat3d.experiments.process import peak_rss_mb

RIG_SPECS = {
    # key: (label, SynthConfig keyword arguments, image-minutiae match test?)
    "uwa-640": ("uwa 640x512", {"rig": "uwa", "size": (640, 512)}, False),
    "uwa-1280": ("uwa 1280x1024", {"rig": "uwa", "size": (1280, 1024)}, True),
    "cfpose": ("cfpose 1024x1280", {"rig": "cfpose"}, True),
}
FRONTAL_VIEW = {"uwa": "center", "cfpose": "p1"}
PATCH_PERIODS = 10  # side of the period-measurement patch, in (predicted) ridge periods
MATCH_FACING = 0.8  # minutiae whose skin faces the camera at least this much (cosine)


# ----------------------------------------------------------------------------------------------
# Measurements (pure numpy / OpenCV)
# ----------------------------------------------------------------------------------------------

def spectral_period(patch, pad: int = 4, min_period: float = 3.0, max_period: float | None = None) -> float:
    """Dominant period (pixels) of a 2-D patch: peak of its radially averaged power spectrum.

    The patch is mean-removed, Hann-windowed and zero-padded ``pad`` times; the peak of the
    radial profile is refined with a parabola through its neighbours. Orientation-free, so curved
    ridges (near a core) still give their spacing.
    """
    import numpy as np

    patch = np.asarray(patch, np.float64)
    n_rows, n_cols = patch.shape
    window = np.outer(np.hanning(n_rows), np.hanning(n_cols))
    values = (patch - patch.mean()) * window
    size = pad * max(n_rows, n_cols)
    power = np.abs(np.fft.fft2(values, s=(size, size))) ** 2
    freq = np.fft.fftfreq(size)
    radius = np.round(np.hypot(freq[:, None], freq[None, :]) * size).astype(np.int64)
    profile = np.bincount(radius.ravel(), power.ravel()) / np.maximum(np.bincount(radius.ravel()), 1)
    max_period = max_period or max(n_rows, n_cols) / 2.5
    low, high = int(np.ceil(size / max_period)), int(np.floor(size / min_period))
    k = low + int(np.argmax(profile[low:high + 1]))
    a, b, c = profile[k - 1], profile[k], profile[k + 1]
    denominator = a - 2 * b + c
    shift = 0.5 * (a - c) / denominator if denominator < 0 else 0.0
    return float(size / (k + shift))


def ridge_area_patch(rendering, half: int):
    """Slices of a square patch (side ``2*half``) centred on the interior centre of the ridge area.

    The centre is the maximum of the distance transform of the pixels that carry ridges (finite
    skin coordinates); the patch shrinks if the ridge area is narrower than it.
    """
    import cv2
    import numpy as np

    ridged = np.isfinite(rendering.skin_ab[..., 0]).astype(np.uint8)
    distance = cv2.distanceTransform(ridged, cv2.DIST_L2, 5)
    row, col = np.unravel_index(int(np.argmax(distance)), distance.shape)
    half = int(max(4, min(half, distance[row, col] - 1)))
    return (slice(row - half, row + half), slice(col - half, col + half)), (int(col), int(row)), half


def to_gray(image):
    import numpy as np

    return image if image.ndim == 2 else image @ np.array([0.299, 0.587, 0.114], np.float32)


def image_minutiae(image, mask, period_px: float) -> dict:
    """Endings / bifurcations in an image: adaptive binarisation, thinning, crossing number.

    The same idea as ``tests/test_synth.py::_image_minutiae`` (re-implemented here, not imported).
    Returns ``{"ending": [K, 2] (u, v), "bifurcation": [K, 2]}``.
    """
    import cv2
    import numpy as np

    smooth = cv2.GaussianBlur(image.astype(np.float32), (0, 0), period_px / 8)
    local = cv2.GaussianBlur(smooth, (0, 0), period_px * 0.6)
    ridges = ((smooth > local) & mask).astype(np.uint8) * 255
    skeleton = (cv2.ximgproc.thinning(ridges) > 0).astype(np.int32)
    s = skeleton
    ring = [s[:-2, 1:-1], s[:-2, 2:], s[1:-1, 2:], s[2:, 2:], s[2:, 1:-1], s[2:, :-2], s[1:-1, :-2], s[:-2, :-2]]
    crossings = sum(np.abs(ring[k] - ring[(k + 1) % 8]) for k in range(8)) // 2
    core = skeleton[1:-1, 1:-1].astype(bool)
    found = {}
    for kind, number in (("ending", 1), ("bifurcation", 3)):
        rows, cols = np.nonzero(core & (crossings == number))
        found[kind] = np.stack([cols + 1, rows + 1], axis=1).astype(np.float64)
    return found


def predicted_period_px(result, view) -> float:
    import numpy as np

    return float(result.pattern.period_mm * view.camera.K[0, 0] / np.nanmedian(view.depth[view.mask]))


def match_minutiae(result) -> dict:
    """Per view: exported minutiae (visible, facing > 0.8, inside the mask eroded by 2 periods)
    that land within 0.5 period of a detected image minutia of the same kind; and the same with
    the positions moved by (period, period) as a control."""
    import cv2
    import numpy as np

    by_id = {m["id"]: m for m in result.minutiae["minutiae_3d"]}
    per_view = {}
    for view in result.capture.views:
        period = predicted_period_px(result, view)
        side = max(3, int(4 * period))
        inner = cv2.erode(view.mask.astype(np.uint8), np.ones((side, side), np.uint8)).astype(bool)
        found = image_minutiae(to_gray(view.image), inner, period)
        selected, oblique = [], []  # facing > MATCH_FACING / visible but less camera-facing
        for entry in result.minutiae["views"][view.name]:
            if not entry["visible"]:
                continue
            minutia = by_id[entry["id"]]
            to_camera = view.camera.center - np.asarray(minutia["xyz"])
            facing = float(np.asarray(minutia["normal"]) @ to_camera / np.linalg.norm(to_camera))
            u, v = entry["uv"]
            if inner[int(round(v)), int(round(u))]:
                (selected if facing > MATCH_FACING else oblique).append((np.asarray(entry["uv"]), minutia["kind"]))

        def hits(items, offset) -> int:
            count = 0
            for uv, kind in items:
                candidates = found[kind]
                count += bool(len(candidates)) and float(np.min(np.linalg.norm(candidates - (uv + offset), axis=1))) < 0.5 * period
            return count

        per_view[view.name] = {"selected": len(selected), "hits": hits(selected, np.zeros(2)),
                               "control_hits": hits(selected, np.array([period, period])),
                               "oblique": len(oblique), "oblique_hits": hits(oblique, np.zeros(2)),
                               "detected": {k: len(v) for k, v in found.items()}}
    return per_view


# ----------------------------------------------------------------------------------------------
# Worker: one rig, all seeds, in its own process
# ----------------------------------------------------------------------------------------------

def run_worker(key: str, seeds: list[int], poses: int, match: bool) -> dict:
    clock = time.perf_counter()
    import numpy as np
    import open3d  # noqa: F401  (the renderer imports it lazily: keep its import off the clock)

    from fingersplat3d.io.capture import write_capture
    from fingersplat3d.synth import Appearance, SynthConfig, synthesize
    from fingersplat3d.synth.render import skin_weight
    import_s = time.perf_counter() - clock
    rss_after_import = peak_rss_mb()

    label, kwargs, _ = RIG_SPECS[key]
    if kwargs["rig"] == "cfpose":
        kwargs = dict(kwargs, poses=poses)
    config = SynthConfig(**kwargs)
    records = []
    for seed in seeds:
        load = os.getloadavg()[0]
        usage = resource.getrusage(resource.RUSAGE_SELF)
        clock = time.perf_counter()
        result = synthesize(seed, config)
        synth_s = time.perf_counter() - clock
        with tempfile.TemporaryDirectory(prefix="bench_synth_") as tmp:
            clock = time.perf_counter()
            write_capture(result.capture, Path(tmp) / "capture", minutiae=result.minutiae,
                          mesh=result.surface.to_open3d())
            write_s = time.perf_counter() - clock
            after = resource.getrusage(resource.RUSAGE_SELF)
            cpu_s = (after.ru_utime - usage.ru_utime) + (after.ru_stime - usage.ru_stime)
            written_mb = sum(p.stat().st_size for p in Path(tmp).rglob("*") if p.is_file()) / 2**20
        record = {"seed": seed, "load1": load, "synth_s": synth_s, "write_s": write_s,
                  "total_s": synth_s + write_s, "cpu_s": cpu_s, "stages": dict(result.seconds), "written_mib": written_mb,
                  "peak_rss_mib": peak_rss_mb()}

        # --- sample statistics (off the clock) ---
        views = result.capture.views
        minutiae = result.minutiae
        kinds = [m["kind"] for m in minutiae["minutiae_3d"]]
        frontal = result.capture[FRONTAL_VIEW[kwargs["rig"]]]
        rendering = result.renderings[frontal.name]
        predicted = predicted_period_px(result, frontal)
        slices, centre, half = ridge_area_patch(rendering, int(round(PATCH_PERIODS * predicted / 2)))
        ab = rendering.skin_ab[slices]
        height = result.pattern.sample(np.nan_to_num(ab[..., 0]), np.nan_to_num(ab[..., 1]))
        grid = result.pattern.ridges
        spacing, half_width = result.pattern.spacing_mm, result.pattern.half_width_mm
        a_grid = np.arange(grid.shape[0])[:, None] * spacing
        b_grid = np.arange(grid.shape[1])[None, :] * spacing - half_width
        ab_grid = np.stack(np.broadcast_arrays(a_grid, b_grid), axis=-1)
        # The area minutiae are exported from (skin weight 1, a > 1 mm: see minutiae_ground_truth).
        exported_area = float(((skin_weight(ab_grid, result.pattern, result.surface.params.crease) >= 0.999)
                               & (a_grid > 1.0)).sum() * spacing**2)
        a0, b0 = rendering.skin_ab[centre[1], centre[0]]
        n = int(round(PATCH_PERIODS * result.pattern.period_mm / spacing / 2))
        i, j = int(round(a0 / spacing)), int(round((b0 + half_width) / spacing))
        local_grid = grid[max(i - n, 0):i + n, max(j - n, 0):j + n]
        record.update({
            "exported_area_mm2": exported_area,
            "pattern_local_period_mm": spectral_period(local_grid) * spacing,
            "pattern_class": minutiae["pattern_class"], "period_mm": result.pattern.period_mm,
            "pattern_grid_period_mm": spectral_period(grid, pad=2, max_period=grid.shape[0] / 4) * result.pattern.spacing_mm,
            "minutiae_3d": len(kinds), "endings": kinds.count("ending"), "bifurcations": kinds.count("bifurcation"),
            "cores": len(minutiae["cores_3d"]), "deltas": len(minutiae["deltas_3d"]),
            "visible_per_view": {name: sum(e["visible"] for e in entries) for name, entries in minutiae["views"].items()},
            "frontal_view": frontal.name, "period_px_predicted": predicted,
            "period_px_predicted_patch": float(result.pattern.period_mm * frontal.camera.K[0, 0]
                                               / np.nanmedian(frontal.depth[slices])),
            "period_px_measured": spectral_period(to_gray(frontal.image)[slices]),
            "period_px_height_field": spectral_period(height),
            "patch_centre_uv": centre, "patch_side_px": 2 * half,
            "patch_centre_ab_mm": [float(x) for x in rendering.skin_ab[centre[1], centre[0]]],
            "mask_fraction": float(np.mean([v.mask.mean() for v in views])),
        })
        records.append(record)
        del result, rendering, frontal, views
    peak_timing = peak_rss_mb()

    match_records = []
    if match:
        clean = SynthConfig(**kwargs, appearance=Appearance(noise=0.0, blur_px=0.0, specular=0.0))
        for seed in seeds:
            result = synthesize(seed, clean)
            match_records.append({"seed": seed, "views": match_minutiae(result)})
            del result
    return {"key": key, "label": label, "import_s": import_s,
            "rss_after_import_mib": rss_after_import, "peak_rss_mib": peak_timing,
            "peak_rss_with_match_mib": peak_rss_mb(), "records": records, "match": match_records,
            "poses": poses if kwargs["rig"] == "cfpose" else None}


# ----------------------------------------------------------------------------------------------
# Driver and tables
# ----------------------------------------------------------------------------------------------

def fmt(value: float, digits: int = 2) -> str:
    return f"{value:.{digits}f}"


def span(values, digits: int = 2) -> str:
    """``mean (min–max)``."""
    if not values:
        return "–"
    return f"{fmt(statistics.fmean(values), digits)} ({fmt(min(values), digits)}–{fmt(max(values), digits)})"


def args_seeds(args) -> int:
    return 1 if args.quick else args.seeds


def tables(results: list[dict], info: dict, args, wall_s: float, load_end) -> str:
    lines = []
    load = ", ".join(f"{x:.2f}" for x in info["load"])
    lines += ["# fs3d synth benchmark", "",
              f"Machine: {info['cpu']}, {info['cores']} CPU cores (os.cpu_count()), load average at start "
              f"{load} (1/5/15 min), at end {', '.join(f'{x:.2f}' for x in load_end)}; "
              f"Python {info['python']}, NumPy {info['numpy']}, Open3D {info['open3d']}, Linux {info['kernel']}.",
              "", f"Command: `{' '.join(['python', 'tools/bench_synth.py'] + sys.argv[1:])}` — total wall time "
              f"{wall_s:.0f} s. Seeds 0..N-1; each rig in a fresh process.", ""]
    reduced = [r for r in results if len(r["records"]) < args_seeds(args)]
    if reduced:
        lines += ["Note: " + ", ".join(f"{r['label']} ran {len(r['records'])} seeds instead of {args_seeds(args)}"
                                       for r in reduced)
                  + " (`--cfpose-seeds`), the slowest rig, to keep the whole run near 6 minutes on this machine.", ""]

    lines += ["## Speed: one capture = `synthesize` + `write_capture` (images, masks, depth, cameras, minutiae, mesh)", "",
              "| rig | views | seeds | total median (s) | total max (s) | CPU time median (s) | shape | ridges | render | minutiae | write | "
              "render per view | written (MiB) | peak RSS (MiB) | load 1-min during |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for res in results:
        recs = res["records"]
        med = lambda f: statistics.median(f(r) for r in recs)  # noqa: E731
        n_views = len(recs[0]["visible_per_view"])
        lines.append(
            f"| {res['label']} | {n_views} | {len(recs)} | {fmt(med(lambda r: r['total_s']))} | "
            f"{fmt(max(r['total_s'] for r in recs))} | {fmt(med(lambda r: r['cpu_s']))} | "
            + " | ".join(fmt(med(lambda r, k=k: r["stages"][k])) for k in ("shape", "ridges", "render", "minutiae"))
            + f" | {fmt(med(lambda r: r['write_s']))} | {fmt(med(lambda r: r['stages']['render']) / n_views)} | "
            f"{fmt(med(lambda r: r['written_mib']), 1)} | {res['peak_rss_mib']:.0f} | "
            f"{min(r['load1'] for r in recs):.2f}–{max(r['load1'] for r in recs):.2f} |")
    lines += ["", "Stage columns are medians of `SynthResult.seconds`; `write` includes `surface.to_open3d()`. "
              "CPU time: user + system time of the process for the capture (all threads), less sensitive than wall "
              "time to other users' load on a shared machine. "
              "Peak RSS is `ru_maxrss` of the rig's process after its timed captures (imports: "
              + ", ".join(f"{r['label']} {r['rss_after_import_mib']:.0f} MiB" for r in results)
              + "). Imports (NumPy, OpenCV, Open3D, fingersplat3d) are off the clock: "
              + ", ".join(f"{r['label']} {r['import_s']:.1f} s" for r in results)
              + " in a fresh process. Target: one uwa capture at 1280x1024 in ≤ 10 s on 2 cores.", ""]

    lines += ["## Sample statistics per rig", "",
              "| rig | seeds | pattern classes | minutiae / finger (3D) | per 100 mm² | endings share | visible / view (mean) | "
              "period (mm) | period at pad, predicted (px) | measured on image (px) | measured / predicted | "
              "GT height field in patch (px) | image-minutiae match rate (cos > 0.8) | control (shifted 1 period) | "
              "match rate, visible with cos ≤ 0.8 |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for res in results:
        recs = res["records"]
        classes = {}
        for r in recs:
            classes[r["pattern_class"]] = classes.get(r["pattern_class"], 0) + 1
        class_text = ", ".join(f"{k} ×{v}" for k, v in sorted(classes.items()))
        visible = [statistics.fmean(r["visible_per_view"].values()) for r in recs]
        ratio = [r["period_px_measured"] / r["period_px_predicted"] for r in recs]
        if res["match"]:
            selected = sum(v["selected"] for m in res["match"] for v in m["views"].values())
            hit = sum(v["hits"] for m in res["match"] for v in m["views"].values())
            control = sum(v["control_hits"] for m in res["match"] for v in m["views"].values())
            per_seed = [sum(v["hits"] for v in m["views"].values()) / max(1, sum(v["selected"] for v in m["views"].values()))
                        for m in res["match"]]
            oblique = sum(v["oblique"] for m in res["match"] for v in m["views"].values())
            oblique_hit = sum(v["oblique_hits"] for m in res["match"] for v in m["views"].values())
            match_text = f"{hit / max(selected, 1):.1%} ({hit}/{selected}; per seed {min(per_seed):.0%}–{max(per_seed):.0%})"
            control_text = f"{control / max(selected, 1):.1%}"
            oblique_text = f"{oblique_hit / max(oblique, 1):.1%} ({oblique_hit}/{oblique})"
        else:
            match_text = control_text = oblique_text = "– (period ~8 px)" if "640" in res["label"] else "–"
        lines.append(
            f"| {res['label']} | {len(recs)} | {class_text} | {span([r['minutiae_3d'] for r in recs], 1)} | "
            f"{span([100 * r['minutiae_3d'] / r['exported_area_mm2'] for r in recs], 1)} | "
            f"{span([r['endings'] / max(r['minutiae_3d'], 1) for r in recs])} | {span(visible, 1)} | "
            f"{span([r['period_mm'] for r in recs], 3)} | {span([r['period_px_predicted'] for r in recs])} | "
            f"{span([r['period_px_measured'] for r in recs])} | {span(ratio, 3)} | "
            f"{span([r['period_px_height_field'] for r in recs])} | {match_text} | {control_text} | {oblique_text} |")
    lines += ["", "mean (min–max) over seeds. Predicted period: `period_mm × focal / median depth in the mask` of the "
              "frontal view (uwa `center`, cfpose `p1`). Measured: peak of the radially averaged power spectrum of "
              f"a Hann-windowed {PATCH_PERIODS}-period square patch of the rendered image (default appearance: blur, "
              "noise, highlight) at the interior centre of the ridge area (distance-transform maximum); the "
              "GT-height-field column is the same measurement on the noise-free ridge field sampled through the "
              "rendering's skin coordinates in that patch (no shading), to separate rendering from geometry. Match "
              "rate: visible exported minutiae whose skin faces the camera (cos > 0.8) inside the mask eroded by 2 "
              "periods, pooled over all views, that lie within 0.5 period of a same-kind ending/bifurcation found "
              "in a noise-free rendering (`Appearance(noise=0, blur_px=0, specular=0)`) by adaptive "
              "binarisation + thinning + crossing number.", ""]

    lines += ["## Per seed", "",
              "| rig | seed | class | period (mm) | pattern-grid period (mm) | pattern period in patch (mm) | "
              "minutiae 3D (end/bif) | exported area (mm²) | cores/deltas | "
              "visible per view | predicted (px) | patch predicted (px) | measured (px) | GT field (px) | "
              "patch centre (a, b) mm | match (hits/selected) | total (s) | load 1-min |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for res in results:
        matches = {m["seed"]: m for m in res["match"]}
        for r in res["records"]:
            m = matches.get(r["seed"])
            match_text = "–"
            if m:
                hit = sum(v["hits"] for v in m["views"].values())
                sel = sum(v["selected"] for v in m["views"].values())
                match_text = f"{hit}/{sel}"
            visible = "/".join(str(v) for v in r["visible_per_view"].values())
            lines.append(
                f"| {res['label']} | {r['seed']} | {r['pattern_class']} | {r['period_mm']:.3f} | "
                f"{r['pattern_grid_period_mm']:.3f} | {r['pattern_local_period_mm']:.3f} | "
                f"{r['minutiae_3d']} ({r['endings']}/{r['bifurcations']}) | {r['exported_area_mm2']:.0f} | "
                f"{r['cores']}/{r['deltas']} | {visible} | {r['period_px_predicted']:.2f} | "
                f"{r['period_px_predicted_patch']:.2f} | {r['period_px_measured']:.2f} | {r['period_px_height_field']:.2f} | "
                f"({r['patch_centre_ab_mm'][0]:.1f}, {r['patch_centre_ab_mm'][1]:.1f}) | {match_text} | {r['total_s']:.2f} | "
                f"{r['load1']:.2f} |")
    lines += ["", "Pattern-grid period: the same spectral measurement on the whole flat ridge field (pattern space); "
              "pattern period in patch: on the flat field in a window of the same size (in mm) around the skin point at "
              "the patch centre — local deviations of the grown pattern from the nominal period show up here and, "
              "scaled, in the measured image period. Exported area: pattern-space area with skin weight 1 and "
              "a > 1 mm, where ground-truth minutiae are exported from. Visible per view: exported minutiae flagged "
              "visible, view by view.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per rig (default 5)")
    parser.add_argument("--cfpose-seeds", type=int, default=None, help="fewer seeds for the slow cfpose rig")
    parser.add_argument("--quick", action="store_true", help="smoke run: 1 seed, cfpose with 3 poses")
    parser.add_argument("--rigs", default=",".join(RIG_SPECS), help=f"comma-separated subset of {','.join(RIG_SPECS)}")
    parser.add_argument("--out", type=Path, default=None, help="also write the markdown here")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--poses", type=int, default=10, help=argparse.SUPPRESS)
    parser.add_argument("--match", type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument("--json", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.worker:  # internal: one rig in its own process
        result = run_worker(args.worker, list(range(args.seeds)), args.poses, bool(args.match))
        args.json.write_text(json.dumps(result))
        return 0

    seeds = 1 if args.quick else args.seeds
    poses = 3 if args.quick else 10
    keys = [k.strip() for k in args.rigs.split(",") if k.strip()]
    unknown = [k for k in keys if k not in RIG_SPECS]
    if unknown:
        parser.error(f"unknown rig(s) {unknown}; choose from {list(RIG_SPECS)}")
    if seeds < 1 or (args.cfpose_seeds is not None and args.cfpose_seeds < 1):
        parser.error("--seeds and --cfpose-seeds must be >= 1")
    info = machine()
    start = time.perf_counter()
    results = []
    for key in keys:
        n = seeds if key != "cfpose" or args.cfpose_seeds is None else min(seeds, args.cfpose_seeds)
        with tempfile.TemporaryDirectory(prefix="bench_synth_") as tmp:
            out = Path(tmp) / "result.json"
            command = [sys.executable, str(Path(__file__).resolve()), "--worker", key, "--seeds", str(n),
                       "--poses", str(poses), "--match", str(int(RIG_SPECS[key][2])), "--json", str(out)]
            print(f"[bench_synth] {RIG_SPECS[key][0]}: {n} seed(s) ...", file=sys.stderr, flush=True)
            clock = time.perf_counter()
            subprocess.run(command, check=True)
            results.append(json.loads(out.read_text()))
            print(f"[bench_synth] {RIG_SPECS[key][0]}: done in {time.perf_counter() - clock:.0f} s",
                  file=sys.stderr, flush=True)
    for res in results:
        if res["poses"] is not None and res["poses"] != 10:
            res["label"] = f"{res['label']} ({res['poses']} poses)"
    text = tables(results, info, args, time.perf_counter() - start, os.getloadavg())
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
