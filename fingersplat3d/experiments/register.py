"""``fs3d eval register``: the paper's 3D-registration experiment (minutiae carried between views).

For each reconstruction folder and each pair of views (by default its middle camera to each other
camera: 45 degrees apart on the UWA rig), minutiae of view A are carried into view B three ways
and compared with their *mates* in B (mean pixel distance, the paper's metric):

* **3D**: through the reconstruction (A's depth and camera, then B's camera;
  :func:`fingersplat3d.align.transfer.transfer_points`);
* **rigid 2D** and **TPS**: the paper's 2D baselines fitted to the mates themselves
  (:mod:`fingersplat3d.eval.warp2d`), each mate scored by a model fitted without it (5-fold
  cross-validation), which is as much as a 2D method can be given.

Mates come from, in this order: a CSV of the user's (``view_a, view_b, x_a, y_a, x_b, y_b``),
ground truth (``minutiae.json``: the minutiae visible in both views; found beside the capture's
``images/`` or given), or the paper's "UWA*" protocol: mindtct minutiae of both photos paired the
way bozorth3 pairs them (:mod:`fingersplat3d.eval.minutiae_pairs`). Every method is scored on the
same mates: those the 3D model could carry (on the surface in A, in B's frame and not hidden);
how many that was is reported.

Writes ``register_errors.csv`` (one row per pair and method), ``mates/<rec>__<A>__<B>.csv``,
``pictures/<rec>__<A>__<B>.png`` (view B with the mates and where each method put them) and
``summary.md`` beside the paper's figures.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import FS3DError, InputError
from ..io.reconstruction_folder import ReconstructionFolder
from .tables import write_rows

__all__ = ["PAPER_FIGURES", "Mates", "default_pairs", "read_mates_csv", "truth_mates", "matcher_mates",
           "pair_textures", "warp_check", "run_register_evaluation"]

PAPER_FIGURES = {"rigid 2D": 52.27, "TPS": 26.18, "VGGT": 10.45, "FingerSplat": 13.94}
"""The paper's mean distance (px) between mapped and mated minutiae on UWA ("UWA*" mates)."""
METHODS = ("3D", "rigid 2D", "TPS")
COLUMNS = ("reconstruction", "view_a", "view_b", "mates_source", "mates", "scored", "method", "mean_px",
           "median_px", "p90_px", "warp_shift_px", "warp_ncc", "warp_ncc_flowed", "warp_residual_depth_px",
           "warp_residual_pose_px", "warp_fitted", "status", "reason")
COLOURS = {"3D": (40, 40, 230), "rigid 2D": (230, 160, 40), "TPS": (200, 60, 200)}  # BGR


@dataclass(frozen=True)
class Mates:
    """Mated minutiae of two views: ``xy_a[k]`` in A is ``xy_b[k]`` in B."""

    xy_a: np.ndarray  # [N, 2] pixels
    xy_b: np.ndarray  # [N, 2] pixels
    source: str  # "csv" | "ground truth" | "mindtct + bozorth3-style pairing"


def default_pairs(cameras) -> list[tuple[str, str]]:
    """The middle camera (by angle about the rig axis) to each other camera."""
    from ..splat.camera_path import middle_camera

    names = cameras.names
    if len(names) < 2:
        raise InputError("a reconstruction with one view has no pair of views to register")
    try:
        middle = names[middle_camera(list(cameras.cameras.values()))]
    except ValueError:  # cameras that do not share an axis: the first view to the others
        return [(names[0], n) for n in names[1:]]
    return [(middle, n) for n in names if n != middle]


