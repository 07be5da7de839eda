"""The same photos given in every order: how far a capture's result moves with the order alone.

A fuse should not depend on the order its photos are given in; every default was tuned with the real captures in
their rig's order (front, side, side), and users give them in any. :func:`in_every_order` fuses one capture once per
order of its views (six for three) and returns each record (:func:`~fingersplat3d.experiments.real.measure_real`'s)
with its cameras put back in the capture's own order, so the orders compare camera by camera and each order's records
over a dataset feed :func:`~fingersplat3d.eval.rig_consistency.rig_consistency` as the rig's order does.
:func:`order_spread` is the figure of one capture: the largest angle between two orders' turns of any camera pair,
and the spread of the fitted focal over the orders. Pure numpy/scipy around the fuse.
"""
from __future__ import annotations

import itertools

import numpy as np

__all__ = ["in_every_order", "order_spread", "orders_table"]


def _order_key(order) -> str:
    return "".join(str(v) for v in order)


def in_every_order(capture, config=None) -> dict[str, dict]:
    """Per order of the capture's views (key ``"021"``: views 0, 2, 1 given in that order): the fuse's record, its
    ``world_to_cam``, ``sizes`` and ``angles_deg`` in the capture's own view order."""
    from ..scene import Capture
    from .real import measure_real, pair_angles_deg

    count = len(capture.views)
    records = {}
    for order in itertools.permutations(range(count)):
        record = measure_real(Capture(tuple(capture.views[v] for v in order), capture.metadata), config)
        position = {view: k for k, view in enumerate(order)}  # where the capture's view lies in the order given
        for key in ("world_to_cam", "sizes"):
            record[key] = [record[key][position[view]] for view in range(count)]
        record["angles_deg"] = pair_angles_deg([np.asarray(pose)[:3, :3] for pose in record["world_to_cam"]])
        record["order"] = _order_key(order)
        records[record["order"]] = record
    return records


def order_spread(by_order: dict[str, dict]) -> dict:
    """One capture's spread over its orders: ``turn_deg`` the largest angle between two orders' relative rotations of
    any camera pair (orders with every view registered), ``focal`` the fitted focal's range over its median, and
    ``registered_orders`` how many orders registered every view."""
    from ..eval.poses import rotation_angle_deg
    from .real import focal_spread

    whole = [r for r in by_order.values() if r["registered"] == len(r["world_to_cam"])]
    nan = float("nan")
    if len(whole) < 2:
        return {"turn_deg": nan, "focal": nan, "registered_orders": len(whole)}
    count = len(whole[0]["world_to_cam"])
    rotations = [[np.asarray(pose)[:3, :3] for pose in r["world_to_cam"]] for r in whole]
    turn = 0.0
    for i, j in itertools.combinations(range(count), 2):
        relative = [R[j] @ R[i].T for R in rotations]
        for first, second in itertools.combinations(relative, 2):
            turn = max(turn, float(rotation_angle_deg(first, second)))
    return {"turn_deg": turn, "focal": focal_spread([r["focal"] for r in whole]), "registered_orders": len(whole)}


def orders_table(by_capture: dict[str, dict[str, dict]]) -> str:
    """Markdown: per order, the rig deviation of the dataset's captures given in that order (pairs' medians, max,
    focal spread); then per capture, its spread over the orders (:func:`order_spread`)."""
    from .real import summarize_real

    orders = sorted({order for by_order in by_capture.values() for order in by_order})
    lines = ["| views given as | rig deviation 0-1 / 0-2 / 1-2 ° (max) | focal spread |", "|---|---|---|"]
    for order in orders:
        summary = summarize_real([by_order[order] for by_order in by_capture.values() if order in by_order])
        pairs = " / ".join(f"{entry['median_deg']:.2f}" for entry in summary["rig"].values()) or "–"
        lines.append(f"| {', '.join(order)} | {pairs} ({summary['rig_deviation_max_deg']:.2f}) | "
                     f"{100 * summary['focal_spread']:.1f} % |")
    spreads = {name: order_spread(by_order) for name, by_order in by_capture.items()}
    lines += ["", "| capture | orders with every view registered | turn spread ° | focal spread |", "|---|---|---|---|"]
    for name, spread in spreads.items():
        lines.append(f"| {name} | {spread['registered_orders']} of {len(by_capture[name])} | {spread['turn_deg']:.2f} | "
                     f"{100 * spread['focal']:.1f} % |")
    turns = [s["turn_deg"] for s in spreads.values() if np.isfinite(s["turn_deg"])]
    focals = [s["focal"] for s in spreads.values() if np.isfinite(s["focal"])]
    if turns:
        lines.append(f"| **median** (range) | | **{np.median(turns):.2f}** ({min(turns):.2f}–{max(turns):.2f}) | "
                     f"**{100 * np.median(focals):.1f} %** ({100 * min(focals):.1f}–{100 * max(focals):.1f} %) |")
    return "\n".join(lines)
