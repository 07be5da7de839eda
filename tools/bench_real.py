"""Real rig captures without ground truth: registration, rig consistency, focal spread, leave-one-view-out.

    python3 tools/bench_real.py [--data ../shared/data/uwa-real-dev] [--select finger=2] [--ridge-px 8] [--json out.json]
                                [--two-views] [--focal-px F] [--crop-tip [SHARE] | --crop-sides [ACROSS] [--on-finger]]
                                [--orders] [--mask-offset PX]

Each UWA capture (frames 0-2) is fused geometry-only in a fresh process
(:func:`fingersplat3d.experiments.real.measure_real`, leave-one-view-out on); prints the markdown
table of docs/measurements.md and the machine it ran on. With ``--crop-tip``, each capture is also fused with its
photos cropped about their centres, the fingertip outside the frame
(:func:`fingersplat3d.experiments.real_crops.crop_without_tip`, in memory), and the crops' turns are measured against
the whole captures' rig mean; with ``--crop-sides``, cropped about their centres so that the finger fills them across
its width (ACROSS of it kept, the tip in view: :func:`fingersplat3d.experiments.real_crops.crop_filling`), the same;
with ``--on-finger`` as well, cropped about the finger's pad instead, as a dataset crops (the principal point moves).
With ``--orders``, instead, each capture is fused once per order of its photos (six,
:mod:`fingersplat3d.experiments.orders`): the rig table of each order and how far each capture moves with the order.
With ``--mask-offset PX``, each view's finger mask is found on the photo, grown by PX pixels (shrunk where negative)
and given to the fuse (:mod:`fingersplat3d.experiments.mask_offset`): how far the focal follows the outline.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fingersplat3d.errors import run_script

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "uwa-real-dev"


def _measure(job, guided_rounds: int, ridge_px: float, two_views: bool, focal_px: float | None,
             mask_offset: int | None = None) -> dict:
    from fingersplat3d.align.register import RegistrationConfig
    from fingersplat3d.experiments.real import measure_real
    from fingersplat3d.io.jobs import load_job
    from fingersplat3d.pipeline import FuseConfig
    from fingersplat3d.scene import Capture

    capture = load_job(job)
    if mask_offset is not None:
        from fingersplat3d.experiments.mask_offset import with_offset_masks

        capture = Capture(with_offset_masks(capture.views, mask_offset), capture.metadata)
    config = FuseConfig(splat=None, registration=RegistrationConfig(guided_rounds=guided_rounds), ridge_px=ridge_px or None,
                        focal_px=focal_px)
    return measure_real(capture, config, leave_one_out=True, two_views=two_views) | {"capture": job.name}


def _measure_orders(job, guided_rounds: int, ridge_px: float, focal_px: float | None) -> dict:
    from fingersplat3d.align.register import RegistrationConfig
    from fingersplat3d.experiments.orders import in_every_order
    from fingersplat3d.io.jobs import load_job
    from fingersplat3d.pipeline import FuseConfig

    config = FuseConfig(splat=None, registration=RegistrationConfig(guided_rounds=guided_rounds), ridge_px=ridge_px or None,
                        focal_px=focal_px)
    return {order: record | {"capture": job.name} for order, record in in_every_order(load_job(job), config).items()}


def _measure_cropped(job, guided_rounds: int, ridge_px: float, focal_px: float | None, share: float,
                     sides: bool = False, on_finger: bool = False) -> dict | None:
    from fingersplat3d.align.register import RegistrationConfig
    from fingersplat3d.experiments.real import measure_real
    from fingersplat3d.experiments.real_crops import crop_filling, crop_without_tip
    from fingersplat3d.io.jobs import load_job
    from fingersplat3d.pipeline import FuseConfig
    from fingersplat3d.scene import Capture

    capture = load_job(job)
    views = [crop_filling(view, share, on_finger=on_finger) if sides else crop_without_tip(view, share)
             for view in capture.views]
    if any(view is None for view in views):
        return None
    config = FuseConfig(splat=None, registration=RegistrationConfig(guided_rounds=guided_rounds), ridge_px=ridge_px or None,
                        focal_px=focal_px)
    return measure_real(Capture(views, capture.metadata), config) | {"capture": job.name}


def main() -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.experiments.process import in_fresh_process
    from fingersplat3d.experiments.real import (real_table, sensitivity_against_deviation, summarize_real,
                                                two_view_table)
    from fingersplat3d.io.jobs import list_jobs
    from fingersplat3d.working_scale import RIDGE_PX

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of UWA raw frames")
    parser.add_argument("--select", help="a subset, as fs3d batch takes it: subject=S,finger=F,capture=C,count=K")
    parser.add_argument("--guided-rounds", type=int, default=2)
    parser.add_argument("--ridge-px", type=float, default=RIDGE_PX,
                        help=f"working pixels per ridge period (default {RIDGE_PX:g}; 0: the photos' own resolution)")
    parser.add_argument("--json", type=Path, help="write every figure here")
    parser.add_argument("--two-views", action="store_true",
                        help="also fuse every pair of views alone and compare its turn with the three-view fuse's")
    parser.add_argument("--focal-px", type=float, help="the cameras' focal in the photos' pixels, kept (fs3d fuse --focal-px)")
    parser.add_argument("--crop-tip", type=float, nargs="?", const=0.3, metavar="SHARE",
                        help="also fuse every capture cropped about its centre with the fingertip and SHARE (default 0.3) "
                             "of the finger's width behind it outside the frame, against the whole captures' rig")
    parser.add_argument("--crop-sides", type=float, nargs="?", const=0.8, metavar="ACROSS",
                        help="also fuse every capture cropped about its centre so that the finger fills it: ACROSS "
                             "(default 0.8) of its width kept across it, the tip in view; against the whole captures' "
                             "rig")
    parser.add_argument("--on-finger", action="store_true",
                        help="with --crop-sides: crop about the finger's pad instead of the image centre, as a dataset "
                             "crops (the principal point moves with the crop, unknown to the fuse)")
    parser.add_argument("--mask-offset", type=int, metavar="PX",
                        help="each view's finger mask found on the photo and grown by PX pixels (shrunk where negative; "
                             "0: as found), given to the fuse: how far the focal and the turns follow the outline")
    parser.add_argument("--orders", action="store_true",
                        help="instead: fuse every capture with its photos in each of their orders and report how far the "
                             "result moves with the order")
    args = parser.parse_args()
    if args.crop_tip is not None and not 0.0 <= args.crop_tip <= 2.0:
        print(f"bench_real: --crop-tip {args.crop_tip:g}: the share of the finger's width cut behind the tip must lie "
              "in 0-2", file=sys.stderr)
        return 2
    if args.crop_sides is not None and (args.crop_tip is not None or not 0.1 <= args.crop_sides <= 2.0):
        print("bench_real: --crop-sides takes a share of the finger's width in 0.1-2, and not with --crop-tip",
              file=sys.stderr)
        return 2
    if args.on_finger and args.crop_sides is None:
        print("bench_real: --on-finger goes with --crop-sides", file=sys.stderr)
        return 2
    if args.mask_offset is not None and (args.orders or args.crop_tip is not None or args.crop_sides is not None):
        print("bench_real: --mask-offset grows the masks of the whole captures' run only; --orders and the crops find "
              "their own: run it alone", file=sys.stderr)
        return 2
    if not args.data.is_dir():
        print(f"bench_real: {args.data}: no such folder (the real dev captures live in ../shared/data/uwa-real-dev)",
              file=sys.stderr)
        return 2
    if args.orders:
        return _orders(args)
    records = []
    for job in list_jobs([args.data], args.select):
        records.append(in_fresh_process(_measure, job, args.guided_rounds, args.ridge_px, args.two_views, args.focal_px,
                                         args.mask_offset))
        r = records[-1]
        print(f"{job.name}: {r['registered']}/3 registered, angles {', '.join(f'{v:.1f}' for v in r['angles_deg'].values())}, "
              f"focal {r['focal']:.0f}, {r['seconds']:.1f} s", file=sys.stderr, flush=True)
    summary = summarize_real(records)
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores, load {info['load'][0]:.2f}; torch {info['torch']}, "
          f"open3d {info['open3d']}; {len(records)} captures of {args.data.name}, geometry only, "
          f"{args.guided_rounds} guided rounds, {args.ridge_px:g} px per ridge (0: photo resolution).\n")
    print(real_table(records, summary))
    print(f"\nFocal spread {100 * summary['focal_spread']:.0f} %; rig deviation over all pairs: median "
          f"{summary['rig_deviation_median_deg']:.2f}°, max {summary['rig_deviation_max_deg']:.2f}°.")
    how_sure = sensitivity_against_deviation(records, summary)
    if how_sure:
        print("\nHow sure, per camera pair (" + ", ".join(f"{k}: Spearman {v['spearman']:.2f} (p = {v['p']:.2g})"
                                                    for k, v in how_sure.items()) + ") against its rig deviation.")
    if args.two_views:
        print("\n" + two_view_table(summary))
    cropped = []
    if args.crop_tip is not None or args.crop_sides is not None:
        from fingersplat3d.eval.rig_consistency import deviation_against
        from fingersplat3d.experiments.real_crops import crop_table

        for job in list_jobs([args.data], args.select):
            sides = args.crop_sides is not None
            record = in_fresh_process(_measure_cropped, job, args.guided_rounds, args.ridge_px, args.focal_px,
                                      args.crop_sides if sides else args.crop_tip, sides, args.on_finger)
            if record is None:
                print(f"{job.name}: not cropped (no finger found, or the crop does not fit about the centre)",
                      file=sys.stderr)
                continue
            cropped.append(record)
            print(f"{job.name} cropped: {record['registered']}/3 registered, focal {record['focal']:.0f}", file=sys.stderr)
        deviations = deviation_against(cropped, records)
        how = (f"the finger filling the frame, {args.crop_sides:g} of its width kept, the tip in view" if sides else
               f"the fingertip and {args.crop_tip:g} of the finger's width outside the frame")
        where = "the finger's pad (the principal point moved)" if args.on_finger else "the centre"
        print(f"\nCropped about {where}, {how}; rig deviation against the whole captures' rig mean:\n")
        print(crop_table(cropped, deviations))
    if args.json:
        args.json.write_text(json.dumps({"machine": info, "records": records, "summary": summary, "cropped": cropped},
                                        indent=1, default=float))
    return 0


def _orders(args) -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.experiments.orders import order_spread, orders_table
    from fingersplat3d.experiments.process import in_fresh_process
    from fingersplat3d.io.jobs import list_jobs

    by_capture = {}
    for job in list_jobs([args.data], args.select):
        by_capture[job.name] = in_fresh_process(_measure_orders, job, args.guided_rounds, args.ridge_px, args.focal_px)
        spread = order_spread(by_capture[job.name])
        print(f"{job.name}: {spread['registered_orders']} of {len(by_capture[job.name])} orders whole, turns within "
              f"{spread['turn_deg']:.2f}°, focal within {100 * spread['focal']:.1f} %", file=sys.stderr, flush=True)
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores, load {info['load'][0]:.2f}; torch {info['torch']}; "
          f"{len(by_capture)} captures of {args.data.name}, each in every order of its photos, geometry only, "
          f"{args.guided_rounds} guided rounds, {args.ridge_px:g} px per ridge (0: photo resolution).\n")
    print(orders_table(by_capture))
    if args.json:
        args.json.write_text(json.dumps({"machine": info, "orders": by_capture}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
