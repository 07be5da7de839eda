"""Benchmark image matching (``align.correspond.features``) and pair registration (``align.solve.pairwise``).

    python tools/bench_matching.py [--seeds 3] [--out FILE.md] [--quick] [--methods minutiae,sift]

Prints markdown tables (and writes them to ``--out``):

1. Matching, per data set, pair kind and method: verified matches per pair, the fraction within
   2 px of ground truth, the median ground-truth error, the share of pairs that returned matches,
   and the wall time per pair. Ground truth of a match: lift ``uv_a`` with view a's exact depth
   (bilinear) and camera, project into b; the error is the distance to ``uv_b`` in pixels, and a
   match whose ground-truth point is hidden in b (depth test, 1 %) counts as infinitely wrong.
   Data: ``uwa`` 640x512 (left-center, center-right, left-right = 90 degrees apart, where no
   overlap is expected and the right answer is no matches), ``uwa`` 1280x1024, and ``cfpose``
   512x640 (4 poses; pairs of neighbouring rolls, the roll difference is shown).
2. Registration of uwa 640x512 pairs from the default matches: rotation error of ``b_to_a``
   against the ground-truth relative pose (degrees), scale error, inliers, residual, for
   pointmaps made from the exact depth, from the exact depth distorted by a smooth error (relief
   scaled 1.3x and 0.7x about the mean depth: a wrong cross-section), and from the ``prior``
   backend when it is installed.

Seeds are 0..N-1; everything runs single-threaded in this process (OpenCV threads set to 1).
"""
from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from collections import defaultdict

import cv2
import numpy as np

from fingersplat3d.align.correspond.features import DEFAULT_METHOD, match_views
from fingersplat3d.align.solve.pairwise import register_pair
from fingersplat3d.pointmaps.base import Pointmap
from fingersplat3d.synth import SynthConfig, synthesize

METHOD_SPECS = {
    # label: (method, extra keyword arguments)
    "minutiae": ("minutiae", {}),
    "minutiae+dense": ("minutiae", {"densify": True}),
    "minutiae full-res": ("minutiae", {"target_period_px": None}),
    "sift": ("sift", {}),
    "rootsift": ("rootsift", {}),
    "akaze": ("akaze", {}),
}


# ------------------------------------------------------------------------------------------------
# Ground truth
# ------------------------------------------------------------------------------------------------

def bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    height, width = image.shape[:2]
    u = np.clip(uv[:, 0], 0, width - 1.001)
    v = np.clip(uv[:, 1], 0, height - 1.001)
    u0, v0 = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - u0, v - v0
    return (image[v0, u0] * (1 - fu) * (1 - fv) + image[v0, u0 + 1] * fu * (1 - fv)
            + image[v0 + 1, u0] * (1 - fu) * fv + image[v0 + 1, u0 + 1] * fu * fv)


def gt_errors(view_a, view_b, uv_a: np.ndarray, uv_b: np.ndarray) -> np.ndarray:
    """Ground-truth error ``[N]`` in pixels of each match (inf when the point is hidden in b)."""
    if len(uv_a) == 0:
        return np.zeros(0)
    depth = bilinear(view_a.depth.astype(np.float64), uv_a)
    world = view_a.camera.unproject(uv_a, depth)
    projected, z = view_b.camera.project(world)
    error = np.linalg.norm(projected - uv_b, axis=1)
    seen = bilinear(view_b.depth.astype(np.float64), np.nan_to_num(projected))
    visible = np.isfinite(seen) & np.isfinite(error) & (np.abs(seen - z) < 0.01 * z)
    error[~visible] = np.inf
    return error


