"""A fixed multi-camera rig (UWA's three cameras): calibrated from many captures, and captures aligned on it.

A rig is fixed hardware: every capture it takes has the same relative camera poses and the same
focal lengths; only the finger (its position, roll and shape) changes. One capture determines the
turn between its cameras only weakly (three near-orthographic views; README "Measurements"), but
the rig's poses are shared by all captures, so pooling their correspondences determines them far
better. The model:

* the rig frame is camera 0's (landscape) frame; camera ``v`` has a rotation ``R_v`` (cam -> rig,
  ``R_0 = I``) and a centre ``c_v`` in *rig units* (camera 0's median depth of the finger = 1 in
  the first capture); each camera its own focal length ``f_v`` (from three captures on; one for all
  cameras with fewer, or when asked: :data:`PER_CAMERA_FOCAL_MIN_CAPTURES`);
* capture ``k`` sees the rig scaled by its own ``s_k`` (the finger sits nearer or farther), and
  keeps its own per-view depth surfaces (relief, fields) of
  :class:`~fingersplat3d.align.alignment_problem.AlignmentProblem`, whose loss it contributes;
* a view stored portrait among landscape ones (UWA does this now and then) is its camera turned
  by a quarter turn about the optical axis: the sign is the one that agrees with the data.

:func:`calibrate_rig` starts from the robust mean of the captures' own alignments and minimises
the sum of the captures' losses over the rig and every capture's unknowns jointly, then drops the
captures that disagree with the result (residual above ``3x`` the median) and fits again.
:func:`rig_align` aligns one capture on a known rig (the rig fixed; only the capture's scale and
surfaces move), as ``fs3d fuse --rig`` does. Pure numpy/scipy/torch.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from ...device import single_threaded
from ...rotations import axis_angle_to_matrix
from ...scene import scaled_size
from .alignment_problem import InitialState, median_depth
from .global_opt import (
    GlobalAlignConfig,
    GlobalAlignment,
    PairCorrespondences,
    alignment_problem,
    alignment_result,
    field_grids,
    reached,
    spanning_tree,
)
from .optimize import minimize
from .rig_levenberg import levenberg_marquardt_rig

__all__ = ["Rig", "RigCapture", "RigCalibration", "calibrate_rig", "rig_align", "robust_rotation_mean", "quarter_turn"]

OUTLIER_RATIO = 3.0
"""A capture whose residual exceeds this multiple of the median capture's is left out of the rig."""

PER_CAMERA_FOCAL_MIN_CAPTURES = 3
"""Each camera its own focal from this many captures on; fewer fit one for all. Real UWA rig (docs/measurements.md,
"Each camera its own focal"): the front camera fits a focal 6-7 % shorter than the side cameras' from either finger
alone (4 and 5 captures) and from every eight of the nine, and a left-out frame's ridges are predicted better on 8 of
9 captures; synthetic (one true focal): the cameras' focals within 1-2 % of each other from three captures or more,
the rotations as with one focal, but from two captures 2.5 % apart and up to 0.14 degrees worse."""


def quarter_turn(turns: int) -> np.ndarray:
    """Rotation by ``turns * 90`` degrees about the optical (z) axis of a camera frame."""
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][turns % 4]
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def robust_rotation_mean(rotations: Sequence[np.ndarray], floor_deg: float = 0.25) -> np.ndarray:
    """Iteratively reweighted (weight 1 / deviation) mean of ``[3, 3]`` rotations: one outlier does not drag it."""
    stack = Rotation.from_matrix(np.stack(rotations))
    mean = stack.mean()
    for _ in range(10):
        deviation = (stack * mean.inv()).magnitude()
        mean = stack.mean(weights=1.0 / np.maximum(deviation, np.radians(floor_deg)))
    return mean.as_matrix()


