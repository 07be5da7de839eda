"""Real rig captures, checks that need no ground truth: registration, rig consistency, leave-one-view-out.

For each capture (three cameras of a fixed rig, e.g. UWA's frames 0-2), a geometry-only fuse gives
the registered views, the relative rotation of each camera pair, the focal, the residual, time and
memory (:func:`measure_real`). Over the captures (:func:`summarize_real`):

* **rig consistency** (:func:`~fingersplat3d.eval.rig_consistency.rig_consistency`): the rig is fixed
  hardware, so each camera pair's relative rotation must be the same in every capture; each
  capture's deviation from the pair's robust mean, in degrees;
* **focal spread**: ``(max - min) / median`` of the registered captures' focals (same cameras, same focal);
* **leave-one-view-out** (optional): frames 0 and 1 fused alone and seen from camera 2, posed against
  that two-view model by PnP from where the three-view run puts frame 0's pixels in frame 2 (the model
  under test never sees frame 2's pixels): the share of its surface outside frame 2's silhouette and
  the correlation of its ridge texture with frame 2's (about 0 when off by half a ridge period).
"""
from __future__ import annotations

import time

import numpy as np

from .process import peak_rss_mb

__all__ = ["measure_real", "summarize_real", "pair_angles_deg", "focal_spread", "real_table", "sensitivity_against_deviation"]

_TURN_WARNING = "the turn between"  # how every warning about a turn's certainty begins or names it (pipeline.py)


def _texture_seen_from(texture, depth, camera, target_camera, target_mask):
    """A view's ridge texture carried by its depth into ``target_camera`` (nearest pixel, nearest depth wins),
    and the share of it that lands outside ``target_mask``."""
    rows, cols = np.nonzero(np.isfinite(depth))
    points = camera.unproject(np.stack([cols, rows], 1).astype(np.float64), depth[rows, cols])
    uv, z = target_camera.project(points)
    u, v = np.round(uv[:, 0]), np.round(uv[:, 1])
    inside = np.isfinite(u) & (u >= 0) & (v >= 0) & (u < target_camera.width) & (v < target_camera.height)
    u, v, z, values = u[inside].astype(int), v[inside].astype(int), z[inside], texture[rows[inside], cols[inside]]
    order = np.argsort(-z)  # far first, so that the nearest point is written last
    image = np.full((target_camera.height, target_camera.width), np.nan, np.float32)
    image[v[order], u[order]] = values[order]
    outside = float(np.mean(~target_mask[v, u])) if len(u) else float("nan")
    return image, outside


def texture_check(two, camera2, view2) -> dict:
    """Frames 0 and 1 of a two-view reconstruction ``two``, their ridge texture carried into ``camera2``: the share
    outside ``view2``'s mask and the correlation with its own ridge texture (0: off by half a ridge period)."""
    from ..align.correspond.texture import estimate_ridge_period, ridge_texture

    period = estimate_ridge_period(view2.image, view2.mask)
    target = ridge_texture(view2.image, view2.mask, period)
    predicted = np.full(target.shape, np.nan, np.float32)
    outside = []
    for index in (0, 1):
        view = two.capture.views[index]
        image, out = _texture_seen_from(ridge_texture(view.image, view.mask, period), two.depths[index],
                                        two.cameras[index], camera2, view2.mask)
        predicted = np.where(np.isnan(predicted), image, predicted)
        outside.append(out)
    both = np.isfinite(predicted) & view2.mask
    x, y = predicted[both] - predicted[both].mean(), target[both] - target[both].mean()
    ncc = float(np.dot(x, y) / np.sqrt(np.dot(x, x) * np.dot(y, y) + 1e-12)) if both.sum() > 100 else None
    return {"outside_mask": float(np.mean(outside)), "texture_ncc": ncc}


