"""The experiments' pictures: DET curves, time-vs-error trade curves and a sweep's captures by their turn and depth
errors (matplotlib, Agg, PNG)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["det_picture", "sweep_picture", "trade_picture"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _finish(figure, path: Path, note: str = "") -> Path:
    """Lay ``figure`` out, ``note`` (the machine) in small print under it, write it to ``path`` and close it."""
    if note:
        figure.text(0.01, 0.01, note, fontsize=7, color="0.35")
    figure.tight_layout(rect=(0, 0.03 if note else 0, 1, 1))
    figure.savefig(path)
    _pyplot().close(figure)
    return path


def det_picture(path: Path, curves: dict[str, tuple[np.ndarray, np.ndarray]], title: str) -> Path:
    """DET curves (FNMR against FMR, log axes) for ``{label: (fmr, fnmr)}``; rates of 0 are drawn
    at the plot's floor (half the smallest non-zero rate) so that steps to zero stay visible."""
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(5.5, 5), dpi=120)
    positive = [v[v > 0] for fmr, fnmr in curves.values() for v in (fmr, fnmr)]
    floor = 0.5 * min((v.min() for v in positive if v.size), default=1e-3)
    for label, (fmr, fnmr) in curves.items():
        axes.step(np.maximum(fmr, floor), np.maximum(fnmr, floor), where="post", label=label)
    axes.plot([floor, 1], [floor, 1], color="0.7", linestyle=":", linewidth=1, label="FMR = FNMR")
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.set_xlim(floor, 1.05)
    axes.set_ylim(floor, 1.05)
    axes.set_xlabel(f"false match rate (0 drawn at {floor:.1g})")
    axes.set_ylabel("false non-match rate")
    axes.set_title(title)
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=8)
    return _finish(figure, path)


def trade_picture(path: Path, curves: dict[str, list[tuple[float, float, str]]], x_label: str, y_label: str,
                  title: str, note: str = "") -> Path:
    """One curve per knob: ``{knob: [(time, error, setting label), ...]}``, points labelled; ``note``
    (the machine) in small print under the plot."""
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(7, 5), dpi=120)
    for knob, points in curves.items():
        points = sorted(points)
        xs, ys = [p[0] for p in points], [p[1] for p in points]
        axes.plot(xs, ys, marker="o", label=knob)
        for x, y, label in points:
            axes.annotate(label, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=7)
    axes.set_xlabel(x_label)
    axes.set_ylabel(y_label)
    axes.set_title(title, fontsize=10)
    axes.grid(True, alpha=0.3)
    axes.legend(fontsize=8)
    return _finish(figure, path, note)


def sweep_picture(path: Path, points: dict[str, list[tuple[float, float, bool]]], warn_above_deg: float,
                  depth_target_mm: float, title: str, note: str = "") -> Path:
    """A sweep's captures, one marker each: ``{kind: [(worst pair's turn error in degrees, depth MAE in mm, warned),
    ...]}``; filled where the capture carries a warning, hollow where not, so that a hollow marker right of the
    ``warn_above_deg`` line is a bad capture a user could not tell; the depth target as a line."""
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(7, 5), dpi=120)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for colour, (kind, marks) in zip(colours, points.items()):
        for warned in (True, False):
            chosen = [(x, y) for x, y, w in marks if w == warned]
            if not chosen:
                continue
            xs, ys = zip(*chosen)
            axes.scatter(np.maximum(xs, 0.01), ys, s=28, edgecolors=colour, linewidths=1.2,
                         facecolors=colour if warned else "none",
                         label=f"{kind}, {'warned' if warned else 'no warning'} ({len(chosen)})")
    axes.axvline(warn_above_deg, color="0.4", linestyle="--", linewidth=1)
    axes.axhline(depth_target_mm, color="0.4", linestyle=":", linewidth=1)
    axes.text(warn_above_deg * 1.05, 0.97, f"{warn_above_deg:g}°: should warn", fontsize=7, color="0.3", va="top",
              transform=axes.get_xaxis_transform())
    axes.text(0.99, depth_target_mm * 1.03, f"{depth_target_mm:g} mm target", fontsize=7, color="0.3", ha="right",
              transform=axes.get_yaxis_transform())
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.set_xlabel("worst view pair's turn error (degrees)")
    axes.set_ylabel("depth MAE over whole views, after scale and shift (mm)")
    axes.set_title(title, fontsize=10)
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=7, loc="upper left")
    return _finish(figure, path, note)
