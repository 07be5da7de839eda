"""Benchmark the ``prior`` pointmap backend against synthetic ground truth.

    python tools/bench_prior.py [--uwa-seeds 5] [--cfpose-seeds 3] [--out FILE.md] [--quick]

Per view it measures, inside the ground-truth mask:

* **depth MAE (mm)** after a least-squares scale-and-shift fit of the predicted depth to the
  ground-truth depth (monocular relief is known up to scale and shift);
* **depth MAE after scale, shift and tilt** (a plane in u, v): what is left once a ramp that no
  silhouette can reveal (finger pitch, roll) is removed, as the global alignment's smooth
  per-view correction can;
* **3D error (mm)**: mean point distance after a least-squares similarity (rotation, translation,
  scale; Umeyama) fit of the predicted camera-frame points to the ground-truth ones. Unlike the
  depth MAE this sees the relief-to-width proportion (``depth_ratio``) and the focal guess.

Rigs: ``uwa`` 640x512 (views ``center`` frontal, ``left``/``right`` at 45 degrees) over seeds
0..N-1, and ``cfpose`` 512x640 with 4 poses (``p1`` frontal, ``p2..p4`` rolled/pitched) over seeds
100..100+M-1 (other fingers). Methods: the backend as shipped, on the ground-truth mask and on ``finger_mask``; naive
baselines (flat, distance-transform tent, one global sphere radius); the distance-transform
inflation with a local radius from the medial axis (raw and smoothed); ablations of the
shipped swept-section model (orthographic, unsmoothed). All but the flat and tent baselines are
ray cast in perspective like the backend; and the best ``depth_ratio`` per view type by the 3D error.

Prints markdown tables (and writes them to ``--out``).
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from dataclasses import replace

import cv2
import numpy as np

from fingersplat3d.errors import run_script
from fingersplat3d.pointmaps.prior import PriorBackend, finger_height, height_to_points
from fingersplat3d.segment.masks import finger_mask, mask_iou
from fingersplat3d.synth import SynthConfig, synthesize

CFPOSE_SEED_OFFSET = 100
RATIOS = np.round(np.arange(0.5, 1.31, 0.05), 2)


# ----------------------------------------------------------------------------------------------
# Metrics
# ----------------------------------------------------------------------------------------------

def scale_shift_mae(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray) -> float:
    """MAE of ``a * pred + b`` against ``gt`` over ``mask`` (finite in both), ``a, b`` least squares."""
    used = mask & np.isfinite(pred) & np.isfinite(gt)
    p, g = pred[used].astype(np.float64), gt[used].astype(np.float64)
    design = np.stack([p, np.ones_like(p)], axis=1)
    (a, b), *_ = np.linalg.lstsq(design, g, rcond=None)
    return float(np.mean(np.abs(a * p + b - g)))


def similarity_error(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean distance after the least-squares similarity ``s R pred + t ~ gt`` (Umeyama), ``[N, 3]``."""
    pred, gt = pred.astype(np.float64), gt.astype(np.float64)
    mp, mg = pred.mean(0), gt.mean(0)
    p, g = pred - mp, gt - mg
    u, sigma, vt = np.linalg.svd(g.T @ p / len(p))
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rotation = u @ d @ vt
    scale = np.trace(np.diag(sigma) @ d) / np.mean(np.sum(p * p, axis=1))
    return float(np.mean(np.linalg.norm(scale * p @ rotation.T - g, axis=1)))


def camera_points(view) -> np.ndarray:
    """Ground-truth camera-frame points ``[H, W, 3]`` (NaN off the finger)."""
    cam = view.camera
    return cam.pixel_directions(cam.pixel_grid()) * view.depth[..., None].astype(np.float64)


# ----------------------------------------------------------------------------------------------
# Alternatives to the shipped model (heights in pixels on a mask)
# ----------------------------------------------------------------------------------------------