def leave_one_view_out(three, two) -> dict:
    """:func:`texture_check` of a capture's frame 2, camera 2 resected by PnP from the three-view fuse ``three``
    into the frame of the two-view fuse ``two`` (None where either did not register)."""
    import cv2

    from ..scene import Camera

    if not (three.registered and two.registered):
        return {"outside_mask": None, "texture_ncc": None}
    view2 = three.capture.views[2]
    rows, cols = np.nonzero(np.isfinite(three.depths[0]) & np.isfinite(two.depths[0]))
    pick = np.random.default_rng(0).choice(len(rows), min(4000, len(rows)), replace=False)
    pixels0 = np.stack([cols[pick], rows[pick]], 1).astype(np.float64)
    seen_in_2, _ = three.cameras[2].project(three.cameras[0].unproject(pixels0, three.depths[0][rows[pick], cols[pick]]))
    inside = np.isfinite(seen_in_2).all(1)
    inside[inside] = view2.mask[np.clip(np.round(seen_in_2[inside, 1]).astype(int), 0, view2.height - 1),
                                np.clip(np.round(seen_in_2[inside, 0]).astype(int), 0, view2.width - 1)]
    model_points = two.cameras[0].unproject(pixels0, two.depths[0][rows[pick], cols[pick]])
    focal = two.cameras[0].K[0, 0]
    K = np.array([[focal, 0, (view2.width - 1) / 2], [0, focal, (view2.height - 1) / 2], [0, 0, 1.0]])
    ok, rvec, tvec, _ = cv2.solvePnPRansac(model_points[inside], seen_in_2[inside], K, None, reprojectionError=3.0)
    if not ok:
        return {"outside_mask": None, "texture_ncc": None}
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
    return texture_check(two, Camera(K, pose, view2.width, view2.height), view2)


def _pair_rotations(three, twos: dict):
    """Per view pair ``"ij"`` of ``twos``: the world-to-camera rotations of views i and j fused alone and in ``three``,
    or None where either fuse did not register."""
    for key, two in twos.items():
        i, j = int(key[0]), int(key[1])
        registered = three.registered and two.registered
        yield key, ((two.cameras[0].world_to_cam[:3, :3], two.cameras[1].world_to_cam[:3, :3]),
                    (three.cameras[i].world_to_cam[:3, :3], three.cameras[j].world_to_cam[:3, :3])) if registered else None


def two_view_turn_errors(three, twos: dict) -> dict:
    """Per view pair ``"ij"``: how far the turn of a fuse of views i and j alone (``twos["ij"]``) lies from the same
    pair's turn in the fuse of all views ``three`` (degrees; None where the pair did not register)."""
    from ..eval.poses import rotation_angle_deg

    return {key: None if found is None else float(rotation_angle_deg(found[0][1] @ found[0][0].T, found[1][1] @ found[1][0].T))
            for key, found in _pair_rotations(three, twos)}


def two_view_turn_excess(three, twos: dict) -> dict:
    """Per view pair ``"ij"``: how much wider (positive) or narrower the angle between the optical axes of views i and j
    comes out fused alone than in the fuse of all views (degrees; None where the pair did not register). The sign
    :func:`two_view_turn_errors` lacks: two views' turn slides along the bas-relief valley, one way on every capture
    where a bias holds it."""
    from ..eval.poses import view_turn_deg

    return {key: None if found is None else float(view_turn_deg(*found[0])[0] - view_turn_deg(*found[1])[0])
            for key, found in _pair_rotations(three, twos)}


def pair_angles_deg(rotations) -> dict[str, float]:
    """Per view pair ``"ij"`` (i < j): the turn (degrees) between the views' optical axes, from their world-to-camera
    rotations ``[3, 3]`` (:func:`~fingersplat3d.eval.poses.view_turn_deg`: a camera stored portrait turns as it is)."""
    from ..eval.poses import view_turn_deg

    return {f"{i}{j}": view_turn_deg(rotations[i], rotations[j])[0]
            for i in range(len(rotations)) for j in range(i + 1, len(rotations))}


def focal_spread(focals) -> float:
    """The fitted focals' range over their median."""
    focals = np.asarray(focals, np.float64)
    return float((focals.max() - focals.min()) / np.median(focals))


