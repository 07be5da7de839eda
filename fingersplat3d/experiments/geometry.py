"""The geometry of ``fs3d fuse`` against synthetic ground truth: rigs, numbers of views, seeds.

Each case is a rig of ``fs3d synth`` (``ring``: cameras at -45, -22.5, 0, +22.5, +45 degrees about the
finger; ``uwa``: three cameras at -45/0/+45 with the finger laid in by hand; ``cfpose``: one camera, the
finger rolled by up to 45 degrees between ten shots) and a number of views handed to ``fuse`` (images
and masks only, no cameras, no depth). Scored per capture:

* rotation error: the angle between the predicted and the true relative rotation of every pair of
  fused views (median and max over the pairs);
* depth error: per fused view, the mean absolute error after a least-squares scale and shift inside
  the ground-truth mask, over the *whole* view (rims included); the mean over the views and the worst;
* all views registered, the alignment residual, the fuse's wall time and the process's peak memory.

Every case runs in a fresh process over all its seeds (:func:`run_geometry`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .process import in_fresh_process, peak_rss_mb
from ..synth.rigs import CAMERA_DISTANCE_MM

__all__ = ["GeometryCase", "CASES", "RING_ANGLES", "RING_VIEWS", "pick_views", "score_geometry", "synth_captures", "run_geometry",
           "geometry_table", "columns_cropped"]

RING_ANGLES = (-45.0, -22.5, 0.0, 22.5, 45.0)
RING_VIEWS = {2: ("v0", "v2"), 3: ("v0", "v2", "v4"), 5: ("v0", "v1", "v2", "v3", "v4")}


@dataclass(frozen=True)
class GeometryCase:
    """A rig of ``fs3d synth``, the number of its views fused, and the image size."""

    rig: str  # "ring" | "uwa" | "cfpose"
    views: int
    size: tuple[int, int] = (640, 512)
    distance_mm: float = CAMERA_DISTANCE_MM
    """Camera to finger (the framing kept): short for a wide-angle close-up, long for a nearly orthographic camera."""
    shapes: str = "adult"
    """``fs3d synth``'s finger shapes: ``wide`` for pads and sections the ``prior`` does not share."""
    zoom: float = 1.0
    """The focal times the rig's default: at 1.6 the finger fills the frame, cut at both ends and along some sides."""

    @property
    def label(self) -> str:
        far = "" if self.distance_mm == CAMERA_DISTANCE_MM else f" at {self.distance_mm:g} mm"
        wide = "" if self.shapes == "adult" else f", {self.shapes} shapes"
        zoom = "" if self.zoom == 1.0 else f", zoomed {self.zoom:g}x"
        return f"{self.rig} {self.views} views {self.size[0]}x{self.size[1]}{far}{wide}{zoom}"

    @property
    def shots(self) -> int:
        """The shots ``fs3d synth`` takes of a cfpose finger: its default 10, or as many as the case fuses."""
        return max(10, self.views) if self.rig == "cfpose" else 0

    @property
    def synth_key(self) -> tuple:
        return (self.rig, self.size, self.distance_mm, self.shapes, self.zoom, self.shots)


CASES = {
    "ring2": GeometryCase("ring", 2), "ring3": GeometryCase("ring", 3), "ring5": GeometryCase("ring", 5),
    "uwa2": GeometryCase("uwa", 2), "uwa3": GeometryCase("uwa", 3),
    "cfpose2": GeometryCase("cfpose", 2, (512, 640)), "cfpose3": GeometryCase("cfpose", 3, (512, 640)),
    "cfpose5": GeometryCase("cfpose", 5, (512, 640)), "cfpose10": GeometryCase("cfpose", 10, (512, 640)),
    "cfpose20": GeometryCase("cfpose", 20, (512, 640)),
    "uwa3-1280": GeometryCase("uwa", 3, (1280, 1024)),
    "uwa3-wide": GeometryCase("uwa", 3, shapes="wide"), "ring5-wide": GeometryCase("ring", 5, shapes="wide"),
    "uwa3-close": GeometryCase("uwa", 3, distance_mm=50.0), "uwa3-far": GeometryCase("uwa", 3, distance_mm=400.0),
    "uwa3-zoom": GeometryCase("uwa", 3, zoom=1.6), "uwa3-wide-zoom": GeometryCase("uwa", 3, shapes="wide", zoom=1.2),
}