def ray_cast(height: np.ndarray, focal: float, iterations: int = 8) -> np.ndarray:
    """Perspective relief of an orthographic height image (the backend's fixed point, by remap)."""
    rows, cols = height.shape
    cu, cv_ = (cols - 1) / 2.0, (rows - 1) / 2.0
    u, v = np.meshgrid(np.arange(cols, dtype=np.float32) - cu, np.arange(rows, dtype=np.float32) - cv_)
    height = height.astype(np.float32)
    relief = height
    for _ in range(iterations):
        shrink = 1.0 - relief / focal
        relief = cv2.remap(height, cu + u * shrink, cv_ + v * shrink, cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    return relief


def distance(mask: np.ndarray) -> np.ndarray:
    """Euclidean distance to the outline; the image border does not count as outline."""
    return cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5)


def height_tent(mask: np.ndarray) -> np.ndarray:
    return distance(mask)


def height_global_sphere(mask: np.ndarray) -> np.ndarray:
    dt = distance(mask)
    radius = dt.max()
    return np.sqrt(np.maximum(2 * radius * dt - dt * dt, 0.0))


def height_medial(mask: np.ndarray, smooth: bool) -> np.ndarray:
    """Inflation ``sqrt(2 R dt - dt^2)`` with R the distance value at the nearest medial-axis pixel."""
    dt = distance(mask)
    skeleton = cv2.ximgproc.thinning(mask.astype(np.uint8) * 255) > 0
    if not skeleton.any():
        skeleton = dt >= dt.max()
    _, labels = cv2.distanceTransformWithLabels((~skeleton).astype(np.uint8), cv2.DIST_L2, 5,
                                                labelType=cv2.DIST_LABEL_PIXEL)
    radius_of_label = np.concatenate([[0.0], dt[skeleton]])  # labels count zero pixels in raster order
    radius = radius_of_label[labels].astype(np.float32)
    if smooth:
        sigma = 0.5 * float(np.median(dt[skeleton]))
        weight = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), sigma)
        radius = cv2.GaussianBlur(radius * mask, (0, 0), sigma) / np.maximum(weight, 1e-6)
    radius = np.maximum(radius, dt)
    return np.where(mask, np.sqrt(np.maximum(2 * radius * dt - dt * dt, 0.0)), 0.0)


# ----------------------------------------------------------------------------------------------
# The run
# ----------------------------------------------------------------------------------------------

def view_type(rig: str, name: str) -> str:
    if rig == "uwa":
        return "uwa frontal" if name == "center" else "uwa 45 deg"
    return "cfpose frontal" if name == "p1" else "cfpose rolled"


def captures(uwa_seeds: int, cfpose_seeds: int):
    for seed in range(uwa_seeds):
        yield "uwa", seed, synthesize(seed, SynthConfig(rig="uwa", size=(640, 512))).capture
    for seed in range(cfpose_seeds):
        seed += CFPOSE_SEED_OFFSET  # other fingers than the uwa seeds
        yield "cfpose", seed, synthesize(seed, SynthConfig(rig="cfpose", size=(512, 640), poses=4)).capture


def scale_plane_mae(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray) -> float:
    """MAE of ``a * pred + b + c u + d v`` against ``gt``: the error left once an unobservable tilt
    (finger pitch, roll seen as a ramp) is removed, as the global alignment's polynomial can."""
    used = mask & np.isfinite(pred) & np.isfinite(gt)
    v, u = np.nonzero(used)
    p, g = pred[used].astype(np.float64), gt[used].astype(np.float64)
    design = np.stack([p, np.ones_like(p), u / 100.0, v / 100.0], axis=1)
    solution, *_ = np.linalg.lstsq(design, g, rcond=None)
    return float(np.mean(np.abs(design @ solution - g)))