def measure_real(capture, config=None, leave_one_out: bool = False, two_views: bool = False) -> dict:
    """One real capture fused (geometry only unless ``config`` says otherwise): a record for :func:`summarize_real`.
    ``two_views``: also every pair of views fused alone, against the same turn with all three
    (:func:`two_view_turn_errors`)."""
    from ..alignment_status import NO_LOOP_WARNING, NO_TIP_WARNING, SIDES_CUT_WARNING
    from ..pipeline import FuseConfig, fuse
    from ..scene import Capture

    config = config or FuseConfig(splat=None)
    started = time.perf_counter()
    three = fuse(capture, config)
    seconds = time.perf_counter() - started
    report = three.report
    rotations = [c.world_to_cam[:3, :3] for c in three.cameras]
    ids = [str(capture.metadata[key]) for key in ("subject", "finger") if capture.metadata.get(key) is not None]
    record = {"capture": capture.metadata.get("name", "capture"), "finger": "_".join(ids) or None,
              "seconds": seconds, "peak_rss_mb": peak_rss_mb(),
              "registered": int(sum(report["alignment"]["aligned"].values())),
              "focal": float(report["alignment"]["focals_px"][0]), "residual_px": report["alignment"].get("residual_px"),
              "turn_uncertainty_deg": report["alignment"].get("turn_uncertainty_deg", {}),
              "turn_sensitivity_deg": report["alignment"].get("turn_sensitivity_deg", {}),
              "focal_probe": report["alignment"].get("focal_probe", {}),
              "warned_turns": any(any(text in str(w) for text in (_TURN_WARNING, NO_TIP_WARNING, NO_LOOP_WARNING,
                                                                  SIDES_CUT_WARNING))
                                  for w in report.get("warnings", [])),
              "sizes": [[v.width, v.height] for v in capture.views],
              "world_to_cam": [c.world_to_cam.tolist() for c in three.cameras],
              "angles_deg": pair_angles_deg(rotations),
              "axis_tilt_deg": report.get("registration", {}).get("axis_tilt_deg", {}),
              "pointmaps_tilted": bool(report.get("registration", {}).get("pointmaps_tilted", False))}
    twos = {}
    if (leave_one_out or two_views) and len(capture) == 3:
        twos["01"] = fuse(Capture(capture.views[:2], capture.metadata), config)
    if leave_one_out and len(capture) == 3:
        record["leave_one_out"] = leave_one_view_out(three, twos["01"])
    if two_views and len(capture) == 3:
        for i, j in ((0, 2), (1, 2)):
            twos[f"{i}{j}"] = fuse(Capture((capture.views[i], capture.views[j]), capture.metadata), config)
        record["two_view_turn_error_deg"] = two_view_turn_errors(three, twos)
        record["two_view_turn_excess_deg"] = two_view_turn_excess(three, twos)
        record["two_view_rotations"] = {key: [c.world_to_cam[:3, :3].tolist() for c in two.cameras] if two.registered
                                        else None for key, two in twos.items()}
    return record


def summarize_real(records: list[dict]) -> dict:
    """Rig consistency per camera pair, focal spread and medians over the captures."""
    from ..eval.rig_consistency import rig_consistency

    rig = rig_consistency(records) if all(len(r["sizes"]) == 3 for r in records) else {}
    registered = [r for r in records if r["registered"] == len(r["sizes"])]
    focals = np.array([r["focal"] for r in registered])
    deviations = [d for pair in rig.values() for d in pair["deviation_deg"].values()]
    nan = float("nan")
    fingers = sorted({r["finger"] for r in records if r.get("finger")})
    by_finger = {finger: {pair: float(np.median([d for name, d in entry["deviation_deg"].items()
                                                 if any(r["capture"] == name and r.get("finger") == finger for r in records)]
                                                or [nan]))
                          for pair, entry in rig.items()} for finger in fingers} if len(fingers) > 1 else {}
    return {"captures": len(records), "registered_all": len(registered), "rig": rig, "by_finger": by_finger,
            "rig_deviation_median_deg": float(np.median(deviations)) if deviations else nan,
            "rig_deviation_max_deg": float(np.max(deviations)) if deviations else nan,
            "focal_spread": focal_spread(focals) if len(focals) > 1 else nan,
            "fuse_s_median": float(np.median([r["seconds"] for r in records])) if records else nan,
            "peak_rss_mb": max((r["peak_rss_mb"] for r in records), default=nan),
            "two_views": _two_view_summary(records, rig)}