def read_mates_csv(path: Path) -> dict[tuple[str, str], np.ndarray]:
    """``{(view_a, view_b): [N, 4] x_a, y_a, x_b, y_b}`` from a CSV with those columns."""
    needed = ("view_a", "view_b", "x_a", "y_a", "x_b", "y_b")
    try:
        with open(path, newline="") as handle:
            reader = csv.DictReader(handle)
            header = [h.strip().lower() for h in reader.fieldnames or []]
            missing = [c for c in needed if c not in header]
            if missing:
                raise InputError(f"{path}: the mates CSV needs the columns {', '.join(needed)}; missing {', '.join(missing)}")
            table: dict[tuple[str, str], list] = {}
            for line, row in enumerate(reader, start=2):
                row = {k.strip().lower(): (v or "").strip() for k, v in row.items() if k}
                try:
                    values = [float(row[c]) for c in needed[2:]]
                except ValueError:
                    raise InputError(f"{path}, line {line}: x_a, y_a, x_b, y_b must be numbers") from None
                if not np.all(np.isfinite(values)):
                    raise InputError(f"{path}, line {line}: x_a, y_a, x_b, y_b must be finite")
                table.setdefault((row["view_a"], row["view_b"]), []).append(values)
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"{path}: cannot read the mates CSV ({error})") from None
    return {key: np.array(rows, np.float64) for key, rows in table.items()}


def truth_mates(minutiae: dict, view_a: str, view_b: str) -> Mates | None:
    """Ground-truth mates: minutiae visible in both views of ``minutiae.json``; None when it lacks a view."""
    views = minutiae.get("views", {})
    if view_a not in views or view_b not in views:
        return None
    in_a = {e["id"]: e["uv"] for e in views[view_a] if e.get("visible", True)}
    in_b = {e["id"]: e["uv"] for e in views[view_b] if e.get("visible", True)}
    both = [i for i in in_a if i in in_b]
    return Mates(np.array([in_a[i] for i in both], np.float64).reshape(-1, 2),
                 np.array([in_b[i] for i in both], np.float64).reshape(-1, 2), "ground truth")


def matcher_mates(photo_a: np.ndarray, photo_b: np.ndarray) -> Mates:
    """The "UWA*" mates: mindtct minutiae of both photos, paired as bozorth3 pairs them."""
    from ..eval.fingerprint import fingerprint_of
    from ..eval.minutiae_pairs import pair_minutiae

    found = []
    for photo in (photo_a, photo_b):
        contact, fingerprint, failure = fingerprint_of(photo, nfiq2=False)
        if contact is None:
            raise InputError(failure)
        found.append((fingerprint, contact.ppi_scale))
    (a, scale_a), (b, scale_b) = found
    index_a, index_b, _ = pair_minutiae(a.minutiae[:, :2] * scale_a, a.minutiae[:, 2],
                                        b.minutiae[:, :2] * scale_b, b.minutiae[:, 2])
    return Mates(a.minutiae[index_a, :2], b.minutiae[index_b, :2], "mindtct + bozorth3-style pairing")


