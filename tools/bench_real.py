"""Benchmark on real captures, without ground truth: registration, rig consistency, leave-one-view-out.

    python3 tools/bench_real.py [--data ../shared/data/uwa-real-dev] [--json out.json]

For every UWA capture in ``--data`` (frames 0-2), each in a fresh process (so time and peak memory
are its own): a geometry-only ``fs3d fuse`` of the three views, and a two-view fuse of frames
0 and 1 for the leave-one-view-out check. Reported:

* registered views, the relative rotation angle of each camera pair, focal, residual, time, peak RSS;
* **rig consistency**: the rig is fixed hardware, so the relative rotation of each camera pair
  ``R_j R_i^T`` must be the same in every capture; each capture's deviation (degrees) from the
  pair's robust mean over the captures (an iteratively reweighted rotation mean, so that one
  failed capture does not drag the mean), and the median deviation per pair. A camera stored
  portrait (its image transposed against the others of its frame index) sees the rig turned by
  +-90 degrees about its optical axis; that roll is taken out (the sign that agrees with the other
  captures) before comparing;
* **focal consistency**: every capture has the same cameras, so the same focal; its spread is
  ``(max - min) / median`` over the registered captures;
* **leave-one-view-out**: the surface fused from frames 0 and 1 alone, seen from camera 2 (posed
  against that two-view model by PnP, see :func:`_leave_one_out`), must fall inside frame 2's
  silhouette and show frame 2's ridge texture: the share of projected surface pixels outside
  frame 2's mask, and the normalised correlation of the projected ridge texture with frame 2's
  (a texture off by half a ridge period correlates at about 0).

Prints a markdown table (the README's) and the machine line.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing
import resource
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from fingersplat3d.eval.rig_consistency import PAIRS, rig_consistency

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "uwa-real-dev"


def _splat_texture(texture_a, depth_a, camera_a, camera_b, mask_b):
    """Frame a's ridge texture carried by a's depth into camera b (nearest pixel, nearest depth wins)."""
    rows, cols = np.nonzero(np.isfinite(depth_a))
    points = camera_a.unproject(np.stack([cols, rows], 1).astype(np.float64), depth_a[rows, cols])
    uv, z = camera_b.project(points)
    u, v = np.round(uv[:, 0]), np.round(uv[:, 1])
    inside = np.isfinite(u) & (u >= 0) & (v >= 0) & (u < camera_b.width) & (v < camera_b.height)
    u, v, z, values = u[inside].astype(int), v[inside].astype(int), z[inside], texture_a[rows[inside], cols[inside]]
    order = np.argsort(-z)  # far first, so that the nearest point is written last
    image = np.full((camera_b.height, camera_b.width), np.nan, np.float32)
    image[v[order], u[order]] = values[order]
    outside = float(np.mean(~mask_b[v, u])) if len(u) else float("nan")
    return image, outside


def _leave_one_out(capture, three, two) -> dict:
    """Frames 0 and 1 fused alone, seen from camera 2 posed against that two-view model.

    Camera 2 is resected (PnP, RANSAC) from 2D-3D correspondences: pixels of frame 0, lifted onto
    the two-view surface, and where frame 2 sees them according to the three-view run (the model
    under test never sees frame 2's pixels; its pose is fitted to it, as a new photo's would be).
    """
    import cv2

    from fingersplat3d.scene import Camera

    if not (three.registered and two.registered):
        return {"outside_mask": None, "texture_ncc": None}
    view2 = three.capture.views[2]
    rows, cols = np.nonzero(np.isfinite(three.depths[0]) & np.isfinite(two.depths[0]))
    pick = np.random.default_rng(0).choice(len(rows), min(4000, len(rows)), replace=False)
    pixels0 = np.stack([cols[pick], rows[pick]], 1).astype(np.float64)
    seen_in_2, z2 = three.cameras[2].project(three.cameras[0].unproject(pixels0, three.depths[0][rows[pick], cols[pick]]))
    on_2 = np.isfinite(seen_in_2).all(1)
    inside = on_2.copy()
    inside[on_2] = view2.mask[np.clip(np.round(seen_in_2[on_2, 1]).astype(int), 0, view2.height - 1),
                              np.clip(np.round(seen_in_2[on_2, 0]).astype(int), 0, view2.width - 1)]
    model_points = two.cameras[0].unproject(pixels0, two.depths[0][rows[pick], cols[pick]])
    focal = two.cameras[0].K[0, 0]
    K = np.array([[focal, 0, (view2.width - 1) / 2], [0, focal, (view2.height - 1) / 2], [0, 0, 1.0]])
    ok, rvec, tvec, _ = cv2.solvePnPRansac(model_points[inside], seen_in_2[inside], K, None, reprojectionError=3.0)
    if not ok:
        return {"outside_mask": None, "texture_ncc": None}
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
    return texture_check(two, Camera(K, pose, view2.width, view2.height), view2)


def texture_check(two, camera2, view2) -> dict:
    """The two-view model (frames 0, 1) seen from ``camera2``: share of its surface outside frame 2's
    mask, and the correlation of its ridge texture with frame 2's."""
    from fingersplat3d.align.correspond.texture import estimate_ridge_period, ridge_texture

    period = estimate_ridge_period(view2.image, view2.mask)
    target = ridge_texture(view2.image, view2.mask, period)
    predicted = np.full(target.shape, np.nan, np.float32)
    outside = []
    for v in (0, 1):
        view = two.capture.views[v]
        image, out = _splat_texture(ridge_texture(view.image, view.mask, period), two.depths[v], two.cameras[v], camera2, view2.mask)
        predicted = np.where(np.isnan(predicted), image, predicted)
        outside.append(out)
    both = np.isfinite(predicted) & view2.mask
    x, y = predicted[both] - predicted[both].mean(), target[both] - target[both].mean()
    ncc = float(np.dot(x, y) / np.sqrt(np.dot(x, x) * np.dot(y, y) + 1e-12)) if both.sum() > 100 else None
    return {"outside_mask": float(np.mean(outside)), "texture_ncc": ncc}


