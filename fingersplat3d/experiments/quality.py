"""``fs3d eval quality``: how real the synthesized views look (PSNR, SSIM, NFIQ2), leave one view out.

For each capture (synthetic or real, 2+ views):

1. all views are registered (``fuse`` without the splat stage): the held-out view's camera comes
   from the same registration, as test cameras of pose-free 3DGS benchmarks come from all views;
2. for each view ``k``: Gaussians are fitted to the *other* views only, starting from the fused
   cloud of those views (:func:`fingersplat3d.pipeline.cloud_of_views`), and rendered at ``k``'s
   camera ("placed") and again after aligning that camera to the photo with the model frozen
   (:func:`fingersplat3d.splat.fit.fit_camera`, "aligned", as pose-free 3DGS evaluation does); with
   ``SplatConfig.match_exposures`` (the default) the model is at the fitted views' mean exposure, and both renders
   are multiplied by ``k``'s exposure against theirs, estimated with the rest of the registration from the skin
   the registered views share (:mod:`fingersplat3d.splat.shading_estimate`; column ``exposure``), as its camera is;
3. PSNR and SSIM inside ``k``'s finger mask (:mod:`fingersplat3d.eval.image`), the PSNR again on the skin the
   fitted views saw and on the unseen skin's completion apart (``psnr_seen``, ``psnr_unseen``; ``unseen_share``: the
   share of the finger rendered mostly from the completion, which is a guess of skin no fitted photo shows), the
   seen skin within one ridge period of the completion apart again (``psnr_beside_unseen``, and ``tone_beside_unseen``:
   the render's mean there less the photo's, in grey levels of 1: skin the fitted views see only at a slant, where a
   new view looking at it squarely shows how well its tone was carried over), and NFIQ2 of the
   real photo and of the aligned render, both as contact-like prints
   (:mod:`fingersplat3d.eval.contact`; the render's print covers where the model is opaque and is
   scaled by the photo's ridge period: a blurred render must not read as a coarser finger).

Writes ``quality.csv`` (one row per capture and view; failures are rows with their reason),
``views/<capture>__<view>.png`` (photo | render | both prints) and ``summary.md`` beside the
paper's NFIQ2 figures.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from ..errors import FS3DError
from ..viz import gray8, side_by_side
from .tables import write_rows

__all__ = ["PAPER_NFIQ2", "evaluate_capture", "run_quality_evaluation"]

PAPER_NFIQ2 = {"real": 38.13, "FingerSplat": 35.68}
"""The paper's mean NFIQ2 on UWA: real views and FingerSplat's synthesized views."""
COLUMNS = ("capture", "view", "status", "reason", "train_views", "exposure", "psnr_placed", "ssim_placed", "psnr",
           "ssim", "unseen_share", "psnr_seen", "psnr_unseen", "psnr_beside_unseen", "tone_beside_unseen", "nfiq2_real",
           "nfiq2_render", "nfiq2_failure", "fit_s")
MIN_PART_PIXELS = 500
"""A part of the finger (the skin the fitted views saw, or the unseen skin's completion) smaller than this many pixels
in the left-out view gets no PSNR of its own (an empty cell): too few pixels to say anything."""


def _nfiq2(image: np.ndarray, mask: np.ndarray, period_px: float | None = None):
    """NFIQ2 of a photo or render as a contact-like print: ``(score, failure, print, ridge period)``."""
    from ..eval.fingerprint import fingerprint_of

    contact, fingerprint, failure = fingerprint_of(image, mask, period_px=period_px)
    if contact is None:
        return None, failure, None, period_px
    return fingerprint.nfiq2, failure, contact.image, contact.period_px


def evaluate_capture(name: str, capture, config, out: Path, *, nfiq2: bool = True, progress: bool = False) -> list[dict]:
    """The rows of one capture (see the module docstring)."""
    from ..device import resolve_device
    from ..eval.image import image_scores
    from ..pipeline import cloud_of_views, fuse, unseen_skin_of
    from ..splat.fit import fit_camera
    from ..splat.novel import render_views
    from ..splat.stage import run_splat_stage

    if len(capture) < 2:
        return [{"capture": name, "view": "", "status": "failed", "reason": "one view: nothing to leave out"}]
    result = fuse(capture, replace(config, splat=None))
    views = result.capture.views  # with the masks fuse used
    aligned = [v for v, ok in enumerate(result.report["alignment"]["aligned"].values()) if ok]
    device = resolve_device(config.device)
    exposures = _exposures(result, aligned) if config.splat.match_exposures else None
    rows = []
    for k, view in enumerate(views):
        row = {"capture": name, "view": view.name}
        train = [v for v in aligned if v != k]
        if k not in aligned or not train:
            rows.append(dict(row, status="failed", reason="the view was not registered with the others" if k not in aligned
                             else "no other registered view to fit"))
            continue
        try:
            cloud = cloud_of_views(result, train, config.min_confidence, config.voxel)
            unseen = unseen_skin_of(cloud, views, result.cameras, train, config.splat)
            stage = run_splat_stage(views, result.cameras, train, cloud, config.splat, config.clean, unseen=unseen,
                                    depths=result.depths, device=device, progress=progress)
        except FS3DError as error:
            rows.append(dict(row, status="failed", reason=str(error)))
            continue
        model = stage.gaussians.to(device)
        placed = result.cameras[k]
        gain = 1.0 if exposures is None else float(exposures.gains([aligned.index(v) for v in train])[aligned.index(k)])
        before = _exposed(render_views(model, [(view.name, placed)])[0], gain)
        camera = fit_camera(model, placed, (view.image / gain).astype(np.float32), view.mask)
        after = _exposed(render_views(model, [(view.name, camera)])[0], gain)
        scores_before = image_scores(before.image, view.image, view.mask)
        scores = image_scores(after.image, view.image, view.mask)
        split = _by_part(model, stage.unseen, camera, after.image, view)
        row.update(status="done", reason="", train_views=" ".join(views[v].name for v in train), exposure=round(gain, 4),
                   psnr_placed=scores_before.psnr, ssim_placed=scores_before.ssim, psnr=scores.psnr, ssim=scores.ssim,
                   **split, fit_s=stage.report["fit_seconds"])
        parts = [gray8(view.image), gray8(after.image)]
        if nfiq2:
            real, real_failure, real_print, period = _nfiq2(view.image, view.mask)
            # the render is of the same view at the same scale: its print is made at the photo's ridge period
            render, render_failure, render_print, _ = _nfiq2(after.image, after.alpha >= 0.5, period)
            row.update(nfiq2_real="" if real is None else real, nfiq2_render="" if render is None else render,
                       nfiq2_failure="; ".join(f"{who}: {why}" for who, why in (("real", real_failure),
                                                                               ("render", render_failure)) if why))
            parts += [p for p in (real_print, render_print) if p is not None]
        cv2.imwrite(str(out / "views" / f"{name}__{view.name}.png"), side_by_side(parts, 360, 8, cv2.INTER_AREA))
        rows.append(row)
    return rows


def _by_part(model, completion, camera, render: np.ndarray, view) -> dict:
    """The left-out view's finger split by where its render comes from: ``unseen_share``, the share of its mask
    pixels rendered mostly (half their opacity or more) by the ``completion`` rows of the model (``[N]`` bool,
    :attr:`~fingersplat3d.splat.stage.SplatStage.unseen`: a guess, no photo saw that skin), the PSNR of the render
    on each part, and on the seen skin within one ridge period of the completion with the tone of the render there
    against the photo's (empty where a part, or the completion beside it, has under :data:`MIN_PART_PIXELS` pixels)."""
    from scipy import ndimage

    from ..align.correspond.texture import as_gray, estimate_ridge_period
    from ..eval.image import masked_psnr
    from ..splat.novel import opacity_share

    mask = np.asarray(view.mask, bool)
    unseen = np.zeros_like(mask)
    if bool(completion.any()):
        unseen = (opacity_share(model, completion, camera) >= 0.5) & mask
    seen = mask & ~unseen
    beside = np.zeros_like(mask)
    if unseen.sum() >= MIN_PART_PIXELS:  # beside a completion large enough to score
        beside = seen & (ndimage.distance_transform_edt(~unseen) <= estimate_ridge_period(as_gray(view.image), mask))
    psnr = lambda part: masked_psnr(render, view.image, part) if part.sum() >= MIN_PART_PIXELS else ""  # noqa: E731
    tone = ""
    if beside.sum() >= MIN_PART_PIXELS:
        tone = round(float(as_gray(render)[beside].mean() - as_gray(view.image)[beside].mean()), 4)
    return {"unseen_share": round(float(unseen.sum()) / max(int(mask.sum()), 1), 4), "psnr_seen": psnr(seen),
            "psnr_unseen": psnr(unseen), "psnr_beside_unseen": psnr(beside), "tone_beside_unseen": tone}


def _exposures(result, aligned: list[int]):
    """The registered views' exposures (a :class:`~fingersplat3d.splat.shading_estimate.ShadingEstimate` over
    ``aligned``, in that order), from the skin they share."""
    from ..splat.shading_estimate import estimate_shading

    views = [result.capture.views[v] for v in aligned]
    return estimate_shading([v.image for v in views], [v.mask for v in views], [result.cameras[v] for v in aligned],
                            [result.depths[v] for v in aligned])


def _exposed(render, gain: float):
    """``render`` (a :class:`~fingersplat3d.splat.novel.NovelView`) at an exposure ``gain`` times the model's."""
    return render if gain == 1.0 else replace(render, image=np.clip(render.image * gain, 0.0, 1.0).astype(np.float32))


def run_quality_evaluation(captures: list[tuple[str, object]], out: Path, config, *, nfiq2: bool = True,
                           progress: bool = True) -> list[dict]:
    """Every ``(name, capture)``; one that cannot be fused is a failed row with its reason."""
    from tqdm import tqdm

    (out / "views").mkdir(parents=True, exist_ok=True)
    rows = []
    for name, capture in tqdm(captures, desc="fs3d eval quality", unit="capture", disable=not progress):
        try:
            rows += evaluate_capture(name, capture, config, out, nfiq2=nfiq2)
        except FS3DError as error:
            rows.append({"capture": name, "view": "", "status": "failed", "reason": str(error)})
    write_rows(out / "quality.csv", COLUMNS, rows)
    (out / "summary.md").write_text(summary_markdown(rows))
    return rows


def _mean(rows: list[dict], key: str) -> tuple[float | None, int]:
    values = [float(r[key]) for r in rows if r.get(key) not in (None, "")]
    finite = [v for v in values if np.isfinite(v)]
    return (float(np.mean(finite)) if finite else None), len(finite)


def summary_markdown(rows: list[dict]) -> str:
    done = [r for r in rows if r["status"] == "done"]
    lines = ["# Synthesized views against the real ones (leave one view out)", "",
             f"{len(done)} of {len(rows)} views scored: Gaussians fitted without the view, rendered at its registered "
             "camera (placed) and after aligning that camera to the photo with the model frozen (aligned); both at the "
             "view's exposure when the model's are matched (column `exposure` of quality.csv).", ""]
    if done:
        lines += ["| capture | view | PSNR dB placed -> aligned | SSIM placed -> aligned | NFIQ2 real | NFIQ2 render |",
                  "|---|---|---|---|---|---|"]
        for r in done:
            lines.append(f"| {r['capture']} | {r['view']} | {r['psnr_placed']:.2f} -> {r['psnr']:.2f} | "
                         f"{r['ssim_placed']:.3f} -> {r['ssim']:.3f} | {r.get('nfiq2_real', '') or '—'} | "
                         f"{r.get('nfiq2_render', '') or '—'} |")
        lines += ["", "| mean over views | value | views |", "|---|---|---|"]
        for key, label in (("psnr", "PSNR dB (aligned)"), ("ssim", "SSIM (aligned)"),
                           ("psnr_seen", "PSNR dB on the skin the fitted views saw"),
                           ("psnr_unseen", "PSNR dB on the unseen skin's completion (a guess)"),
                           ("psnr_beside_unseen", "PSNR dB on the seen skin within a ridge period of the completion"),
                           ("tone_beside_unseen", "render less photo there, mean grey level (of 1)"),
                           ("unseen_share", "share of the finger rendered from the completion"), ("nfiq2_real", "NFIQ2 real"),
                           ("nfiq2_render", "NFIQ2 render")):
            value, count = _mean(done, key)
            if value is not None:
                lines.append(f"| {label} | {value:.3f} | {count} |")
        lines += ["", "The paper's mean NFIQ2 on UWA: " + ", ".join(f"{k} {v}" for k, v in PAPER_NFIQ2.items()) +
                  ". NFIQ2 here scores contact-like prints made from the photos (see `fs3d eval match --help`), so "
                  "compare the gap between real and render, not the level."]
        failures = [r for r in done if r.get("nfiq2_failure")]
        if failures:
            lines += ["", "NFIQ2 could not score:", ""] + [f"- {r['capture']} {r['view']}: {r['nfiq2_failure']}"
                                                          for r in failures]
    failed = [r for r in rows if r["status"] != "done"]
    if failed:
        lines += ["", "Not scored:", ""] + [f"- {r['capture']} {r['view']}: {r['reason']}".replace("  ", " ")
                                            for r in failed]
    return "\n".join(lines) + "\n"