def pick_views(capture, case: GeometryCase) -> tuple[str, ...]:
    """The views of ``capture`` a case fuses: ring views by angle; uwa's left and centre for two views;
    cfpose's shots spread evenly over the roll, the extremes included."""
    if case.rig == "ring":
        return RING_VIEWS[case.views]
    if case.rig == "uwa":
        return ("left", "center") if case.views == 2 else tuple(capture.names)
    poses = capture.metadata["poses"]
    by_roll = sorted(capture.names, key=lambda name: poses[name]["roll_deg"])
    picked = np.unique(np.round(np.linspace(0, len(by_roll) - 1, case.views)).astype(int))
    return tuple(by_roll[i] for i in picked)


def columns_cropped(capture, first: int, last: int):
    """``capture`` with every view cut to the image columns ``first..last`` (inclusive), as datasets publish crops: its
    image, mask and true depth cut, its camera's principal point moved with the cut (the truth stays true)."""
    from ..scene import Camera, Capture

    views = []
    for view in capture.views:
        K = view.camera.K.copy()
        K[0, 2] -= first
        camera = Camera(K, view.camera.world_to_cam, last - first + 1, view.height)
        columns = slice(first, last + 1)
        views.append(view.with_(image=np.ascontiguousarray(view.image[:, columns]), mask=view.mask[:, columns].copy(),
                                depth=np.ascontiguousarray(view.depth[:, columns]), camera=camera))
    return Capture(tuple(views), capture.metadata)


def score_geometry(result, truth: dict) -> dict:
    """Rotation and depth errors of a fuse ``result`` of the views ``truth`` (name -> true view), in order."""
    from ..eval import depth_errors
    from ..eval.poses import relative_rotation_errors

    names = list(truth)
    rotations = relative_rotation_errors([c.world_to_cam for c in result.cameras],
                                         [truth[n].camera.world_to_cam for n in names])
    errors = [depth_errors(d, truth[n].depth, truth[n].mask) for n, d in zip(names, result.depths)]
    depths = [e.mae for e in errors]
    two, one = _backed_depth(result, truth, names, errors)
    return {"rotation_error_deg": float(np.median(rotations)), "rotation_mean_deg": float(np.mean(rotations)),
            "rotation_max_deg": float(np.max(rotations)),
            "depth_mae_mm": float(np.mean(depths)), "depth_worst_view_mm": float(np.max(depths)),
            "depth_two_views_mm": two, "depth_one_view_mm": one,
            "registered_all": bool(all(result.report["alignment"]["aligned"].values())),
            "turn_uncertainty_max_deg": max(result.report["alignment"].get("turn_uncertainty_deg", {}).values(),
                                            default=float("nan")),
            "turn_sensitivity_max_deg": max(result.report["alignment"].get("turn_sensitivity_deg", {}).values(),
                                            default=float("nan"))}


def _backed_depth(result, truth: dict, names: list[str], errors: list) -> tuple[float, float]:
    """The whole-view depth error split by where a second view backs each view's surface
    (:func:`~fingersplat3d.eval.depth.split_by_backing`, on each view's own scale and shift): the means over the
    views of the skin two views see and of the skin one view alone sees (NaN where no view has that part)."""
    from ..eval.depth import split_by_backing

    parts = [split_by_backing(result.depths[index], truth[name].depth, truth[name].mask, error, result.backing[index])
             for index, (name, error) in enumerate(zip(names, errors))
             if result.backing is not None and result.backing[index] is not None]
    mean = lambda values: float(np.mean(values)) if values else float("nan")  # noqa: E731
    return (mean([p.mae_two_views for p in parts if np.isfinite(p.mae_two_views)]),
            mean([p.mae_one_view for p in parts if np.isfinite(p.mae_one_view)]))


def synth_captures(seeds: list[int], folder: Path, size: tuple[int, int], rig: str,
                   distance_mm: float = CAMERA_DISTANCE_MM, shapes: str = "adult", zoom: float = 1.0,
                   shots: int = 0) -> list[Path]:
    """One ``fs3d synth`` capture of ``rig`` per seed (ring: cameras at :data:`RING_ANGLES`; the focal ``zoom`` times
    the rig's default; cfpose: ``shots`` poses, 0 for its default), pickled into ``folder`` for measurements that run
    in other processes."""
    import pickle

    from ..synth import SynthConfig, synthesize
    from ..synth.rigs import default_focal

    options = {"angles": RING_ANGLES} if rig == "ring" else {}
    if zoom != 1.0:
        options["focal"] = zoom * default_focal(size, distance_mm)
    if rig == "cfpose" and shots:
        options["poses"] = shots
    paths = []
    for seed in seeds:
        path = folder / f"{rig}-{size[0]}x{size[1]}-{distance_mm:g}mm-{shapes}-{zoom:g}x-{shots}-{seed}.pkl"
        config = SynthConfig(rig=rig, size=size, distance_mm=distance_mm, shapes=shapes, **options)
        path.write_bytes(pickle.dumps(synthesize(seed, config).capture))
        paths.append(path)
    return paths


