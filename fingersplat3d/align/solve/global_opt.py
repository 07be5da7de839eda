"""Global alignment of N views (the paper's eq. 3): poses, focal, scales and surface, jointly.

The problem (unknowns and loss) is :class:`~fingersplat3d.align.alignment_problem.AlignmentProblem`;
this module builds it from the pairs, starts it and solves it by Levenberg-Marquardt
(:func:`~fingersplat3d.align.solve.levenberg.levenberg_marquardt`; or the generic Adam/L-BFGS loop,
:func:`~fingersplat3d.align.solve.optimize.minimize`, with ``solver="lbfgs"``):

* start: a maximum spanning tree of the pairs by correspondence weight chains each pair's
  similarity ``b_to_a`` from the root (DUSt3R's ``init='mst'``); views the tree does not reach are
  not aligned. Or, to refine, a previous :class:`GlobalAlignment` (its poses, focal, scales and
  fields), as the registration loop does after each round of guided matching;
* outputs: poses and dense depth maps (normalised units: the root view's median pointmap depth
  is 1), residuals, and the state for the next round.

Why a surface and not free 3D points: with near-orthographic cameras the pose of a view pair and
the depth of its points trade against each other (the bas-relief ambiguity); three views fix
the trade only where their correspondences share surface. A smooth field per view makes every
correspondence of a pair inform the surface that the other pairs see, and the pointmap shape
fills in between. Measured on synthetic captures with ground truth, free points left the
relative rotations 4-8 degrees off; the fields, solved to convergence, 0.3-0.9 degrees
(docs/measurements.md, synthetic geometry).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
import torch
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

from ...device import single_threaded
from ...sampling import sample_bilinear
from ..transfer import distinct_viewpoints
from .alignment_problem import AlignmentProblem, Correspondences, InitialState, median_depth
from .depth_field import FieldGrid
from .levenberg import levenberg_marquardt, turn_uncertainty_deg
from .optimize import minimize
from .settings import PIVOT_MIN_VIEWS, GlobalAlignConfig

__all__ = ["PairCorrespondences", "GlobalAlignConfig", "GlobalAlignment", "global_align", "spanning_tree", "reached",
           "turn_uncertainty_of", "weighted_median"]


@dataclass(frozen=True, eq=False)
class PairCorrespondences:
    """Correspondences of one registered pair and its initial relative similarity."""

    a: int
    b: int
    uv_a: np.ndarray  # [M, 2] pixels in view a
    uv_b: np.ndarray  # [M, 2] pixels in view b
    weight: np.ndarray  # [M] >= 0
    b_to_a: np.ndarray  # [4, 4] similarity taking b's own-frame points into a's frame
    information_a: np.ndarray | None = None  # [M, 2, 2] in a's pixels (None: identity)
    information_b: np.ndarray | None = None  # [M, 2, 2] in b's pixels (None: identity)


@dataclass(frozen=True, eq=False)
class GlobalAlignment:
    """The aligned views: poses, focal lengths, dense depth maps, residuals and the state to refine from."""

    cam_to_world: list[np.ndarray]  # N x [4, 4] rigid
    focals: list[float]
    depths: list[np.ndarray]  # N x [H, W] float32, NaN where the pointmap had no point
    relief_scale: list[float]
    scales: list[float]
    residual_px: float
    """Weighted median reprojection error over both directions of every correspondence, in pixels
    across the ridges (information-weighted; the plain pixel distance for matches without information)."""
    residual_rel3d: float  # weighted median 3D distance between the two ends' points (normalised units)
    tree: list[tuple[int, int]]
    aligned: list[bool]  # views reached by the spanning tree
    root: int
    fields: list[np.ndarray] = field(default_factory=list)
    loss_history: list[float] = field(default_factory=list)
    turn_uncertainty_deg: np.ndarray | None = None
    """``[N, N]``: each view pair's rotation uncertainty from the fit's curvature (degrees; NaN for a view
    not aligned), where the solver gives one (Levenberg-Marquardt); None otherwise."""
    turn_sensitivity_deg: np.ndarray | None = None
    """``[N, N]``: how far each view pair's turn moves when the focal is held 10 % off its solved value, or shorter where
    the photos do not hold it (degrees; :mod:`~fingersplat3d.align.solve.sensitivity`), where the registration probed
    it; None otherwise."""
    focal_probe: dict | None = None
    """:meth:`~fingersplat3d.align.solve.sensitivity.FocalProbe.summary` of that probe (whether the photos hold the
    focal, the loss's rises), where the registration probed it; None otherwise."""

    @property
    def world_to_cam(self) -> list[np.ndarray]:
        return [np.linalg.inv(pose) for pose in self.cam_to_world]


def spanning_tree(n_views: int, pairs: Sequence[PairCorrespondences], root: int | None = None) -> tuple[int, list[tuple[int, int]]]:
    """Maximum spanning tree by total correspondence weight; the root and parent->child edges in breadth-first order."""
    strength = np.zeros((n_views, n_views))
    for pair in pairs:
        total = float(np.sum(pair.weight))
        strength[pair.a, pair.b] += total
        strength[pair.b, pair.a] += total
    if root is None:
        root = int(np.argmax(strength.sum(1))) if strength.any() else 0
    if not strength.any():
        return root, []
    # A minimum spanning tree of the negated weights is a maximum one (zero entries are "no edge").
    forest = minimum_spanning_tree(csr_matrix(-strength)).toarray()
    undirected = csr_matrix((forest != 0) | (forest.T != 0))
    order, predecessors = breadth_first_order(undirected, root, directed=False)
    return root, [(int(predecessors[child]), int(child)) for child in order[1:]]


def reached(n_views: int, root: int, tree: Sequence[tuple[int, int]]) -> list[bool]:
    """Per view: whether it is the root or a child in ``tree`` (the views an alignment places)."""
    aligned = [False] * n_views
    aligned[root] = True
    for _, child in tree:
        aligned[child] = True
    return aligned


def _chain(n_views: int, root: int, tree: list[tuple[int, int]], pairs: Sequence[PairCorrespondences],
           scene: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chain pair similarities along the tree: cam_to_world rotations ``[N, 3, 3]``, translations (normalised) and log scales."""
    relative = {}
    for pair in pairs:
        relative[(pair.a, pair.b)] = pair.b_to_a
        relative[(pair.b, pair.a)] = np.linalg.inv(pair.b_to_a)
    similarity = {root: np.eye(4)}
    for parent, child in tree:
        similarity[child] = similarity[parent] @ relative[(parent, child)]
    rotations, translations, log_scales = [], [], []
    for view in range(n_views):
        matrix = similarity.get(view, np.eye(4))
        scale = float(np.cbrt(abs(np.linalg.det(matrix[:3, :3])))) or 1.0
        u, _, vt = np.linalg.svd(matrix[:3, :3] / scale)
        rotations.append(u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt)
        translations.append(matrix[:3, 3] / scene)
        log_scales.append(np.log(scale / scene))
    return np.stack(rotations), np.stack(translations), np.asarray(log_scales)


def _correspondences(depths: Sequence[np.ndarray], pairs: Sequence[PairCorrespondences], used: Sequence[bool]) -> Correspondences:
    chunks: dict[str, list[np.ndarray]] = {key: [] for key in ("view_a", "view_b", "uv_a", "uv_b", "z_a", "z_b", "weight",
                                                                 "information_a", "information_b")}
    for pair in pairs:
        if not (used[pair.a] and used[pair.b]) or len(pair.weight) == 0:
            continue
        z_a, z_b = sample_bilinear(depths[pair.a], pair.uv_a), sample_bilinear(depths[pair.b], pair.uv_b)
        if pair.information_a is not None and not np.any(pair.information_a):
            # One-way rows (a's surface onto b's outline): b's end is weighed by nothing, and its target lies on b's
            # silhouette, where b's pointmap may have no depth: any finite depth serves.
            z_b = np.where(np.isfinite(z_b), z_b, median_depth(depths[pair.b]))
        keep = np.isfinite(z_a) & np.isfinite(z_b) & (np.asarray(pair.weight) > 0)
        if not keep.any():
            continue
        count = int(keep.sum())
        identity = np.broadcast_to(np.eye(2), (len(keep), 2, 2))
        chunks["view_a"].append(np.full(count, pair.a))
        chunks["view_b"].append(np.full(count, pair.b))
        for key, value in (("uv_a", pair.uv_a), ("uv_b", pair.uv_b), ("z_a", z_a), ("z_b", z_b), ("weight", pair.weight),
                           ("information_a", identity if pair.information_a is None else pair.information_a),
                           ("information_b", identity if pair.information_b is None else pair.information_b)):
            chunks[key].append(np.asarray(value, np.float64)[keep])
    shapes = {"uv_a": (0, 2), "uv_b": (0, 2), "information_a": (0, 2, 2), "information_b": (0, 2, 2)}
    arrays = {key: np.concatenate(value) if value else np.zeros(shapes.get(key, (0,))) for key, value in chunks.items()}
    arrays["view_a"], arrays["view_b"] = arrays["view_a"].astype(np.int64), arrays["view_b"].astype(np.int64)
    arrays["weight"] = arrays["weight"] / max(float(arrays["weight"].sum()), 1e-300)
    return Correspondences(**arrays)


def global_align(depths: Sequence[np.ndarray], focal_guess: float | Sequence[float],
                 pairs: Sequence[PairCorrespondences], config: GlobalAlignConfig = GlobalAlignConfig(),
                 root: int | None = None, previous: GlobalAlignment | None = None,
                 min_turns: np.ndarray | None = None, uncertainty: bool = True) -> GlobalAlignment:
    """Align views given own-frame pointmap depths ``depths[v] [H, W]`` (NaN = none) and pair correspondences.

    ``focal_guess``: the focal (pixels) the pointmaps were made with (one, or one per view).
    ``previous``: refine from this alignment (same views and depths) instead of the spanning tree.
    ``min_turns``: ``[N, N]`` radians, the least turn each view pair may have (NaN: none), kept by hinge rows.
    ``uncertainty``: also each pair's turn uncertainty from the solved curvature (Levenberg-Marquardt only).
    Views that no pair reaches keep an identity pose and are marked not aligned.
    """
    n_views = len(depths)
    guesses = np.broadcast_to(np.asarray(focal_guess, np.float64), (n_views,)).copy()
    if previous is not None:
        root, tree = previous.root, previous.tree
        aligned = list(previous.aligned)
    else:
        root, tree = spanning_tree(n_views, pairs, root)
        aligned = reached(n_views, root, tree)
    scene = median_depth(depths[root])
    grids = field_grids(depths, config)
    if previous is not None:
        initial = _state_of(previous)
    else:
        rotations, translations, log_scales = _chain(n_views, root, tree, pairs, scene)
        shared = np.full(n_views, np.exp(np.mean(np.log(guesses)))) if config.shared_focal else guesses
        initial = InitialState(rotations, translations, log_scales, np.zeros(n_views), np.log(shared),
                               [np.zeros(g.size) for g in grids])
    problem, data = alignment_problem(depths, guesses, pairs, config, grids, initial, aligned, root, min_turns)
    with single_threaded():  # a few thousand residuals: threads only add hand-offs
        curvature = None
        if not len(data.weight):
            history = []
        elif config.solver == "lm":
            steps = config.lm_iterations if sum(aligned) >= PIVOT_MIN_VIEWS else min(config.lm_iterations,
                                                                                   config.two_view_lm_iterations)
            history = levenberg_marquardt(problem, steps, config.lm_tolerance)
            curvature = turn_uncertainty_deg(problem, aligned) if uncertainty else None
        else:
            history = minimize(problem, config.iterations, config.learning_rate, config.polish_iterations,
                               config.polish_rounds)
    result = alignment_result(problem, depths, grids, data, root, tree, aligned, history)
    return replace(result, turn_uncertainty_deg=curvature)


def _state_of(alignment: GlobalAlignment) -> InitialState:
    """A solved alignment as the start of another solve."""
    return InitialState(np.stack([p[:3, :3] for p in alignment.cam_to_world]), np.stack([p[:3, 3] for p in alignment.cam_to_world]),
                        np.log(alignment.scales), np.log(alignment.relief_scale), np.log(alignment.focals),
                        [np.asarray(f, np.float64) for f in alignment.fields])


def turn_uncertainty_of(alignment: GlobalAlignment, depths: Sequence[np.ndarray], focal_guess: float | Sequence[float],
                        pairs: Sequence[PairCorrespondences], config: GlobalAlignConfig = GlobalAlignConfig(),
                        min_turns: np.ndarray | None = None) -> np.ndarray | None:
    """``alignment.turn_uncertainty_deg`` of a solved alignment, from its problem set up again at the solution: the
    arguments are those :func:`global_align` solved it with. A registration solves several times and reports only the
    last, so it asks for the curvature once, here (with ten views each one cost over a second). None without
    correspondences."""
    n_views = len(depths)
    guesses = np.broadcast_to(np.asarray(focal_guess, np.float64), (n_views,)).copy()
    problem, data = alignment_problem(depths, guesses, pairs, config, field_grids(depths, config), _state_of(alignment),
                                      alignment.aligned, alignment.root, min_turns)
    if not len(data.weight):
        return None
    with single_threaded():
        return turn_uncertainty_deg(problem, alignment.aligned)


def alignment_problem(depths: Sequence[np.ndarray], guesses: np.ndarray, pairs: Sequence[PairCorrespondences],
                      config: GlobalAlignConfig, grids: Sequence[FieldGrid], initial: InitialState, aligned: Sequence[bool],
                      root: int, min_turns: np.ndarray | None = None) -> tuple[AlignmentProblem, Correspondences]:
    """The problem of one capture: the aligned views' correspondences, the root view fixed."""
    data = _correspondences(depths, pairs, aligned)
    free = [aligned[v] and v != root for v in range(len(depths))]
    closed = sum(aligned) >= PIVOT_MIN_VIEWS  # three views or more: the bas-relief valley closed
    # The fields bend freely only where three of the views see the finger from distinct places (optical axes
    # MIN_PARALLAX_DEG apart): two views a degree apart hold no more relief than one, and beside a third, counted as
    # three, soft fields let the turns follow the relief (another group's renders at rolls 47 and 48 with a third:
    # 0.4 -> 4.4 degrees from stop 78 to 83). The pivot and the turn bound keep the view count (switched with the
    # fields, those triplets came out 8-27 degrees off).
    bending = distinct_viewpoints([np.asarray(r).T for r in initial.rotations],
                                  [v for v in range(len(depths)) if aligned[v]]) >= PIVOT_MIN_VIEWS
    problem = AlignmentProblem(depths, grids, data, initial, free, shared_focal=config.shared_focal,
                               optimize_focal=config.optimize_focal and len(data.weight) > 0, focal_guess=guesses,
                               robust_px=config.robust_px, alpha_prior=config.alpha_prior,
                               field_smoothness=config.field_smoothness if bending else config.two_view_field_smoothness,
                               field_prior=config.field_prior, focal_prior=config.focal_prior,
                               shared_relief=config.shared_relief, min_turns=min_turns,
                               turn_bound_weight=config.turn_bound_weight if closed else config.two_view_turn_bound_weight,
                               pivot=_pivot(initial, root) if config.pivot_poses and closed else None)
    return problem, data


def _pivot(initial: InitialState, root: int) -> np.ndarray:
    """A point of the finger: on the root camera's optical axis at its median depth (1 in normalised units)."""
    return np.asarray(initial.translations[root], np.float64) + np.asarray(initial.rotations[root], np.float64)[:, 2]


def field_grids(depths: Sequence[np.ndarray], config: GlobalAlignConfig) -> list[FieldGrid]:
    """Each view's depth-field knot grid over its pointmap's support."""
    return [FieldGrid.covering(np.isfinite(d), config.field_knots) if config.field_knots > 0 else FieldGrid(0.0, 0.0, 1.0, (0, 0))
            for d in depths]


def alignment_result(problem: AlignmentProblem, depths, grids, data: Correspondences, root, tree, aligned, history,
                     cameras: tuple | None = None) -> GlobalAlignment:
    """The :class:`GlobalAlignment` a solved problem describes (``cameras``: poses held elsewhere, as by a rig)."""
    with torch.no_grad():
        cameras = problem.cameras() if cameras is None else cameras
        rotations, translations = cameras[0].numpy(), cameras[1].numpy()
        if len(data.weight):
            x_a, x_b, e_ab, e_ba = problem.correspondence_terms(cameras)
            weights = np.concatenate([data.weight, data.weight])
            residual_px = weighted_median(np.sqrt(torch.cat([e_ab, e_ba]).numpy()), weights)
            residual_3d = weighted_median((x_a - x_b).norm(dim=1).numpy(), data.weight)
        else:
            residual_px = residual_3d = float("nan")
        poses, out_depths, fields = [], [], []
        for view, depth in enumerate(depths):
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = rotations[view], translations[view]
            poses.append(pose)
            start, stop = problem.field_offsets[view], problem.field_offsets[view + 1]
            coefficients = problem.field[start:stop].numpy()
            field = grids[view].dense(coefficients, depth.shape) if grids[view].size else 0.0
            median = float(problem.medians[view])
            dense = (float(problem.scales()[view]) * (median + float(torch.exp(problem.log_alphas()[view])) * (depth - median)
                                                      + float(problem.reliefs[view]) * field)).astype(np.float32)
            out_depths.append(dense)
            fields.append(coefficients.copy())
        return GlobalAlignment(poses, [float(f) for f in cameras[2]], out_depths,
                               [float(a) for a in torch.exp(problem.log_alphas())], [float(s) for s in problem.scales()],
                               float(residual_px), float(residual_3d), list(tree), list(aligned), root, fields, history)


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The weighted median of ``values`` (the plain median when all weights are 0)."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    if cumulative.size == 0:
        return float("nan")
    if cumulative[-1] <= 0:
        return float(np.median(values))
    return float(values[order][np.searchsorted(cumulative, 0.5 * cumulative[-1])])