def run(uwa_seeds: int, cfpose_seeds: int) -> str:
    shipped = PriorBackend()
    ratio = shipped.depth_ratio

    def section(**options):
        return lambda m, f: finger_height(m, ratio, **{"smoothing": shipped.smoothing, "focal": f, **options}).height

    height_methods = {
        "flat (h = 0)": lambda m, f: np.zeros(m.shape, np.float32),
        "tent (h = dt)": lambda m, f: ratio * height_tent(m),
        "global sphere (R = max dt)": lambda m, f: ray_cast(ratio * height_global_sphere(m), f),
        "dt + medial radius, raw": lambda m, f: ray_cast(ratio * height_medial(m, smooth=False), f),
        "dt + medial radius, smoothed": lambda m, f: ray_cast(ratio * height_medial(m, smooth=True), f),
        "section, orthographic": section(focal=None),
        "section, no smoothing": section(smoothing=0.0),
        "section (shipped)": section(),
    }
    rows: dict[str, dict[str, list[float]]] = {}  # method -> view type -> depth MAE per view
    rows_plane: dict[str, dict[str, list[float]]] = {}
    rows3d: dict[str, dict[str, list[float]]] = {}
    ratio_errors: dict[str, list[np.ndarray]] = {}
    conf_bins = np.array([0.0, 0.25, 0.5, 0.75, 0.999, 1.01])
    conf_sum = np.zeros((2, len(conf_bins) - 1))  # scale-shift, scale-shift-tilt residuals
    conf_count = np.zeros(len(conf_bins) - 1)
    ious, seg_ms, prior_ms = [], [], []

    def record(table, method, kind, value):
        table.setdefault(method, {}).setdefault(kind, []).append(value)

    def score(method, kind, points, mask):
        record(rows, method, kind, scale_shift_mae(points[..., 2], gt_depth, mask))
        record(rows_plane, method, kind, scale_plane_mae(points[..., 2], gt_depth, mask))
        if method != "flat (h = 0)":
            used = mask & np.isfinite(points[..., 2])
            record(rows3d, method, kind, similarity_error(points[used], gt_points[used]))

    for rig, seed, capture in captures(uwa_seeds, cfpose_seeds):
        print(f"{rig} seed {seed}", file=sys.stderr)
        for view in capture.views:
            kind = view_type(rig, view.name)
            gt_mask, gt_depth, gt_points = view.mask, view.depth, camera_points(view)
            focal = shipped.focal_factor * max(view.width, view.height)
            clock = time.perf_counter()
            predicted_mask = finger_mask(view.image, name=view.name)
            seg_ms.append(1e3 * (time.perf_counter() - clock))
            ious.append(mask_iou(predicted_mask, gt_mask))
            for method, height_of in height_methods.items():
                score(method, kind, height_to_points(height_of(gt_mask, focal), gt_mask, focal), gt_mask)
            # The backend end to end, on the ground-truth mask and on its own segmentation.
            for label, source in (("backend, GT mask", view), ("backend, finger_mask", replace(view, mask=None))):
                clock = time.perf_counter()
                pointmap = shipped.predict_views([source])[0]
                if label.endswith("GT mask"):
                    prior_ms.append(1e3 * (time.perf_counter() - clock))
                    # Confidence calibration: aligned depth error per confidence bin.
                    used = gt_mask & pointmap.valid
                    v, u = np.nonzero(used)
                    p, g = pointmap.depth[used].astype(np.float64), gt_depth[used].astype(np.float64)
                    which = np.digitize(pointmap.confidence[used], conf_bins) - 1
                    np.add.at(conf_count, which, 1)
                    for column, design in enumerate((np.stack([p, np.ones_like(p)], 1),
                                                     np.stack([p, np.ones_like(p), u / 100.0, v / 100.0], 1))):
                        solution, *_ = np.linalg.lstsq(design, g, rcond=None)
                        np.add.at(conf_sum[column], which, np.abs(design @ solution - g))
                score(label, kind, np.where(pointmap.valid[..., None], pointmap.points, np.nan), gt_mask)
            # Best depth ratio by the 3D error.
            errors = []
            for candidate in RATIOS:
                height = finger_height(gt_mask, float(candidate), shipped.smoothing, focal=focal).height
                points = height_to_points(height, gt_mask, focal)
                errors.append(similarity_error(points[gt_mask], gt_points[gt_mask]))
            ratio_errors.setdefault(kind, []).append(np.array(errors))

    kinds = ["uwa frontal", "uwa 45 deg", "cfpose frontal", "cfpose rolled"]
    out = [f"Machine: {platform.machine()}, {platform.processor() or 'cpu'}, Python {platform.python_version()}; "
           f"uwa seeds 0..{uwa_seeds - 1} (640x512, 3 views), "
           f"cfpose seeds {CFPOSE_SEED_OFFSET}..{CFPOSE_SEED_OFFSET + cfpose_seeds - 1} "
           "(512x640, 4 poses); focal guess 3 x max(W, H) (true: 3.33 x).", ""]

    def table(title, data):
        out.extend([f"### {title}", "",
                    "| method | " + " | ".join(kinds) + " | all views |",
                    "|---|" + "---:|" * (len(kinds) + 1)])
        for method, by_kind in data.items():
            cells = [f"{np.mean(by_kind[k]):.3f} ± {np.std(by_kind[k]):.3f}" if k in by_kind else "-" for k in kinds]
            every = np.concatenate([by_kind[k] for k in kinds if k in by_kind])
            out.append(f"| {method} | " + " | ".join(cells) + f" | {np.mean(every):.3f} (max {np.max(every):.3f}) |")
        out.append("")

    table("Depth MAE (mm) after scale-and-shift alignment, inside the GT mask (mean ± std over views)", rows)
    table("Depth MAE (mm) after scale, shift and tilt (plane in u, v) alignment, inside the GT mask", rows_plane)
    table(f"3D error (mm) after similarity alignment, all methods at depth_ratio {ratio} "
          "(sees depth_ratio and focal)", rows3d)

    out.extend([f"### Best depth_ratio by 3D error (median over views of the argmin; error at {ratio} "
                "and at the best)", "",
                f"| view type | best ratio (median, range) | 3D error at shipped {ratio} | at per-type best |",
                "|---|---:|---:|---:|"])
    for kind in kinds:
        errors = np.stack(ratio_errors[kind])
        best = RATIOS[np.argmin(errors, axis=1)]
        column = int(np.argmin(errors.mean(0)))
        at_default = errors[:, int(np.argmin(np.abs(RATIOS - ratio)))].mean()
        out.append(f"| {kind} | {np.median(best):.2f} ({best.min():.2f}-{best.max():.2f}) | {at_default:.3f} | "
                   f"{errors[:, column].mean():.3f} (at {RATIOS[column]:.2f}) |")
    pooled = np.concatenate([np.stack(ratio_errors[k]) for k in kinds]).mean(0)
    out.extend(["", f"Pooled over all views, the 3D error is lowest at depth_ratio {RATIOS[np.argmin(pooled)]:.2f} "
                f"({pooled.min():.3f} mm; {pooled[int(np.argmin(np.abs(RATIOS - ratio)))]:.3f} mm at {ratio}).", ""])

    out.extend(["### Confidence vs aligned depth error (shipped backend, GT mask, all views)", "",
                "| confidence | share of pixels | depth MAE (mm), scale-shift | depth MAE (mm), scale-shift-tilt |",
                "|---|---:|---:|---:|"])
    for k in range(len(conf_bins) - 1):
        if conf_count[k]:
            hi = "1" if k == len(conf_bins) - 2 else f"{conf_bins[k + 1]:.2f}"
            out.append(f"| [{conf_bins[k]:.2f}, {hi}) | {conf_count[k] / conf_count.sum():.1%} | "
                       f"{conf_sum[0, k] / conf_count[k]:.3f} | {conf_sum[1, k] / conf_count[k]:.3f} |")
    out.extend(["", "### Segmentation and speed", "",
                f"finger_mask IoU vs GT mask: mean {np.mean(ious):.4f}, min {np.min(ious):.4f} "
                f"over {len(ious)} views.  ",
                f"finger_mask: median {np.median(seg_ms):.1f} ms per view; prior backend (GT mask given): "
                f"median {np.median(prior_ms):.1f} ms per view (640x512 / 512x640).", ""])
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--uwa-seeds", type=int, default=5)
    parser.add_argument("--cfpose-seeds", type=int, default=3)
    parser.add_argument("--out", help="also write the tables to this markdown file")
    parser.add_argument("--quick", action="store_true", help="smoke run: one seed per rig")
    args = parser.parse_args(argv)
    uwa, cfpose = (1, 1) if args.quick else (args.uwa_seeds, args.cfpose_seeds)
    text = run(uwa, cfpose)
    print(text)
    if args.out:
        with open(args.out, "w") as handle:
            handle.write(text + "\n")


if __name__ == "__main__":
    sys.exit(run_script(main))