def _measure_case(case: GeometryCase, capture_paths: list[str], config) -> list[dict]:
    """Every seed of one case, fused and scored (runs in its own process)."""
    import pickle

    from ..pipeline import fuse
    from ..scene import Capture

    rows = []
    for path in capture_paths:
        capture = pickle.loads(Path(path).read_bytes())
        names = pick_views(capture, case)
        truth = {name: capture[name] for name in names}
        blind = Capture(tuple(v.with_(camera=None, depth=None) for v in truth.values()), capture.metadata)
        row = {"case": case.label, "seed": capture.metadata.get("seed"), "views": " ".join(names)}
        started = time.perf_counter()
        try:
            result = fuse(blind, config)
        except Exception as error:  # a failed fuse is a row, not the end of the benchmark
            rows.append({**row, "status": "failed", "reason": f"{type(error).__name__}: {error}"})
            continue
        row.update(score_geometry(result, truth), status="done", wall_s=time.perf_counter() - started,
                   residual_px=result.report["alignment"].get("residual_px"), warned=bool(result.report.get("warnings")),
                   skin_loop=result.report["alignment"].get("skin_loop"))
        rows.append(row)
    for row in rows:
        row["peak_rss_mb"] = peak_rss_mb()
    return rows


def run_geometry(cases: list[GeometryCase], seeds: list[int], config=None, progress: bool = True) -> list[dict]:
    """Rows of :func:`score_geometry` per case and seed; each case in a fresh process, captures made once."""
    import tempfile

    from tqdm import tqdm

    from ..pipeline import FuseConfig

    config = config or FuseConfig(splat=None)
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        paths = {(rig, size, far, shapes, zoom, shots): [str(p) for p in synth_captures(seeds, Path(scratch), size, rig,
                                                                                         far, shapes, zoom, shots)]
                 for rig, size, far, shapes, zoom, shots in dict.fromkeys(case.synth_key for case in cases)}
        for case in tqdm(cases, desc="geometry", unit="case", disable=not progress):
            rows += in_fresh_process(_measure_case, case, paths[case.synth_key], config)
    return rows


def geometry_table(rows: list[dict]) -> str:
    """A markdown table: per case, medians over seeds (worst in brackets); the depth also split by where a second view
    backs each view's surface (:func:`score_geometry`'s ``depth_two_views_mm``, ``depth_one_view_mm``)."""
    lines = ["| case | seeds | all views registered | rotation error ° (max) | depth MAE mm (worst view) | skin two views see / "
             "one view alone sees mm | wall s | peak RSS MB |", "|---|---|---|---|---|---|---|---|"]
    for label in dict.fromkeys(r["case"] for r in rows):
        mine = [r for r in rows if r["case"] == label]
        done = [r for r in mine if r["status"] == "done"]
        if not done:
            lines.append(f"| {label} | {len(mine)} | 0 (failed) | | | | | |")
            continue
        median = lambda key: float(np.median([r[key] for r in done]))  # noqa: E731
        worst = lambda key: float(np.max([r[key] for r in done]))  # noqa: E731
        def split(key: str) -> float:  # NaN: no view of the case had such skin
            values = [r[key] for r in done if np.isfinite(r.get(key, np.nan))]
            return float(np.median(values)) if values else float("nan")
        lines.append(f"| {label} | {len(mine)} | {sum(r['registered_all'] for r in done)} | "
                     f"{median('rotation_error_deg'):.2f} ({worst('rotation_max_deg'):.2f}) | "
                     f"{median('depth_mae_mm'):.3f} ({worst('depth_worst_view_mm'):.3f}) | "
                     f"{split('depth_two_views_mm'):.3f} / {split('depth_one_view_mm'):.3f} | {median('wall_s'):.1f} | "
                     f"{worst('peak_rss_mb'):.0f} |")
    return "\n".join(lines)