@dataclass(frozen=True, eq=False)
class Rig:
    """Camera poses in the rig frame, their image sizes (landscape as the rig holds them) and their focal lengths."""

    names: tuple[str, ...]
    sizes: tuple[tuple[int, int], ...]  # (width, height) per camera
    rotations: np.ndarray  # [V, 3, 3] cam -> rig, camera 0 the identity
    centers: np.ndarray  # [V, 3] camera centres, rig units, camera 0 at the origin
    focals: np.ndarray
    """[V] each camera's focal length (pixels); one number is every camera's."""
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        focals = np.broadcast_to(np.asarray(self.focals, np.float64), (len(self.names),)).copy()
        object.__setattr__(self, "focals", focals)

    @property
    def focal(self) -> float:
        """The cameras' focal length: their geometric mean where each has its own."""
        return float(np.exp(np.mean(np.log(self.focals))))

    @property
    def one_focal(self) -> bool:
        """Whether every camera has the same focal length."""
        return bool(np.allclose(self.focals, self.focals[0], rtol=1e-9))

    def cam_to_rig(self, camera: int) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = self.rotations[camera], self.centers[camera]
        return pose

    def subset(self, cameras: Sequence[int]) -> "Rig":
        """The rig of some of its cameras (in that order), re-expressed in the first one's frame."""
        cameras = list(cameras)
        first = np.linalg.inv(self.cam_to_rig(cameras[0]))
        poses = [first @ self.cam_to_rig(v) for v in cameras]
        return replace(self, names=tuple(self.names[v] for v in cameras), sizes=tuple(self.sizes[v] for v in cameras),
                       focals=self.focals[cameras], rotations=np.stack([pose[:3, :3] for pose in poses]),
                       centers=np.stack([pose[:3, 3] for pose in poses]))

    def scaled(self, factor: float) -> "Rig":
        """The same rig for its photos resized by ``factor`` (the working resolution): sizes and focals in its pixels."""
        if factor == 1.0:
            return self
        return replace(self, sizes=tuple(scaled_size(size, factor) for size in self.sizes), focals=self.focals * factor)

    def turns_for(self, camera: int, size: tuple[int, int]) -> tuple[int, ...]:
        """Quarter turns a view of ``size`` may be rotated by against camera ``camera``: (0,) or (1, 3) for a portrait one."""
        own = tuple(self.sizes[camera])
        if tuple(size) == own:
            return (0,)
        if tuple(size) == own[::-1]:
            return (1, 3)
        raise ValueError(f"a {size[0]}x{size[1]} view cannot be camera {self.names[camera]!r} of the rig ({own[0]}x{own[1]})")


@dataclass(frozen=True, eq=False)
class RigCapture:
    """What one capture brings to a calibration: its pointmap depths, guesses, correspondences and own alignment."""

    name: str
    depths: list[np.ndarray]
    focal_guesses: list[float]
    correspondences: list[PairCorrespondences]
    alignment: GlobalAlignment
    sizes: list[tuple[int, int]]
    view_names: tuple[str, ...] = ()
    contours: list[PairCorrespondences] = field(default_factory=list)
    """Its silhouette contours, as its own last alignment chose them and was fitted to beside the matches (empty when
    none joined it). Without them the joint fit stood on other surfaces than the captures' own fits and turned the
    front camera against both side ones: synthetic uwa rig (six captures), camera 2 0.73 degrees off the true rig and
    the focal +1.0 %; with them 0.21 degrees and +0.1 %. Chosen again through the rig's cameras between joint fits,
    the rig came out the same within 0.05 degree (nine real captures; 0.01 on the synthetic ones) for three times the
    time (docs/measurements.md, "Rig self-calibration")."""


@dataclass(frozen=True, eq=False)
class RigCalibration:
    rig: Rig
    used: list[str]
    left_out: dict[str, str]  # capture -> reason
    residual_px: dict[str, float]  # per used capture
    alignments: dict[str, GlobalAlignment]

    def in_photo_pixels(self, factor: float) -> "RigCalibration":
        """The same calibration with the rig's focal lengths in the photos' pixels, its captures registered at the
        working resolution ``factor`` (a rig's sizes are the photos' already; any later fuse scales it its own way)."""
        return replace(self, rig=replace(self.rig, focals=self.rig.focals / factor))


# ------------------------------------------------------------------------------------------ model

