"""Benchmark rig self-calibration: real dev captures (no ground truth) and synthetic captures (a known rig).

    python3 tools/bench_rig.py [--data ../shared/data/uwa-real-dev] [--synthetic-seeds 8] [--focal each|one] [--ridge-px N] [--json out.json]

Real captures (``fs3d rig calibrate`` on all of them, each registered at the first one's working resolution as it
does, then per capture):

* the rig from all captures: angles, focal, captures used and left out, fit time;
* **stability**: the rig calibrated from finger 1's captures alone against finger 2's alone (two
  disjoint sets of the same hardware): the angle between their relative rotations per camera pair;
* **leave one capture out**: each capture fused with the rig calibrated from the *other*
  captures (``fuse --rig``): its residual, and the leave-one-view-out check of
  ``tools/bench_real.py`` with camera 2 placed by the rig (frames 0 and 1 fused on the rig's
  cameras 0 and 1, the texture projected into camera 2 and correlated with frame 2's ridge
  texture; 0 when off by half a ridge period) next to the same check for the free fuse (camera 2
  resected by PnP, as in ``bench_real.py``).

Synthetic ``uwa`` captures (the generator's rig is fixed; the finger's pose and shape vary): the rig
calibrated from the first N-2 seeds against the true one, and the last two seeds fused free and
on the rig: rotation error and depth MAE.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from bench_real import DEFAULT_DATA  # tools/ is the script's folder

from fingersplat3d.errors import run_script
from fingersplat3d.experiments.real import leave_one_view_out, texture_check

PAIRS = ((0, 1), (0, 2), (1, 2))


def _pair_angles(rig) -> list[float]:
    from fingersplat3d.eval.poses import rotation_angle_deg

    return [float(rotation_angle_deg(rig.rotations[i], rig.rotations[j])) for i, j in PAIRS]


def _rig_difference(a, b) -> list[float]:
    from fingersplat3d.eval.poses import rotation_angle_deg

    return [float(rotation_angle_deg(a.rotations[i].T @ a.rotations[j], b.rotations[i].T @ b.rotations[j])) for i, j in PAIRS]


def _rig_camera2(two, rig, view2):
    """Camera 2 of ``rig`` in the frame of a two-view reconstruction on the rig's cameras 0 and 1."""
    from fingersplat3d.align.solve.rig import quarter_turn
    from fingersplat3d.eval.poses import rotation_angle_deg
    from fingersplat3d.scene import Camera

    poses = [np.linalg.inv(camera.world_to_cam) for camera in two.cameras]
    land0 = min((poses[0][:3, :3] @ quarter_turn(t) for t in range(4)),
                key=lambda r: rotation_angle_deg(r @ rig.rotations[1], poses[1][:3, :3]))
    scale = np.linalg.norm(poses[1][:3, 3] - poses[0][:3, 3]) / np.linalg.norm(rig.centers[1])
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = land0 @ rig.rotations[2], poses[0][:3, 3] + scale * land0 @ rig.centers[2]
    return Camera.from_focal(rig.focals[2], view2.width, view2.height, np.linalg.inv(pose))


def real(data: Path, per_camera: bool = True, ridge_px: float | None = None) -> dict:
    from fingersplat3d.align.solve.global_opt import GlobalAlignConfig
    from fingersplat3d.align.solve.rig import calibrate_rig
    from fingersplat3d.cli.rig import shared_factor
    from fingersplat3d.io.jobs import list_jobs, load_job
    from fingersplat3d.pipeline import FuseConfig, fuse, register_capture
    from fingersplat3d.scene import Capture

    config = FuseConfig(splat=None) if ridge_px is None else FuseConfig(splat=None, ridge_px=ridge_px or None)  # 0: the photos'
    fit = GlobalAlignConfig()
    jobs = list_jobs([data])
    captures = {job.name: load_job(job) for job in jobs}
    factor = shared_factor(jobs, config.ridge_px)  # one resolution for all, as fs3d rig calibrate
    pooled = {name: register_capture(capture, config, factor=factor) for name, capture in captures.items()}
    names = tuple(next(iter(captures.values())).names)

    def calibrated(chosen):  # the rig's focals in the photos' pixels
        return calibrate_rig(chosen, names, fit, per_camera).in_photo_pixels(factor)

    start = time.perf_counter()
    everything = calibrated(list(pooled.values()))
    fit_s = time.perf_counter() - start
    by_finger = {}
    for finger in sorted({name.split("_")[1] for name in pooled}):
        by_finger[finger] = calibrated([c for name, c in pooled.items() if name.split("_")[1] == finger]).rig
    fingers = sorted(by_finger)
    records = []
    for name, capture in captures.items():
        others = calibrated([c for other, c in pooled.items() if other != name]).rig
        start = time.perf_counter()
        three = fuse(capture, config, rig=others)
        seconds = time.perf_counter() - start
        two_capture = Capture(capture.views[:2], capture.metadata)
        two = fuse(two_capture, config, rig=others.subset([0, 1]))
        view2 = three.capture.views[2]  # with its mask
        on_rig = texture_check(two, _rig_camera2(two, others, view2), view2) if two.registered else {}
        free_three, free_two = fuse(capture, config), fuse(two_capture, config)
        records.append({"capture": name, "registered": bool(three.registered), "residual_px": three.report["alignment"]["residual_px"],
                        "free_residual_px": free_three.report["alignment"]["residual_px"], "seconds": seconds,
                        "rig_lovo": on_rig, "free_lovo": leave_one_view_out(free_three, free_two)})
        print(f"{name}: residual {records[-1]['residual_px']:.2f} px on the rig, texture NCC {on_rig.get('texture_ncc')} "
              f"(free {records[-1]['free_lovo']['texture_ncc']})", file=sys.stderr, flush=True)
    return {"working_factor": factor,
            "rig": {"angles_deg": _pair_angles(everything.rig), "focals": everything.rig.focals.tolist(), "used": everything.used,
                    "left_out": everything.left_out, "fit_s": fit_s},
            "fingers": {f: {"angles_deg": _pair_angles(by_finger[f]), "focals": by_finger[f].focals.tolist()} for f in fingers},
            "finger_difference_deg": _rig_difference(by_finger[fingers[0]], by_finger[fingers[-1]]) if len(fingers) > 1 else None,
            "records": records}


