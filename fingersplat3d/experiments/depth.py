"""``fs3d eval depth``: the paper's depth experiment (PolyU 3D+) as a command.

Cases come from two sources:

* **PolyU 3D+** (or any images with per-image MATLAB height maps): images paired with ``.mat``
  files by name (file stem, case-insensitive); each image is reconstructed alone, in monocular
  mode (the paper feeds one image, or the same image twice), and its depth is compared with the
  height map read by :func:`fingersplat3d.io.polyu.read_height_map`. Unpaired files are reported.
* **Capture folders with ``depth/``** (``fs3d synth``): the whole capture is fused and every view's
  depth compared with its ground truth.

The metric is :func:`fingersplat3d.eval.depth_errors` inside the ground truth's valid pixels (and
the capture's mask): mean absolute error after a least-squares scale + shift and after a scale
only, and a confidence-weighted variant (the reconstruction's per-pixel confidence as weights). The scale + shift
error is also split by where a second view backs the view's surface (``report.json``'s ``backed_by_two_views``, pixel
by pixel: :func:`~fingersplat3d.eval.depth.split_by_backing`): the skin whose depth the photos measured, and the skin
this view alone sees, whose depth is the pointmap's guess held to the other views' outlines.
Units are the ground truth's. Results: ``depth_errors.csv`` (one row per image or view, failures
included with their reason), ``summary.md`` and ``error_maps/<name>.png``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import FS3DError, InputError
from ..eval import depth_errors
from ..eval.depth import split_by_backing
from ..io.depth import depth_colormap
from ..io.images import IMAGE_SUFFIXES, find_files
from .tables import write_rows

__all__ = ["DepthCase", "PAPER_FIGURES", "pair_by_name", "polyu_cases", "capture_cases", "run_depth_evaluation"]

PAPER_FIGURES = {"Cui et al.": 2.9577, "FingerSplat": 1.7876}
"""The paper's "weighted depth error" on PolyU 3D+ (mm). Its weighting is not defined there, so the
figures here are beside them, not comparable digit for digit."""
COLUMNS = ("name", "status", "reason", "pixels", "coverage", "mae_scale_shift", "mae_scale", "mae_weighted",
           "rmse_scale_shift", "median_scale_shift", "scale", "share_two_views", "mae_two_views", "mae_one_view")


@dataclass(frozen=True)
class DepthCase:
    """One reconstruction to score: an image (PolyU) or a capture folder, and its truth."""

    name: str
    source: str  # one image, or one capture folder
    truth: str | None  # the .mat file (PolyU), None for a capture folder (its depth/)


def pair_by_name(images: list[Path], truths: list[Path]) -> tuple[list[tuple[Path, Path]], list[Path], list[Path]]:
    """Images and truth files with the same stem (case-insensitive): ``(pairs, unpaired images,
    unpaired truths)``. A stem held twice on one side is an ``InputError``."""
    def by_stem(paths: list[Path], what: str) -> dict[str, Path]:
        table: dict[str, Path] = {}
        for path in paths:
            key = path.stem.lower()
            if key in table:
                raise InputError(f"two {what} files are named {path.stem!r}: {table[key]} and {path}")
            table[key] = path
        return table

    image_by, truth_by = by_stem(images, "image"), by_stem(truths, "ground-truth")
    pairs = [(image_by[k], truth_by[k]) for k in sorted(image_by) if k in truth_by]
    return (pairs, [image_by[k] for k in sorted(image_by) if k not in truth_by],
            [truth_by[k] for k in sorted(truth_by) if k not in image_by])


def polyu_cases(inputs: list[Path], truth: Path) -> tuple[list[DepthCase], list[Path], list[Path]]:
    """Cases from images (files or folders) and a folder of ``.mat`` height maps."""
    if not truth.is_dir():
        raise InputError(f"{truth}: the ground-truth folder does not exist")
    images = find_files(inputs, IMAGE_SUFFIXES)
    mats = find_files([truth], (".mat",))
    if not images:
        raise InputError(f"no images found in {', '.join(map(str, inputs))}")
    if not mats:
        raise InputError(f"{truth}: holds no .mat files")
    pairs, lonely_images, lonely_truths = pair_by_name(images, mats)
    return [DepthCase(image.stem, str(image), str(mat)) for image, mat in pairs], lonely_images, lonely_truths


def capture_cases(inputs: list[Path]) -> list[DepthCase]:
    """One case per capture folder holding ground-truth depth (``depth/``)."""
    from ..io.capture import is_capture_folder

    cases = []
    for path in inputs:
        if not is_capture_folder(path):
            raise InputError(f"{path}: not a capture folder (give --truth FOLDER for images with .mat height maps)")
        cases.append(DepthCase(path.name, str(path), None))
    return cases


def _truths(case: DepthCase, capture) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    """(name, ground-truth depth, mask) per view to score."""
    if case.truth is not None:
        from ..io.polyu import depth_from_height, read_height_map

        return [(case.name, depth_from_height(read_height_map(case.truth)), None)]
    views = [(f"{case.name}/{v.name}", v.depth, v.mask) for v in capture.views if v.depth is not None]
    if not views:
        raise InputError(f"{case.source}: the capture holds no ground-truth depth (depth/)")
    return views


def _on_grid(pred: np.ndarray, shape: tuple[int, int], name: str) -> np.ndarray:
    """``pred`` resampled (nearest) to the truth's ``shape``; the aspect ratios must agree within 2 %."""
    if pred.shape == shape:
        return pred
    ratio = (pred.shape[1] / pred.shape[0]) / (shape[1] / shape[0])
    if abs(ratio - 1.0) > 0.02:
        raise InputError(f"{name}: the image is {pred.shape[1]}x{pred.shape[0]} but its height map "
                         f"{shape[1]}x{shape[0]}; their aspect ratios differ")
    return cv2.resize(pred, (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST)


def _score(name: str, pred: np.ndarray, confidence: np.ndarray, truth: np.ndarray, mask: np.ndarray | None,
           maps: Path, backing: np.ndarray | None = None) -> dict:
    """One view's row; ``backing``: its :func:`~fingersplat3d.align.transfer.multi_view_backing` map (any stride), None
    where it was not placed (the split's cells then empty)."""
    pred = _on_grid(np.asarray(pred, np.float64), truth.shape, name)
    confidence = _on_grid(np.asarray(confidence, np.float64), truth.shape, name)
    weights = np.where(np.isfinite(confidence), np.clip(confidence, 0.0, None), 0.0)
    try:
        shifted = depth_errors(pred, truth, mask, align="scale_shift")
        scaled = depth_errors(pred, truth, mask, align="scale")
        weighted = depth_errors(pred, truth, mask, align="scale_shift", weights=weights)
    except ValueError as error:  # no pixel where both have depth
        raise InputError(f"{name}: {error}") from None
    aligned = shifted.scale * pred + shifted.shift
    error = np.abs(aligned - truth)
    picture = depth_colormap(np.where(np.isfinite(error), error, np.nan))
    path = maps / (name.replace("/", "__") + ".png")
    cv2.imwrite(str(path), picture[..., ::-1])
    row = {"name": name, "status": "done", "reason": "", "pixels": shifted.n, "coverage": round(shifted.coverage, 4),
           "mae_scale_shift": shifted.mae, "mae_scale": scaled.mae, "mae_weighted": weighted.mae,
           "rmse_scale_shift": shifted.rmse, "median_scale_shift": shifted.median_abs, "scale": shifted.scale}
    if backing is not None:
        split = split_by_backing(pred, truth, mask, shifted, backing)
        row.update(share_two_views=round(split.share_two_views, 4), mae_two_views=split.mae_two_views,
                   mae_one_view=split.mae_one_view)
    return row


def _evaluate(case: DepthCase, config, maps: Path) -> list[dict]:
    from ..io.datasets import load_any
    from ..pipeline import fuse

    captures = load_any(case.source)
    if len(captures) != 1:
        raise InputError(f"{case.source}: holds {len(captures)} captures, not one")
    capture = captures[0]
    truths = _truths(case, capture)
    result = fuse(capture, config)
    rows = []
    for index, (name, truth, mask) in enumerate(truths):
        view = index if case.truth is None else 0
        backing = result.backing[view] if result.backing is not None else None
        rows.append(_score(name, result.depths[view], result.confidences[view], truth, mask, maps, backing))
    return rows


def run_depth_evaluation(cases: list[DepthCase], out: Path, config, *, unpaired: tuple[list[Path], list[Path]] = ([], []),
                         progress: bool = True) -> list[dict]:
    """Score every case; write ``depth_errors.csv``, ``summary.md`` and ``error_maps/``. A case that
    fails (unreadable file, no finger found) is a row with its reason, not the end of the run."""
    from tqdm import tqdm

    out.mkdir(parents=True, exist_ok=True)
    maps = out / "error_maps"
    maps.mkdir(exist_ok=True)
    rows: list[dict] = []
    for case in tqdm(cases, desc="fs3d eval depth", unit="image", disable=not progress):
        try:
            rows += _evaluate(case, config, maps)
        except FS3DError as error:
            rows.append({"name": case.name, "status": "failed", "reason": str(error)})
    write_rows(out / "depth_errors.csv", COLUMNS, rows)
    (out / "summary.md").write_text(summary_markdown(rows, unpaired))
    return rows


def summary_markdown(rows: list[dict], unpaired: tuple[list[Path], list[Path]] = ([], [])) -> str:
    done = [r for r in rows if r["status"] == "done"]
    lines = ["# Depth error", "",
             f"{len(done)} of {len(rows)} images or views scored (errors in the ground truth's units, "
             "mm for PolyU 3D+ and `fs3d synth`).", ""]
    if done:
        lines += ["| statistic | scale + shift | scale only | confidence-weighted |", "|---|---|---|---|"]
        for label, reduce in (("mean", np.mean), ("median", np.median)):
            values = [reduce([r[k] for r in done]) for k in ("mae_scale_shift", "mae_scale", "mae_weighted")]
            lines.append(f"| {label} MAE | " + " | ".join(f"{v:.4f}" for v in values) + " |")
        lines += ["", _backed_line(done)]
        lines += ["", "The paper's weighted depth error on PolyU 3D+: " + ", ".join(
            f"{k} {v} mm" for k, v in PAPER_FIGURES.items()) + ". Its weighting is not defined there; the "
            "confidence-weighted column is this tool's reading of it, so compare orders of magnitude, not digits."]
    failed = [r for r in rows if r["status"] != "done"]
    if failed:
        lines += ["", "Failed:", ""] + [f"- {r['name']}: {r['reason']}" for r in failed]
    images, truths = unpaired
    if images or truths:
        lines += ["", f"Unpaired: {len(images)} image(s) without a height map, {len(truths)} height map(s) without an image.", ""]
        lines += [f"- image {p}" for p in images] + [f"- height map {p}" for p in truths]
    return "\n".join(lines) + "\n"


def _backed_line(done: list[dict]) -> str:
    """The summary's sentence on the error split by a second view's backing (means over the views that have each
    part)."""
    def mean_of(key: str) -> float:
        values = [r[key] for r in done if np.isfinite(r.get(key, np.nan))]  # absent: a view not placed
        return float(np.mean(values)) if values else float("nan")

    share, two, one = mean_of("share_two_views"), mean_of("mae_two_views"), mean_of("mae_one_view")
    if not np.isfinite(share):
        return "No view was placed, so the error is not split by a second view's backing."
    if not np.isfinite(two):
        return (f"No second view backs any scored pixel (a single photo: its depth is the pointmap's guess); MAE "
                f"after scale + shift {one:.4f}.")
    return (f"Split by where a second view backs the surface (mean over the views): the skin two views see, "
            f"{100 * share:.0f} % of the scored pixels, MAE after scale + shift {two:.4f}; the skin one view alone sees "
            f"(its depth the pointmap's guess held to the other views' outlines) "
            + ("none." if not np.isfinite(one) else f"{one:.4f}."))