class RigProblem(torch.nn.Module):
    """Captures of one rig: shared poses and focal lengths (one, or one per camera with ``per_camera``), a scale per
    capture, each capture's own surfaces."""

    def __init__(self, problems, rig: Rig, turns: Sequence[Sequence[int]], log_capture_scales: Sequence[float],
                 fixed_rig: bool, per_camera: bool = False) -> None:
        super().__init__()
        dtype = torch.float64
        self.problems = torch.nn.ModuleList(problems)
        for problem in problems:  # poses and focal come from the rig
            for parameter in (problem.omega, problem.translation, problem.log_focal):
                parameter.requires_grad_(False)
        self.register_buffer("base_rotation", torch.as_tensor(rig.rotations, dtype=dtype))
        self.register_buffer("free", torch.as_tensor([0.0] + [1.0] * (len(rig.names) - 1), dtype=dtype))
        self.register_buffer("turns", torch.as_tensor(np.stack([np.stack([quarter_turn(t).T for t in row]) for row in turns]),
                                                      dtype=dtype))  # [K, V, 3, 3]: Q^T per capture view
        self.omega = torch.nn.Parameter(torch.zeros((len(rig.names), 3), dtype=dtype), requires_grad=not fixed_rig)
        self.center = torch.nn.Parameter(torch.as_tensor(rig.centers, dtype=dtype).clone(), requires_grad=not fixed_rig)
        log_focal = np.log(rig.focals) if per_camera else np.log(rig.focal)  # [V] or one for all
        self.log_focal = torch.nn.Parameter(torch.as_tensor(log_focal, dtype=dtype).clone(), requires_grad=not fixed_rig)
        self.log_capture_scale = torch.nn.Parameter(torch.as_tensor(np.asarray(log_capture_scales), dtype=dtype).clone())
        # the rig's unit is the first capture's (a free rig and free capture scales would trade)
        scale_free = np.ones(len(problems)) if fixed_rig else np.r_[0.0, np.ones(len(problems) - 1)]
        self.register_buffer("scale_free", torch.as_tensor(scale_free, dtype=dtype))

    def rig_rotations(self) -> torch.Tensor:
        return axis_angle_to_matrix(self.omega * self.free[:, None]) @ self.base_rotation

    def rig_centers(self) -> torch.Tensor:
        return self.center * self.free[:, None]

    def cameras(self, capture: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Capture ``capture``'s cameras in its own frame (= the rig frame scaled by its scale)."""
        rotations = self.rig_rotations() @ self.turns[capture]
        translations = self.rig_centers() * torch.exp(self.log_capture_scale[capture] * self.scale_free[capture])
        return rotations, translations, torch.exp(self.log_focal).expand(rotations.shape[0])

    def forward(self) -> torch.Tensor:
        return sum(problem(self.cameras(k)) for k, problem in enumerate(self.problems))

    def rig(self, template: Rig, info: dict) -> Rig:
        with torch.no_grad():
            return replace(template, rotations=self.rig_rotations().numpy(), centers=self.rig_centers().numpy(),
                           focals=torch.exp(self.log_focal).numpy(), info=info)


def _median_depths(depths: Sequence[np.ndarray]) -> np.ndarray:
    return np.array([median_depth(d) for d in depths])


def _capture_problem(capture: RigCapture, rig: Rig, turns: Sequence[int], config: GlobalAlignConfig,
                     previous: GlobalAlignment | None, per_camera: bool = False):
    """One capture's problem with root view 0, its surfaces started from ``previous`` (or the pointmaps)."""
    depths = capture.depths
    n_views = len(depths)
    root = 0
    _, tree = spanning_tree(n_views, capture.correspondences, root)
    aligned = reached(n_views, root, tree)
    grids = field_grids(depths, config)
    medians = _median_depths(depths)
    if previous is not None:  # the previous alignment's depth proportions, re-rooted at view 0
        previous_medians = _median_depths(previous.depths)
        relative = previous_medians / previous_medians[root]
        alphas = np.log(np.asarray(previous.relief_scale, np.float64))
        fields = [np.asarray(f, np.float64) for f in previous.fields]
    else:
        relative, alphas, fields = np.ones(n_views), np.zeros(n_views), [np.zeros(g.size) for g in grids]
    log_scales = np.log(relative / medians)
    rotations = np.stack([rig.rotations[v] @ quarter_turn(turns[v]).T for v in range(n_views)])
    initial = InitialState(rotations, rig.centers.copy(), log_scales, alphas, np.log(rig.focals), fields)
    guesses = np.broadcast_to(np.asarray(capture.focal_guesses, np.float64), (n_views,)).copy()
    # The rig holds the poses (camera centres, chained onto its own unknowns): no pivot.
    problem, data = alignment_problem(depths, guesses, list(capture.correspondences) + list(capture.contours),
                                      replace(config, pivot_poses=False, shared_focal=not per_camera), grids, initial,
                                      aligned, root)
    return problem, data, grids, tree, aligned


def _solve(captures: Sequence[RigCapture], rig: Rig, turns, config: GlobalAlignConfig, fixed_rig: bool,
           previous: Sequence[GlobalAlignment | None], per_camera: bool = False):
    built = [_capture_problem(c, rig, t, config, p, per_camera) for c, t, p in zip(captures, turns, previous)]
    problem = RigProblem([b[0] for b in built], rig, turns, np.zeros(len(captures)), fixed_rig, per_camera)
    with single_threaded():
        if config.solver == "lm":
            history = levenberg_marquardt_rig(problem, config.lm_iterations, fixed_rig=fixed_rig)
        else:
            history = minimize(problem, 0, config.learning_rate, config.polish_iterations, config.polish_rounds)
    alignments = []
    with torch.no_grad():
        for k, (capture_problem, data, grids, tree, aligned) in enumerate(built):
            alignments.append(alignment_result(capture_problem, captures[k].depths, grids, data, 0, tree, aligned,
                                               history, cameras=problem.cameras(k)))
    loss = history[-1] if history else float("nan")
    return problem, alignments, loss


# ---------------------------------------------------------------------------------------- start

def _relative_rotation(alignment: GlobalAlignment, view: int, turns: Sequence[int]) -> np.ndarray:
    """Camera ``view``'s landscape frame -> camera 0's landscape frame, from one capture's own alignment."""
    land = [alignment.cam_to_world[v][:3, :3] @ quarter_turn(turns[v]) for v in range(len(turns))]
    return land[0].T @ land[view]


def _initial_rig(captures: Sequence[RigCapture], names: Sequence[str]) -> tuple[Rig, list[tuple[int, ...]]]:
    """The robust mean of the captures' own alignments, and each capture's quarter turns (portrait views)."""
    n_views = len(names)
    sizes = np.array([[tuple(s) for s in c.sizes] for c in captures])  # [K, V, 2]
    landscape = []
    for v in range(n_views):
        counts: dict[tuple[int, int], int] = {}
        for size in map(tuple, sizes[:, v]):
            counts[size] = counts.get(size, 0) + 1
        landscape.append(max(counts, key=lambda s: (counts[s], s[0] >= s[1])))
    template = Rig(tuple(names), tuple(landscape), np.stack([np.eye(3)] * n_views), np.zeros((n_views, 3)), 1.0)
    options = [list(itertools.product(*[template.turns_for(v, tuple(size)) for v, size in enumerate(c.sizes)])) for c in captures]
    turns = [o[0] for o in options]
    means = [np.eye(3)] + [robust_rotation_mean([_relative_rotation(c.alignment, v, t) for c, t in zip(captures, turns)])
                           for v in range(1, n_views)]
    for k, capture in enumerate(captures):  # a portrait view: the quarter turn that agrees with the others
        if len(options[k]) > 1:
            turns[k] = min(options[k], key=lambda t: sum(Rotation.from_matrix(_relative_rotation(capture.alignment, v, t).T @ means[v]).magnitude()
                                                         for v in range(1, n_views)))
    rotations = np.stack([np.eye(3)] + [robust_rotation_mean([_relative_rotation(c.alignment, v, t) for c, t in zip(captures, turns)])
                                        for v in range(1, n_views)])
    centers = []
    for capture, t in zip(captures, turns):
        pose0 = capture.alignment.cam_to_world[0]
        land0 = pose0[:3, :3] @ quarter_turn(t[0])
        unit = float(np.nanmedian(capture.alignment.depths[0]))
        centers.append([land0.T @ (capture.alignment.cam_to_world[v][:3, 3] - pose0[:3, 3]) / unit for v in range(n_views)])
    focal = float(np.median([c.alignment.focals[0] for c in captures]))
    return replace(template, rotations=rotations, centers=np.median(np.asarray(centers), axis=0), focals=focal), turns


# ------------------------------------------------------------------------------------------- API

def calibrate_rig(captures: Sequence[RigCapture], names: Sequence[str],
                  config: GlobalAlignConfig = GlobalAlignConfig(), per_camera_focal: bool = True) -> RigCalibration:
    """The rig that best explains every capture's correspondences (see the module docstring).

    ``captures``: registered captures with all views aligned, at least 2; their views are the
    rig's cameras in order. ``per_camera_focal``: each camera its own focal length, from
    :data:`PER_CAMERA_FOCAL_MIN_CAPTURES` captures on (fewer fit one for all cameras).
    """
    captures = [c for c in captures if all(c.alignment.aligned)]
    if len({c.name for c in captures}) < len(captures):  # names key the report: make them unique
        captures = [replace(c, name=f"{c.name}#{k}") for k, c in enumerate(captures)]
    if len(captures) < 2:
        raise ValueError(f"a rig calibration needs at least 2 captures with every view registered, got {len(captures)}")
    left_out: dict[str, str] = {}
    rig, turns = _initial_rig(captures, names)
    used = list(range(len(captures)))
    for attempt in range(3):
        chosen = [captures[k] for k in used]
        per_camera = per_camera_focal and len(chosen) >= PER_CAMERA_FOCAL_MIN_CAPTURES
        problem, alignments, _ = _solve(chosen, rig, [turns[k] for k in used], config, fixed_rig=False,
                                        previous=[c.alignment for c in chosen], per_camera=per_camera)
        residuals = np.array([a.residual_px for a in alignments])
        limit = OUTLIER_RATIO * float(np.median(residuals))
        outliers = [k for k, r in zip(used, residuals) if not r <= limit]
        if attempt == 2 or not outliers or len(used) - len(outliers) < 2:
            break
        for k in outliers:
            left_out[captures[k].name] = f"residual {residuals[used.index(k)]:.2f} px, over {OUTLIER_RATIO:g}x the median"
        used = [k for k in used if k not in outliers]
    names_used = [captures[k].name for k in used]
    info = {"captures": names_used, "left_out": left_out, "focal": "each camera its own" if per_camera else "one for all",
            "turns": {captures[k].name: list(turns[k]) for k in used},
            "residual_px": {captures[k].name: round(float(a.residual_px), 3) for k, a in zip(used, alignments)}}
    rig = problem.rig(rig, info)
    return RigCalibration(rig, names_used, left_out, info["residual_px"], dict(zip(names_used, alignments)))


def rig_align(depths: Sequence[np.ndarray], focal_guess, pairs: Sequence[PairCorrespondences], config: GlobalAlignConfig,
              rig: Rig, sizes: Sequence[tuple[int, int]], previous: GlobalAlignment | None = None,
              contours: Sequence[PairCorrespondences] = ()) -> GlobalAlignment:
    """One capture aligned on a fixed ``rig`` (its views are the rig's cameras in order): only its scale and surfaces move.
    ``contours``: its silhouette contours (they shape the surfaces; only ``pairs`` place views).

    A portrait view's quarter turn is the one with the lower loss. Views that no registered pair
    reaches are not aligned (as :func:`~fingersplat3d.align.global_opt.global_align`).
    """
    if len(depths) != len(rig.names):
        raise ValueError(f"the rig has {len(rig.names)} cameras but the capture {len(depths)} views")
    guesses = np.broadcast_to(np.asarray(focal_guess, np.float64), (len(depths),)).tolist()
    capture = RigCapture("capture", list(depths), guesses, list(pairs), previous, list(sizes), contours=list(contours))
    best = None
    for turns in itertools.product(*[rig.turns_for(v, tuple(size)) for v, size in enumerate(sizes)]):
        _, (alignment,), loss = _solve([capture], rig, [turns], config, fixed_rig=True, previous=[previous],
                                       per_camera=not rig.one_focal)
        if best is None or loss < best[0]:
            best = (loss, alignment)
    return best[1]