def synthetic(seeds: int, per_camera: bool = True) -> dict:
    from fingersplat3d.align.solve.rig import calibrate_rig
    from fingersplat3d.eval import depth_errors, relative_rotation_errors
    from fingersplat3d.eval.poses import rotation_angle_deg
    from fingersplat3d.pipeline import FuseConfig, fuse, register_capture
    from fingersplat3d.scene import Capture
    from fingersplat3d.synth import SynthConfig, synthesize
    from fingersplat3d.align.solve.global_opt import GlobalAlignConfig

    config = FuseConfig(splat=None)
    truths = [synthesize(seed, SynthConfig(size=(640, 512))).capture for seed in range(seeds)]
    blind = [Capture(tuple(v.with_(camera=None, depth=None) for v in c.views), c.metadata) for c in truths]
    train = [register_capture(c, config) for c in blind[:-2]]
    start = time.perf_counter()
    calibration = calibrate_rig(train, truths[0].names, GlobalAlignConfig(), per_camera)
    fit_s = time.perf_counter() - start
    poses = [np.linalg.inv(v.camera.world_to_cam)[:3, :3] for v in truths[0].views]
    rig_error = [float(rotation_angle_deg(calibration.rig.rotations[v], poses[0].T @ poses[v])) for v in (1, 2)]
    free_single = [float(x) for c in train for x in
                   relative_rotation_errors([np.linalg.inv(p) for p in c.alignment.cam_to_world], [v.camera.world_to_cam for v in truths[train.index(c)].views])]
    held = []
    for truth, capture in zip(truths[-2:], blind[-2:]):
        row = {}
        for label, rig in (("free", None), ("rig", calibration.rig)):
            result = fuse(capture, config, rig=rig)
            gt = [v.camera.world_to_cam for v in truth.views]
            row[label] = {"rotation_deg": [float(x) for x in relative_rotation_errors([c.world_to_cam for c in result.cameras], gt)],
                          "depth_mae_mm": float(np.median([depth_errors(d, v.depth, v.mask).mae for d, v in zip(result.depths, truth.views)]))}
        held.append(row)
    return {"seeds": seeds, "rig_error_deg": rig_error,
            "focal_ratios": (calibration.rig.focals / truths[0].views[0].camera.K[0, 0]).tolist(),
            "fit_s": fit_s, "left_out": calibration.left_out, "free_train_rotation_deg": free_single, "held_out": held}


def main() -> int:
    from fingersplat3d.eval.machine import machine

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--synthetic-seeds", type=int, default=8)
    parser.add_argument("--focal", choices=("each", "one"), default="each",
                        help="each camera its own focal length (default, as fs3d rig calibrate) or one for all")
    parser.add_argument("--ridge-px", type=float, default=None,
                        help="the geometry's pixels per ridge period on the real captures (default: fuse's; 0: the photos' own resolution)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    figures = {"machine": machine()}
    if args.synthetic_seeds >= 4:
        figures["synthetic"] = synthetic(args.synthetic_seeds, args.focal == "each")
        print(json.dumps(figures["synthetic"], indent=1, default=float), flush=True)
    if args.data.is_dir():
        figures["real"] = real(args.data, args.focal == "each", args.ridge_px)
        print(json.dumps({k: v for k, v in figures["real"].items() if k != "records"}, indent=1, default=float))
        print("| capture | residual on the rig / free (px) | leave-one-view-out on the rig: outside mask, texture NCC | free (PnP) |")
        print("|---|---|---|---|")
        for r in figures["real"]["records"]:
            rig, free = r["rig_lovo"], r["free_lovo"]
            text = lambda d: "–" if not d or d.get("texture_ncc") is None else f"{100 * d['outside_mask']:.1f} %, {d['texture_ncc']:.2f}"
            print(f"| {r['capture']} | {r['residual_px']:.2f} / {r['free_residual_px']:.2f} | {text(rig)} | {text(free)} |")
    else:
        print(f"bench_rig: {args.data}: no such folder; real captures skipped", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps(figures, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