def relative_pose(view_a, view_b) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth rotation and translation taking b's camera frame into a's."""
    rotation = view_a.camera.rotation @ view_b.camera.rotation.T
    return rotation, view_a.camera.translation - rotation @ view_b.camera.translation


def rotation_angle(rotation: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1))))


def gt_pointmap(view, index: int, relief: float = 1.0) -> Pointmap:
    """Own-frame pointmap from the exact depth; ``relief != 1`` scales depth about its mean."""
    depth = view.depth.astype(np.float64)
    if relief != 1.0:
        mean = np.nanmean(depth[view.mask])
        depth = mean + relief * (depth - mean)
    depth = np.where(view.mask, depth, np.nan)
    K = view.camera.K
    u, v = np.meshgrid(np.arange(view.width, dtype=np.float64), np.arange(view.height, dtype=np.float64))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)
    points = (rays * depth[..., None]).astype(np.float32)
    confidence = np.where(np.isfinite(depth), 1.0, 0.0).astype(np.float32)
    return Pointmap(index, points, confidence, float(K[0, 0]))


# ------------------------------------------------------------------------------------------------
# Data sets
# ------------------------------------------------------------------------------------------------

def datasets(seeds: int, quick: bool):
    """``(label, [(kind, view_a, view_b, index_a, index_b), ...])`` per data set."""
    out = []
    uwa = [synthesize(seed, SynthConfig(size=(640, 512))).capture for seed in range(seeds)]
    pairs = []
    for capture in uwa:
        left, center, right = capture.views
        pairs += [("left-center", left, center, 0, 1), ("center-right", center, right, 1, 2),
                  ("left-right (90 deg)", left, right, 0, 2)]
    out.append(("uwa 640x512", pairs))
    big_seeds = 1 if quick else min(seeds, 2)
    pairs = []
    for seed in range(big_seeds):
        left, center, right = synthesize(seed, SynthConfig(size=(1280, 1024))).capture.views
        pairs += [("left-center", left, center, 0, 1), ("center-right", center, right, 1, 2)]
    out.append(("uwa 1280x1024", pairs))
    pairs = []
    for seed in range(1 if quick else seeds):
        result = synthesize(seed, SynthConfig(rig="cfpose", size=(512, 640), poses=4))
        views = result.capture.views
        roll = {name: pose["roll_deg"] for name, pose in result.capture.metadata["poses"].items()}
        order = sorted(range(len(views)), key=lambda i: roll[views[i].name])
        for first, second in zip(order, order[1:]):
            difference = abs(roll[views[second].name] - roll[views[first].name])
            pairs.append((f"neighbour rolls ({difference:.0f} deg)", views[first], views[second], first, second))
    out.append(("cfpose 512x640", pairs))
    return out, uwa


# ------------------------------------------------------------------------------------------------
# Tables
# ------------------------------------------------------------------------------------------------

def matching_table(data, labels) -> list[str]:
    lines = ["| data | pair | method | matches/pair | within 2 px | median err px | pairs with matches | s/pair |",
             "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: |"]
    for data_label, pairs in data:
        groups = defaultdict(list)
        for kind, view_a, view_b, _, _ in pairs:
            key = "neighbour rolls" if kind.startswith("neighbour") else kind
            groups[key].append((kind, view_a, view_b))
        for kind, members in groups.items():
            for label in labels:
                method, options = METHOD_SPECS[label]
                counts, errors, seconds, nonempty = [], [], [], 0
                for _, view_a, view_b in members:
                    start = time.perf_counter()
                    matches = match_views(view_a.image, view_a.mask, view_b.image, view_b.mask,
                                          method=method, **options)
                    seconds.append(time.perf_counter() - start)
                    counts.append(len(matches))
                    nonempty += len(matches) > 0
                    errors.append(gt_errors(view_a, view_b, matches.uv_a, matches.uv_b))
                pooled = np.concatenate(errors)
                within = f"{np.mean(pooled < 2):.2f}" if len(pooled) else "-"
                median = f"{np.median(pooled):.2f}" if len(pooled) else "-"
                detail = "" if kind != "neighbour rolls" else " (" + ", ".join(k.split("(")[1].rstrip(")") for k, _, _ in members if "(" in k) + ")"
                lines.append(f"| {data_label} | {kind}{detail} | {label} | {statistics.mean(counts):.1f} "
                             f"(min {min(counts)}) | {within} | {median} | {nonempty}/{len(members)} | "
                             f"{statistics.mean(seconds):.2f} |")
    return lines


def registration_table(uwa_captures) -> list[str]:
    backends = [("exact depth", lambda view, i: gt_pointmap(view, i)),
                ("depth relief x1.3", lambda view, i: gt_pointmap(view, i, 1.3)),
                ("depth relief x0.7", lambda view, i: gt_pointmap(view, i, 0.7))]
    try:
        from fingersplat3d.pointmaps import get_backend

        prior = get_backend("prior")
        backends.append(("prior backend", lambda view, i: prior.predict_views([view])[0]))
    except Exception as error:  # noqa: BLE001 - report, do not fail the bench
        print(f"(prior backend unavailable: {error})", file=sys.stderr)
    lines = ["| pointmaps | pair | rotation err deg (median / max) | scale err % (median) | inliers/pair | rel. residual | ok |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: |"]
    matched = []
    for capture in uwa_captures:
        left, center, right = capture.views
        for kind, view_a, view_b, ia, ib in (("left-center", left, center, 0, 1), ("center-right", center, right, 1, 2)):
            matches = match_views(view_a.image, view_a.mask, view_b.image, view_b.mask, method=DEFAULT_METHOD)
            matched.append((kind, view_a, view_b, ia, ib, matches))
    for backend_label, make in backends:
        for kind in ("left-center", "center-right"):
            rotation_errors, scale_errors, inliers, residuals, ok = [], [], [], [], 0
            for pair_kind, view_a, view_b, ia, ib, matches in matched:
                if pair_kind != kind:
                    continue
                pointmap_a, pointmap_b = make(view_a, ia), make(view_b, ib)
                result = register_pair(pointmap_a, pointmap_b, matches)
                if not result.ok:
                    continue
                ok += 1
                rotation, _ = relative_pose(view_a, view_b)
                rotation_errors.append(rotation_angle(result.b_to_a.rotation @ rotation.T))
                # Scale of b's units in a's units: ratio of the two pointmaps' mean depths for GT-like maps.
                depth_a = np.nanmedian(pointmap_a.depth[view_a.mask]) / np.nanmedian(view_a.depth[view_a.mask])
                depth_b = np.nanmedian(pointmap_b.depth[view_b.mask]) / np.nanmedian(view_b.depth[view_b.mask])
                scale_errors.append(100 * abs(result.b_to_a.scale / (depth_a / depth_b) - 1))
                inliers.append(result.n_inliers)
                residuals.append(result.residual)
            total = sum(1 for m in matched if m[0] == kind)
            if rotation_errors:
                lines.append(f"| {backend_label} | {kind} | {np.median(rotation_errors):.2f} / {np.max(rotation_errors):.2f} | "
                             f"{np.median(scale_errors):.1f} | {np.mean(inliers):.1f} | {np.median(residuals):.3f} | {ok}/{total} |")
            else:
                lines.append(f"| {backend_label} | {kind} | - | - | - | - | 0/{total} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="one seed, fewer data")
    parser.add_argument("--methods", default=",".join(METHOD_SPECS),
                        help=f"comma-separated subset of {', '.join(METHOD_SPECS)}")
    parser.add_argument("--out", help="also write the tables to this markdown file")
    args = parser.parse_args(argv)
    labels = [label.strip() for label in args.methods.split(",") if label.strip()]
    unknown = [label for label in labels if label not in METHOD_SPECS]
    if unknown:
        parser.error(f"unknown methods {unknown}; choose from {', '.join(METHOD_SPECS)}")
    cv2.setNumThreads(1)
    seeds = 1 if args.quick else args.seeds
    data, uwa = datasets(seeds, args.quick)
    text = [f"Machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}, "
            f"OpenCV {cv2.__version__}, single thread; seeds 0..{seeds - 1}.", "",
            "### Matching", "", *matching_table(data, labels), "",
            "### Pair registration (uwa 640x512, default matches)", "", *registration_table(uwa), ""]
    output = "\n".join(text)
    print(output)
    if args.out:
        with open(args.out, "w") as handle:
            handle.write(output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