def _one(capture_stem: str, data: str, rounds: int) -> dict:
    from fingersplat3d.io.datasets import load_uwa
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.align.register import RegistrationConfig
    from fingersplat3d.scene import Capture

    (capture,) = [c for c in load_uwa(data) if c.metadata["name"] == capture_stem]
    config = FuseConfig(splat=None, registration=RegistrationConfig(guided_rounds=rounds))
    start = time.perf_counter()
    three = fuse(capture, config)
    seconds = time.perf_counter() - start
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    two = fuse(Capture(capture.views[:2], capture.metadata), config)
    report = three.report
    return {"capture": capture_stem, "seconds": seconds, "peak_rss_mb": peak_mb,
            "stages": {k: v["seconds"] for k, v in report["stages"].items()},
            "registered": int(sum(report["alignment"]["aligned"].values())), "ok": bool(report["alignment"]["ok"]),
            "pairs": report["pairs"], "focal": report["alignment"]["focals_px"][0],
            "residual_px": report["alignment"]["residual_px"],
            "sizes": [[v.width, v.height] for v in capture.views],
            "world_to_cam": [c.world_to_cam.tolist() for c in three.cameras],
            "leave_one_out": _leave_one_out(capture, three, two)}


def main() -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.eval.poses import rotation_angle_deg
    from fingersplat3d.io.datasets import find_uwa_groups

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of UWA raw frames")
    parser.add_argument("--json", type=Path, help="write every figure here")
    parser.add_argument("--guided-rounds", type=int, default=2)
    args = parser.parse_args()
    if not args.data.is_dir():
        print(f"bench_real: {args.data}: no such folder (the real dev captures live in ../shared/data/uwa-real-dev)", file=sys.stderr)
        return 2
    stems = [group.stem for group in find_uwa_groups(args.data)]
    info = machine()
    records = []
    context = multiprocessing.get_context("spawn")
    for stem in stems:
        with ProcessPoolExecutor(1, mp_context=context) as pool:
            records.append(pool.submit(_one, stem, str(args.data), args.guided_rounds).result())
        r = records[-1]
        R = [np.asarray(p)[:3, :3] for p in r["world_to_cam"]]
        r["angles_deg"] = {f"{i}{j}": float(rotation_angle_deg(R[j] @ R[i].T, np.eye(3))) for i, j in PAIRS}
        print(f"{stem}: {r['registered']}/3 registered, angles {', '.join(f'{v:.1f}' for v in r['angles_deg'].values())}, "
              f"focal {r['focal']:.0f}, {r['seconds']:.1f} s", file=sys.stderr, flush=True)
    rig = rig_consistency(records)
    registered = [r for r in records if r["registered"] == 3]
    focals = np.array([r["focal"] for r in registered])
    print(f"Machine: {info['cpu']}, {info['cores']} cores, load {info['load'][0]:.2f}; torch {info['torch']}, "
          f"open3d {info['open3d']}; data {args.data.name}, {len(records)} captures, geometry only, "
          f"{args.guided_rounds} guided rounds.\n")
    print("| capture | views registered | angle 0-1 / 0-2 / 1-2 (deg) | rig deviation 0-1 / 0-2 / 1-2 (deg) | focal (px) | residual (px) | leave-one-out: outside mask, texture NCC | time (s) | peak RSS (GB) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in records:
        dev = " / ".join(f"{rig[p]['deviation_deg'][r['capture']]:.2f}" if rig and r["capture"] in rig[p]["deviation_deg"] else "–"
                         for p in ("01", "02", "12"))
        lovo = r["leave_one_out"]
        lovo_text = (f"{100 * lovo['outside_mask']:.1f} %, {lovo['texture_ncc']:.2f}" if lovo["texture_ncc"] is not None else "–")
        roll = " (portrait view, roll taken out)" if "roll_corrected" in r else ""
        print(f"| {r['capture']}{roll} | {r['registered']}/3 | {' / '.join(f'{v:.1f}' for v in r['angles_deg'].values())} | "
              f"{dev} | {r['focal']:.0f} | {r['residual_px']:.2f} | {lovo_text} | {r['seconds']:.1f} | {r['peak_rss_mb'] / 1024:.2f} |")
    if rig:
        means = " / ".join(f"{rig[p]['mean_angle_deg']:.1f}" for p in ("01", "02", "12"))
        medians = " / ".join(f"{rig[p]['median_deg']:.2f}" for p in ("01", "02", "12"))
        print(f"| **median** | {len(registered)}/{len(records)} captures | {means} (rig mean) | **{medians}** | "
              f"spread {100 * (focals.max() - focals.min()) / np.median(focals):.0f} % | "
              f"{np.median([r['residual_px'] for r in registered]):.2f} | "
              f"{100 * np.median([r['leave_one_out']['outside_mask'] for r in registered if r['leave_one_out']['outside_mask'] is not None]):.1f} %, "
              f"{np.median([r['leave_one_out']['texture_ncc'] for r in registered if r['leave_one_out']['texture_ncc'] is not None]):.2f} | "
              f"{np.median([r['seconds'] for r in records]):.1f} | {max(r['peak_rss_mb'] for r in records) / 1024:.2f} |")
    if args.json:
        args.json.write_text(json.dumps({"machine": info, "records": records, "rig": rig}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