def sensitivity_against_deviation(records: list[dict], summary: dict) -> dict:
    """How well each "how sure" figure of ``report.json`` ranks the real camera pairs by their rig deviation (the error
    proxy that needs no ground truth): Spearman's rank correlation over every pair of every three-view capture, for
    the curvature's ``turn_uncertainty_deg`` and the probes' ``turn_sensitivity_deg``."""
    from scipy.stats import spearmanr

    result = {}
    for key in ("turn_uncertainty_deg", "turn_sensitivity_deg"):
        figures, deviations = [], []
        for record in records:
            values = list(record.get(key, {}).values())  # in pair order 0-1, 0-2, 1-2
            for (pair, entry), value in zip(summary.get("rig", {}).items(), values):
                deviation = entry["deviation_deg"].get(record["capture"])
                if deviation is not None and np.isfinite(value):
                    figures.append(value)
                    deviations.append(deviation)
        if len(figures) > 2:
            rho = spearmanr(figures, deviations)
            result[key] = {"spearman": float(rho.statistic), "p": float(rho.pvalue), "pairs": len(figures)}
    return result


def _two_view_summary(records: list[dict], rig: dict | None = None) -> dict:
    """Per view pair, over the captures measured with ``two_views``: how many registered alone, the median and largest
    turn error against the three-view fuse, its median per finger (one tuned on, the other held out), how many
    came out turned wider than with all views (with the median of that signed difference), and, with the three-view
    fuses' ``rig`` (:func:`~fingersplat3d.eval.rig_consistency.rig_consistency`), the pair's deviation from the rig
    mean: the three-view target's own measure, free of each capture's own three-view error."""
    from ..eval.rig_consistency import pair_deviation_deg

    summary, against_rig = {}, {}
    for record in records:
        for pair, error in record.get("two_view_turn_error_deg", {}).items():
            excess = record.get("two_view_turn_excess_deg", {}).get(pair)
            summary.setdefault(pair, []).append((error, excess, record.get("finger")))
            rotations = record.get("two_view_rotations", {}).get(pair)
            if rig and pair in rig and rotations is not None and record["capture"] in rig[pair]["deviation_deg"]:
                deviation = pair_deviation_deg(rig, record, int(pair[0]), int(pair[1]), *rotations)
                against_rig.setdefault(pair, []).append((deviation, record.get("finger")))

    def median(values: list[float]) -> float | None:
        return float(np.median(values)) if values else None

    def by_finger(values: list[tuple[float | None, str | None]], fingers: list[str]) -> dict:
        """The median of ``(value, finger)`` per finger (None values left out); {} with one finger or none."""
        return {finger: median([v for v, f in values if f == finger and v is not None])
                for finger in fingers} if len(fingers) > 1 else {}

    result = {}
    for pair, rows in summary.items():
        errors = [e for e, _, _ in rows if e is not None]
        excess = [x for _, x, _ in rows if x is not None]
        fingers = sorted({f for _, _, f in rows if f})
        result[pair] = {"registered": len(errors), "captures": len(rows),
                        "median_deg": median(errors), "max_deg": max(errors, default=None),
                        "wider": sum(x > 0 for x in excess), "signed": len(excess), "excess_median_deg": median(excess),
                        "by_finger": by_finger([(e, f) for e, _, f in rows], fingers)}
        deviations = against_rig.get(pair, [])
        if deviations:
            result[pair]["rig_median_deg"] = median([d for d, _ in deviations])
            result[pair]["rig_max_deg"] = max(d for d, _ in deviations)
            result[pair]["rig_by_finger"] = by_finger(deviations, fingers)
    return result


