"""Rig consistency: a check of real reconstructions that needs no ground truth.

A rig is fixed hardware, so the relative rotation ``R_j R_i^T`` of two of its cameras is the same
in every capture. :func:`rig_consistency` takes one record per capture (``capture`` name,
``registered`` view count, ``sizes`` [[w, h]] and ``world_to_cam`` 4x4 per view, in the rig's camera
order) and gives, per camera pair, the robust mean relative rotation over the captures (an
iteratively reweighted rotation mean, so one failed capture does not drag it) and each capture's
deviation from it in degrees. A camera stored portrait (its image taller than wide where the same
camera's is wider than tall in most other captures, or the other way round: the orientation, not the
size, as crops differ in size) sees the rig turned by +-90 degrees about its optical axis; that roll
is taken out (the sign that agrees with the other captures) before comparing.
:func:`deviation_against` measures other reconstructions of the same captures (the photos cropped,
say) against the rig mean of the whole ones. Pure numpy/scipy.
"""
from __future__ import annotations

import numpy as np

__all__ = ["PAIRS", "rig_consistency", "deviation_against", "pair_deviation_deg"]

PAIRS = ((0, 1), (0, 2), (1, 2))


def rig_consistency(records: list[dict]) -> dict:
    """Per camera pair: each capture's deviation from the robust mean relative rotation (degrees)."""
    from scipy.spatial.transform import Rotation

    from ..align.solve.rig import quarter_turn, robust_rotation_mean

    usable = [r for r in records if r["registered"] == 3]
    if len(usable) < 2:
        return {}
    sizes = np.array([[tuple(s) for s in r["sizes"]] for r in usable])  # [C, 3, 2]
    landscape = sizes[..., 0] >= sizes[..., 1]  # [C, 3]: the orientation, not the size (crops differ in size)
    rotations = {}
    for r in usable:
        R = [np.asarray(pose)[:3, :3] for pose in r["world_to_cam"]]
        rotations[r["capture"]] = R
    # A camera stored portrait: its frame is the rig's rolled by +-90 degrees; pick the sign that agrees.
    for k in range(3):
        majority = bool(np.sum(landscape[:, k]) * 2 >= len(usable))
        for r, wide in zip(usable, landscape[:, k]):
            if bool(wide) != majority:
                others = [rotations[o["capture"]] for o in usable if o is not r]
                best = None
                for sign in (1, -1):
                    trial = list(rotations[r["capture"]])
                    trial[k] = quarter_turn(sign % 4) @ trial[k]
                    cost = sum(Rotation.from_matrix((trial[j] @ trial[i].T) @ (o[j] @ o[i].T).T).magnitude()
                               for o in others for i, j in PAIRS)
                    best = min(best, (cost, sign, trial), key=lambda t: t[0]) if best else (cost, sign, trial)
                rotations[r["capture"]] = best[2]
                r["roll_corrected"] = {"camera": k, "sign": best[1]}
    result = {}
    for i, j in PAIRS:
        relative = {name: R[j] @ R[i].T for name, R in rotations.items()}
        mean = Rotation.from_matrix(robust_rotation_mean(list(relative.values())))
        deviation = {name: float(np.degrees((Rotation.from_matrix(rel) * mean.inv()).magnitude())) for name, rel in relative.items()}
        result[f"{i}{j}"] = {"mean_angle_deg": float(np.degrees(mean.magnitude())), "deviation_deg": deviation,
                             "median_deg": float(np.median(list(deviation.values()))),
                             "mean_rotation": mean.as_matrix().tolist()}
    return result


def deviation_against(records: list[dict], reference: list[dict]) -> dict:
    """Per camera pair, each record's deviation (degrees) from the rig mean of ``reference`` (:func:`rig_consistency`
    records of whole captures): other reconstructions of the same captures, matched by ``capture`` name, their
    cameras turned as the reference's portrait cameras were (a crop keeps its camera's orientation, not its aspect).
    Records of captures the reference lacks, or with a view unregistered, are left out."""
    reference = [dict(r) for r in reference]
    rig = rig_consistency(reference)
    if not rig:
        return {}
    by_name = {r["capture"]: r for r in reference if r["registered"] == 3}
    result = {f"{i}{j}": {} for i, j in PAIRS}
    for record in records:
        whole = by_name.get(record["capture"])
        if whole is None or record["registered"] != 3:
            continue
        R = [np.asarray(pose)[:3, :3] for pose in record["world_to_cam"]]
        for i, j in PAIRS:
            result[f"{i}{j}"][record["capture"]] = pair_deviation_deg(rig, whole, i, j, R[i], R[j])
    return result


def pair_deviation_deg(rig: dict, whole: dict, i: int, j: int, rotation_i: np.ndarray, rotation_j: np.ndarray) -> float:
    """How far (degrees) cameras ``i`` and ``j`` of one capture, with world-to-camera rotations ``rotation_i`` and
    ``rotation_j`` from any reconstruction of it (two of its views fused alone, say), lie from the rig mean ``rig`` of
    :func:`rig_consistency`; ``whole``: that capture's record there, whose portrait camera is turned alike."""
    from scipy.spatial.transform import Rotation

    from ..align.solve.rig import quarter_turn

    R = {i: np.asarray(rotation_i, np.float64), j: np.asarray(rotation_j, np.float64)}
    if "roll_corrected" in whole and whole["roll_corrected"]["camera"] in R:
        k, sign = whole["roll_corrected"]["camera"], whole["roll_corrected"]["sign"]
        R[k] = quarter_turn(sign % 4) @ R[k]
    mean = Rotation.from_matrix(np.asarray(rig[f"{i}{j}"]["mean_rotation"]))
    return float(np.degrees((Rotation.from_matrix(R[j] @ R[i].T) * mean.inv()).magnitude()))
