"""A finger on other backgrounds (phone photos): masks, and the registration of real captures composited on them.

    python3 tools/bench_backgrounds.py [--seeds 3] [--real ../shared/data/uwa-real-dev] [--fuse 1_1_2_1,2_2_7_1]
                                       [--crops 20 [--crop-first-seed 7860] [--only-crops]]

Masks: each view's finger composited onto each background of
:data:`~fingersplat3d.experiments.backgrounds.BACKGROUNDS` (``fs3d synth`` uwa fingers at 640x512, grey and colour skin,
against their true masks; the real dev views at 1280x1024, each finger apart, against their dark-background masks),
then segmented from the composite alone; each view's background drawn from its own seed.
Per background and source: mask IoU median (min) and the outline's offset (median signed, positive = too wide; 90th
percentile of its distance), and how far it lies outside on average to a fraction of a pixel (the area between
the masks over the true outline's length), px at the photo's size. ``--fuse``: those real captures fused (geometry
only) from their composites on each background, each pair's turn against the same capture fused from its own photos.
``--crops N``: the masks of fingers the frame cuts at both ends (no tip, no base), on each background: the real dev
views cut as ``bench_real.py --crop-tip`` cuts them (:func:`~fingersplat3d.experiments.real_crops.tipless_window`
on the dark-background mask), and N fingers of another make (``bench_textured.py``'s: IMPOSE's skin texture, coloured,
three views +-40 degrees at 54 mm, 640x512) cut to 0.9 of the front view's finger width about the image centre.
Markdown tables.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from fingersplat3d.errors import InputError, run_script

DEFAULT_REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "uwa-real-dev"


def _real_views(folder: Path, finger: str) -> list:
    """Frames 0-2 of every capture of one finger (``1_1``, ``2_2``) in ``folder``."""
    from fingersplat3d.io.datasets import load_any

    captures = sorted({path.name.rsplit("_", 1)[0] for path in folder.glob(f"{finger}_*_*_[0-9].jpg")})
    return [view for name in captures for view in
            load_any([folder / f"{name}_{frame}.jpg" for frame in range(3)])[0].views]


def _mask_rows(source: str, views, truths, stream: int) -> None:
    """One row per background; each view's background drawn from its own seed (``stream``, the view, the
    background), so a row's photos do not depend on what ran before it."""
    from fingersplat3d.experiments.backgrounds import BACKGROUNDS, background, on_background
    from fingersplat3d.segment.masks import finger_mask, mask_iou, outline_offset_px, outward_px

    for kind_index, kind in enumerate(BACKGROUNDS):
        ious, outward, offsets, far, seconds = [], [], [], [], []
        for index, (view, truth) in enumerate(zip(views, truths)):
            rng = np.random.default_rng([stream, index, kind_index])
            photo = on_background(view.image, truth, background(kind, view.image.shape, rng))
            start = time.perf_counter()
            try:
                found = finger_mask(photo)
            except Exception as error:  # noqa: BLE001 - a view with no finger found is a row's failure, not the bench's
                print(f"  {source} {view.name} on {kind}: {error}", file=sys.stderr)
                found = np.zeros_like(truth)
            seconds.append(time.perf_counter() - start)
            ious.append(mask_iou(found, truth))
            outward.append(outward_px(found, truth))
            offset, distance = outline_offset_px(found, truth)
            offsets.append(offset)
            far.append(distance)
        print(f"| {source} | {kind} | {np.median(ious):.3f} ({np.min(ious):.3f}) | "
              f"{sum(iou < 0.9 for iou in ious)} of {len(ious)} | {np.nanmedian(outward):+.2f} | "
              f"{np.nanmedian(offsets):+.1f} | "
              f"{np.nanmedian(far):.1f} (worst {np.nanmax(far):.1f}) | {np.median(seconds):.1f} |", flush=True)


def _crop_rows(folder: Path, count: int, first_seed: int) -> None:
    """The ``--crops`` rows: masks of fingers cut at both ends on each background (see the module docstring)."""
    from fingersplat3d.experiments.backgrounds import BACKGROUNDS, background, on_background
    from fingersplat3d.experiments.real_crops import tipless_window
    from fingersplat3d.experiments.textured_finger import random_finger, skin_texture, textured_capture
    from fingersplat3d.segment.masks import finger_mask

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_textured

    print("\n| cut at both ends | background | mask IoU median (min) | IoU under 0.9 | no finger found |\n"
          "|---|---|---|---|---|")
    if folder.is_dir():
        for stream, (finger, label) in enumerate((("1_1", "finger 1"), ("2_2", "finger 2, held out")), start=2):
            views = _real_views(folder, finger)
            truths = [finger_mask(view.image) for view in views]
            windows = [tipless_window(truth) for truth in truths]
            kept = [k for k, window in enumerate(windows) if window is not None]
            for kind_index, kind in enumerate(BACKGROUNDS):
                photos, masks = [], []
                for k in kept:
                    rng = np.random.default_rng([stream, k, kind_index])
                    photo = on_background(views[k].image, truths[k], background(kind, views[k].image.shape, rng))
                    photos.append(np.ascontiguousarray(photo[windows[k]]))
                    masks.append(truths[k][windows[k]])
                _iou_row(f"real dev views ({len(kept)}), {label}", kind, photos, masks)
    texture = skin_texture(bench_textured.DEFAULT_TEXTURE)
    for kind in BACKGROUNDS:
        photos, masks = [], []
        for seed in range(first_seed, first_seed + count):
            capture = textured_capture(random_finger(np.random.default_rng(seed)), texture, size=(640, 512),
                                       ring_deg=[-40, 0, 40], distance_mm=54.0, seed=seed)
            capture = bench_textured._cropped(bench_textured._on_background(capture, kind, seed), 0.9)
            photos += [view.image for view in capture.views]
            masks += [view.mask for view in capture.views]
        _iou_row(f"another make, 640x512 ({len(photos)}: seeds {first_seed}-{first_seed + count - 1}), 0.9 widths",
                 kind, photos, masks)