def real_table(records: list[dict], summary: dict) -> str:
    """The per-capture markdown table and its median row."""
    rig = summary["rig"]
    lines = ["| capture | views registered | angle 0-1 / 0-2 / 1-2 ° | rig deviation 0-1 / 0-2 / 1-2 ° | focal px | "
             "residual px | leave-one-out: outside mask, texture NCC | time s | peak RSS GB |",
             "|---|---|---|---|---|---|---|---|---|"]

    def loo(values: list[dict]) -> str:
        values = [v for v in values if v and v.get("texture_ncc") is not None]
        if not values:
            return "–"
        return (f"{100 * np.median([v['outside_mask'] for v in values]):.1f} %, "
                f"{np.median([v['texture_ncc'] for v in values]):.2f}")

    for r in records:
        deviation = " / ".join(f"{rig[p]['deviation_deg'][r['capture']]:.2f}" if p in rig and r["capture"] in
                               rig[p]["deviation_deg"] else "–" for p in ("01", "02", "12"))
        roll = " (portrait view)" if "roll_corrected" in r else ""
        residual = "–" if r["residual_px"] is None else f"{r['residual_px']:.2f}"
        lines.append(f"| {r['capture']}{roll} | {r['registered']}/{len(r['sizes'])} | "
                     f"{' / '.join(f'{v:.1f}' for v in r['angles_deg'].values())} | {deviation} | {r['focal']:.0f} | "
                     f"{residual} | {loo([r.get('leave_one_out')])} | {r['seconds']:.1f} | {r['peak_rss_mb'] / 1024:.2f} |")
    if rig:
        means = " / ".join(f"{rig[p]['mean_angle_deg']:.1f}" for p in ("01", "02", "12"))
        medians = " / ".join(f"{rig[p]['median_deg']:.2f}" for p in ("01", "02", "12"))
        residuals = [r["residual_px"] for r in records if r["residual_px"] is not None]
        lines.append(f"| **median** | {summary['registered_all']}/{summary['captures']} captures | {means} (rig mean) | "
                     f"**{medians}** | spread {100 * summary['focal_spread']:.0f} % | "
                     f"{np.median(residuals):.2f} | {loo([r.get('leave_one_out') for r in records])} | "
                     f"{summary['fuse_s_median']:.1f} | {summary['peak_rss_mb'] / 1024:.2f} |")
        for finger, medians in summary.get("by_finger", {}).items():
            values = " / ".join(f"{medians[p]:.2f}" for p in ("01", "02", "12"))
            lines.append(f"| median, finger {finger} | | | {values} | | | | | |")
    return "\n".join(lines)


def two_view_table(summary: dict) -> str:
    """Two views fused alone, per view pair: registered captures, turn error against all three views (and per finger),
    how many turned wider than with all three, and the deviation from the rig mean (and per finger)."""
    lines = ["| views fused alone | registered | turn error ° against the three-view fuse, median (max) | per finger | "
             "turned wider than with all views: captures, signed median ° | deviation from the rig mean °, median (max) "
             "| per finger |", "|---|---|---|---|---|---|---|"]

    def per_finger(values: dict) -> str:
        return ", ".join(f"{finger} {'–' if value is None else f'{value:.2f}'}"
                         for finger, value in values.items()) or "–"

    def median_max(median: float | None, largest: float | None) -> str:
        return "–" if median is None else f"{median:.2f} ({largest:.2f})"

    for pair, entry in summary.get("two_views", {}).items():
        signed = entry.get("signed", 0)
        wider = (f"{entry['wider']} of {signed}, {entry['excess_median_deg']:+.2f}" if signed else "–")
        lines.append(f"| {pair[0]}, {pair[1]} | {entry['registered']} of {entry['captures']} "
                     f"| {median_max(entry['median_deg'], entry['max_deg'])} "
                     f"| {per_finger(entry.get('by_finger', {}))} "
                     f"| {wider} | {median_max(entry.get('rig_median_deg'), entry.get('rig_max_deg'))} "
                     f"| {per_finger(entry.get('rig_by_finger', {}))} |")
    return "\n".join(lines)