def _errors(mates: Mates, rec: ReconstructionFolder, view_a: str, view_b: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per-method error (px) on the mates 3D could carry, and the 3D predictions of all mates."""
    from ..align.transfer import transfer_points
    from ..eval.warp2d import BASELINES, cross_validated_errors

    camera_a, camera_b = rec.cameras.cameras[view_a], rec.cameras.cameras[view_b]
    carried, status = transfer_points(mates.xy_a, rec.depth(view_a), camera_a, rec.depth(view_b), camera_b)
    scored = status == "mapped"
    errors = {"3D": np.linalg.norm(carried[scored] - mates.xy_b[scored], axis=1)}
    for name, fit in BASELINES.items():
        errors[name] = cross_validated_errors(mates.xy_a[scored], mates.xy_b[scored], fit)
    return errors, np.where(scored[:, None], carried, np.nan)


def pair_textures(rec: ReconstructionFolder, view_a: str, view_b: str, *, photo_a: np.ndarray | None = None,
                  photo_b: np.ndarray | None = None, depth_b: np.ndarray | None = None):
    """``(texture_a, texture_b, both, period)``: photo A carried into B through B's depth, both as ridge texture
    (band-passed, unit local RMS) where both see the finger, and B's ridge period; the folder's own photos and
    depth unless given. ``both`` has fewer than 1000 pixels where the views share too little (``period`` NaN)."""
    from ..align.correspond.texture import as_gray, estimate_ridge_period, ridge_texture
    from ..align.transfer import warp_image
    from ..segment.masks import finger_mask

    photo_a = rec.photo(view_a) if photo_a is None else photo_a
    photo_b = rec.photo(view_b) if photo_b is None else photo_b
    camera_a, camera_b = rec.cameras.cameras[view_a], rec.cameras.cameras[view_b]
    depth_b = rec.depth(view_b) if depth_b is None else depth_b
    warped, valid = warp_image(as_gray(photo_a), rec.depth(view_a), camera_a, depth_b, camera_b)
    gray_b = as_gray(photo_b)
    both = valid & finger_mask(photo_b)
    if both.sum() < 1000:
        return warped, gray_b, both, float("nan")
    period = estimate_ridge_period(gray_b, both)
    return ridge_texture(warped, both, period), ridge_texture(gray_b, both, period), both, period


def warp_check(photo_a: np.ndarray, photo_b: np.ndarray, rec: ReconstructionFolder, view_a: str, view_b: str) -> dict:
    """A check of the 3D registration that needs no mates: photo A warped into B through the model,
    both as ridge texture (:func:`pair_textures`); the global shift between them by phase correlation (px; ~0
    when the model carries A onto B) and their normalised correlation as they are (ridges in phase: well above 0;
    half a ridge period off: about 0). Then what is left (:func:`fingersplat3d.eval.ridge_flow.flow_residual`):
    the correlation after a smooth flow over six ridge periods (what a better geometry could reach at that scale)
    and the flow's median shift across the ridges where a depth change could move them and where only the
    cameras could."""
    from ..eval.ridge_flow import flow_residual

    texture_a, texture_b, both, period = pair_textures(rec, view_a, view_b, photo_a=photo_a, photo_b=photo_b)
    if not np.isfinite(period):
        return {key: float("nan") for key in ("warp_shift_px", "warp_ncc", "warp_ncc_flowed", "warp_residual_depth_px",
                                              "warp_residual_pose_px")}
    (dx, dy), _ = cv2.phaseCorrelate(texture_a.astype(np.float64), texture_b.astype(np.float64))
    camera_a, camera_b = rec.cameras.cameras[view_a], rec.cameras.cameras[view_b]
    epipole = camera_b.K @ (camera_b.world_to_cam[:3, :3] @ camera_a.cam_to_world[:3, 3] + camera_b.world_to_cam[:3, 3])
    left = flow_residual(texture_a, texture_b, both, period, epipole)
    return {"warp_shift_px": float(np.hypot(dx, dy)), "warp_ncc": left["ncc"], "warp_ncc_flowed": left["ncc_flowed"],
            "warp_residual_depth_px": left["shift_depth_px"], "warp_residual_pose_px": left["shift_pose_px"],
            "warp_fitted": rec.fitted_to_ridges}


def _picture(path: Path, photo_b: np.ndarray, mates: Mates, predictions: dict[str, np.ndarray]) -> None:
    """View B with each mate (green circle) and a line to where each method put it."""
    gray = np.clip(photo_b if photo_b.ndim == 2 else photo_b.mean(2), 0, 1)
    canvas = cv2.cvtColor((gray * 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    scale = min(1.0, 1280.0 / max(canvas.shape[:2]))
    for name, predicted in predictions.items():
        for start, end in zip(mates.xy_b, predicted):
            if np.all(np.isfinite(end)):
                cv2.line(canvas, tuple(int(round(v)) for v in start), tuple(int(round(v)) for v in end),
                         COLOURS[name], 2, cv2.LINE_AA)
    for point in mates.xy_b:
        cv2.circle(canvas, tuple(int(round(v)) for v in point), 6, (60, 200, 60), 2, cv2.LINE_AA)
    for row, name in enumerate(predictions):
        cv2.putText(canvas, name, (12, 30 + 28 * row), cv2.FONT_HERSHEY_SIMPLEX, 0.8, COLOURS[name], 2, cv2.LINE_AA)
    if scale < 1.0:
        canvas = cv2.resize(canvas, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(path), canvas)


def _mates_for(rec: ReconstructionFolder, view_a: str, view_b: str, user: dict | None, truth: dict | None) -> Mates:
    if user is not None:
        table = user.get((view_a, view_b))
        if table is None:
            swapped = user.get((view_b, view_a))
            table = None if swapped is None else swapped[:, [2, 3, 0, 1]]
        if table is None:
            raise InputError(f"the mates CSV has no rows for views {view_a} and {view_b}")
        return Mates(table[:, :2], table[:, 2:], "csv")
    if truth is not None:
        mates = truth_mates(truth, view_a, view_b)
        if mates is not None:
            return mates
    return matcher_mates(rec.photo(view_a), rec.photo(view_b))


def evaluate_pair(rec: ReconstructionFolder, view_a: str, view_b: str, user: dict | None, truth: dict | None,
                  out: Path) -> list[dict]:
    """The rows of one pair of views (one per method), its mates CSV and its picture."""
    base = {"reconstruction": rec.folder.name, "view_a": view_a, "view_b": view_b}
    check = {}  # needs no mates: every pair with both photos gets it, mates or not
    if rec.photo_path(view_a) is not None and rec.photo_path(view_b) is not None:
        check = warp_check(rec.photo(view_a), rec.photo(view_b), rec, view_a, view_b)
    try:
        mates = _mates_for(rec, view_a, view_b, user, truth)
        base.update(mates_source=mates.source, mates=len(mates.xy_a))
        if len(mates.xy_a) < 3:
            raise InputError(f"only {len(mates.xy_a)} mated minutiae from {mates.source} (at least 3 are needed to "
                             "score the 2D baselines)")
    except FS3DError as error:
        return [dict(base, status="failed", reason=str(error), **check)]
    errors, carried = _errors(mates, rec, view_a, view_b)
    stem = f"{rec.folder.name}__{view_a}__{view_b}"
    with open(out / "mates" / f"{stem}.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["x_a", "y_a", "x_b", "y_b", "x_3d", "y_3d"])
        writer.writerows(np.column_stack([mates.xy_a, mates.xy_b, carried]).round(3).tolist())
    if rec.photo_path(view_b) is not None:
        from ..eval.warp2d import BASELINES

        predictions = {"3D": carried}
        for name, fit in BASELINES.items():  # the pictures show each baseline fitted to all mates
            predictions[name] = fit(mates.xy_a, mates.xy_b)(mates.xy_a)
        _picture(out / "pictures" / f"{stem}.png", rec.photo(view_b), mates, predictions)
    rows = []
    for method in METHODS:
        values = errors[method][np.isfinite(errors[method])]
        row = dict(base, method=method, scored=int(values.size), status="done" if values.size else "failed",
                   reason="" if values.size else "no mate could be scored")
        if method == "3D":
            row.update(check)
        if values.size:
            row.update(mean_px=float(values.mean()), median_px=float(np.median(values)),
                       p90_px=float(np.percentile(values, 90)))
        rows.append(row)
    return rows


def run_register_evaluation(folders: list[Path], out: Path, *, pairs: list[tuple[str, str]] | None = None,
                            mates_csv: Path | None = None, truth: Path | None = None, matcher: bool = False,
                            progress: bool = True) -> list[dict]:
    """Every reconstruction and pair; a pair that cannot be scored is a failed row with its reason."""
    from tqdm import tqdm

    from ..io.minutiae import read_minutiae

    user = read_mates_csv(mates_csv) if mates_csv is not None else None
    given_truth = read_minutiae(truth) if truth is not None else None
    for sub in ("mates", "pictures"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    jobs = []
    for folder in folders:
        rec = ReconstructionFolder(folder)
        chosen = pairs or default_pairs(rec.cameras)
        for a, b in chosen:
            for name in (a, b):
                if name not in rec.cameras.cameras:
                    raise InputError(f"{folder / 'cameras.json'}: no view named {name!r}; views: {', '.join(rec.cameras.names)}")
        jobs += [(rec, a, b) for a, b in chosen]
    rows = []
    for rec, a, b in tqdm(jobs, desc="fs3d eval register", unit="pair", disable=not progress):
        try:
            known = None if matcher else given_truth if given_truth is not None else rec.minutiae()
            rows += evaluate_pair(rec, a, b, user, known, out)
        except FS3DError as error:
            rows.append({"reconstruction": rec.folder.name, "view_a": a, "view_b": b, "status": "failed",
                         "reason": str(error)})
    write_rows(out / "register_errors.csv", COLUMNS, rows)
    (out / "summary.md").write_text(summary_markdown(rows))
    return rows


def _median(rows: dict, key: str) -> float:
    values = [float(r.get(key, np.nan)) for r in rows.values()]
    values = [v for v in values if np.isfinite(v)]
    return float(np.median(values)) if values else float("nan")


def summary_markdown(rows: list[dict]) -> str:
    done = [r for r in rows if r["status"] == "done"]
    lines = ["# Registration error: minutiae carried from view A to view B", "",
             "Mean distance (px) between where each method puts a minutia of A in B and its mate in B; the "
             "2D baselines are fitted to the mates (5-fold cross-validated), 3D uses none. The warp check needs no "
             "mates: photo A carried into B through the model against B's own ridges (the global shift left "
             "between them, and their correlation; a wrong model leaves a shift or a correlation near 0, and "
             "3D errors far above the warp check's shift point at wrong mates).", ""]
    if done:
        lines += ["| reconstruction | A -> B | mates (source) | scored | 3D | rigid 2D | TPS | warp check: shift px, NCC |",
                  "|---|---|---|---|---|---|---|---|"]
        keys = sorted({(r["reconstruction"], r["view_a"], r["view_b"]) for r in done})
        for key in keys:
            by = {r["method"]: r for r in done if (r["reconstruction"], r["view_a"], r["view_b"]) == key}
            first = next(iter(by.values()))
            cells = [f"{by[m]['mean_px']:.2f} (median {by[m]['median_px']:.2f})" if m in by else "—" for m in METHODS]
            three = by.get("3D", {})
            check = (f"{three['warp_shift_px']:.1f}, {three['warp_ncc']:.2f}"
                     if np.isfinite(three.get("warp_shift_px", np.nan)) else "—")
            lines.append(f"| {key[0]} | {key[1]} -> {key[2]} | {first['mates']} ({first['mates_source']}) | "
                         f"{first['scored']} | " + " | ".join(cells) + f" | {check} |")
        lines += ["", "| method | mean over pairs (px) | median over pairs (px) |", "|---|---|---|"]
        for method in METHODS:
            values = [r["mean_px"] for r in done if r["method"] == method]
            if values:
                lines.append(f"| {method} | {np.mean(values):.2f} | {np.median(values):.2f} |")
        lines += ["", "The paper, on UWA with mates from a matcher (\"UWA*\"): " + ", ".join(
            f"{k} {v} px" for k, v in PAPER_FIGURES.items()) + ". Figures compare only at the same resolution and "
            "with mates from the same kind of source."]
    checked = {(r["reconstruction"], r["view_a"], r["view_b"]): r for r in rows
               if np.isfinite(float(r.get("warp_ncc", np.nan)))}
    if checked:
        lines += ["", "Warp check of every pair, mates or not (shift px, ridge NCC): " + "; ".join(
            f"{key[0]} {key[1]} -> {key[2]}: {r['warp_shift_px']:.1f}, {r['warp_ncc']:.2f}" for key, r in sorted(checked.items())),
            "", f"Median ridge NCC over {len(checked)} pairs: "
            f"{np.median([r['warp_ncc'] for r in checked.values()]):.2f}; after a smooth flow over six ridge periods "
            f"(what a better geometry could reach at that scale) {_median(checked, 'warp_ncc_flowed'):.2f}. The flow's "
            f"median shift across the ridges: {_median(checked, 'warp_residual_depth_px'):.1f} px where the ridges cross "
            f"the epipolar lines (a depth change could move them), {_median(checked, 'warp_residual_pose_px'):.1f} px "
            "where they run along them (only the cameras could)."]
        fitted = sorted({key[0] for key, r in checked.items() if r.get("warp_fitted")})
        if fitted:
            lines += ["", f"{', '.join(fitted)}: made with `fs3d fuse --photometric`, whose surfaces are fitted to this "
                          "very ridge agreement; there the warp check is in-sample, not an independent check."]
    failed = [r for r in rows if r["status"] != "done"]
    if failed:
        lines += ["", "Not scored:", ""] + [f"- {r['reconstruction']} {r['view_a']} -> {r['view_b']}"
                                            f"{' (' + r['method'] + ')' if r.get('method') else ''}: {r['reason']}"
                                            for r in failed]
    return "\n".join(lines) + "\n"