def _iou_row(source: str, kind: str, photos: list, truths: list) -> None:
    """One row of the ``--crops`` table: each photo masked alone against its true mask."""
    from fingersplat3d.segment.masks import finger_mask, mask_iou

    ious, missed = [], 0
    for photo, truth in zip(photos, truths):
        try:
            ious.append(mask_iou(finger_mask(photo), truth))
        except InputError:
            ious.append(0.0)
            missed += 1
    print(f"| {source} | {kind} | {np.median(ious):.3f} ({np.min(ious):.3f}) | {sum(iou < 0.9 for iou in ious)} of "
          f"{len(ious)} | {missed} |", flush=True)


def _fuse_rows(folder: Path, captures: list[str]) -> None:
    from fingersplat3d.eval.poses import relative_rotation_errors
    from fingersplat3d.experiments.backgrounds import BACKGROUNDS, background, on_background
    from fingersplat3d.io.datasets import load_any
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.scene import Capture, View
    from fingersplat3d.segment.masks import mask_iou

    print("\n| capture | background | views registered | turn against its own photos' fuse 0-1 / 0-2 / 1-2 ° | "
          "masks IoU against the photos' | geometry s |\n|---|---|---|---|---|---|")
    for capture_index, name in enumerate(captures):
        capture = load_any([folder / f"{name}_{frame}.jpg" for frame in range(3)])[0]
        own = fuse(capture, FuseConfig(splat=None))
        for kind_index, kind in enumerate(BACKGROUNDS):
            rng = np.random.default_rng([3, capture_index, kind_index])
            composite = Capture(tuple(View(view.name, on_background(view.image, mask.mask,
                                                                    background(kind, view.image.shape, rng)))
                                      for view, mask in zip(capture.views, own.capture.views)), capture.metadata)
            start = time.perf_counter()
            try:
                result = fuse(composite, FuseConfig(splat=None))
            except InputError as error:  # no finger found in a view: the row says so
                print(f"| {name} | {kind} | – | {error} | | |", flush=True)
                continue
            seconds = time.perf_counter() - start
            registered = sum(result.report["alignment"]["aligned"].values())
            errors = relative_rotation_errors([c.world_to_cam for c in result.cameras],
                                              [c.world_to_cam for c in own.cameras])
            ious = [mask_iou(a.mask, b.mask) for a, b in zip(result.capture.views, own.capture.views)]
            print(f"| {name} | {kind} | {registered}/3 | {' / '.join(f'{e:.2f}' for e in errors)} | "
                  f"{' / '.join(f'{iou:.3f}' for iou in ious)} | {seconds:.1f} |", flush=True)


def main() -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.synth import SynthConfig, synthesize

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="fs3d synth uwa fingers (640x512), grey and colour skin")
    parser.add_argument("--real", type=Path, default=DEFAULT_REAL, help="the real dev captures (skipped if absent)")
    parser.add_argument("--fuse", default="", help="real captures to fuse on each background, comma-separated")
    parser.add_argument("--crops", type=int, default=0,
                        help="also the masks of fingers cut at both ends: the real views, and this many fingers of "
                             "another make")
    parser.add_argument("--crop-first-seed", type=int, default=7860, help="the first of those fingers' seeds")
    parser.add_argument("--only-crops", action="store_true", help="the --crops rows alone")
    args = parser.parse_args()
    if args.crops < 0:
        raise InputError(f"--crops must be 0 or more, got {args.crops}")
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores.\n")
    if args.only_crops:
        _crop_rows(args.real, args.crops, args.crop_first_seed)
        return 0
    print("| views | background | mask IoU median (min) | IoU under 0.9 | outward px (area over outline), median | "
          "outline offset px, median | outline distance px, 90th pct median | mask s |\n"
          "|---|---|---|---|---|---|---|---|")
    for stream, gray in enumerate((True, False)):
        synthetic = [view for seed in range(args.seeds)
                     for view in synthesize(seed, SynthConfig(size=(640, 512), gray=gray)).capture.views]
        _mask_rows(f"synthetic uwa 640x512 ({len(synthetic)}), {'grey' if gray else 'colour'} skin", synthetic,
                   [view.mask for view in synthetic], stream)
    if args.real.is_dir():
        from fingersplat3d.segment.masks import finger_mask

        for stream, (finger, label) in enumerate((("1_1", "finger 1"), ("2_2", "finger 2, held out")), start=2):
            real = _real_views(args.real, finger)
            _mask_rows(f"real dev 1280x1024 ({len(real)}), {label}", real, [finger_mask(view.image) for view in real],
                       stream)
        if args.fuse:
            _fuse_rows(args.real, [name for name in args.fuse.split(",") if name])
    else:
        print(f"\n(real captures not found at {args.real}: skipped)")
    if args.crops:
        _crop_rows(args.real, args.crops, args.crop_first_seed)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
