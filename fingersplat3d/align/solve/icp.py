"""ICP refinement of aligned views with Open3D: pairwise for two views, a multiway pose graph for more.

A finger is close to a cylinder, so geometry alone barely constrains sliding along its axis or
turning about it: plain ICP can drift there. Each view is therefore registered with Open3D's
*colored* ICP (geometry + the ridge texture) when the clouds carry colour, else point-to-plane, and
an update is kept only when it is small (the global alignment is already close) and improves the
fit; otherwise the view keeps its pose and the report says why.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["ICPConfig", "ICPResult", "refine_poses"]


@dataclass(frozen=True)
class ICPConfig:
    """Settings of the ICP refinement (distances relative to the finger size)."""

    max_distance: float = 0.02
    """Correspondence distance, as a fraction of the fused cloud's extent."""
    voxel: float = 0.004
    """Downsampling voxel, as a fraction of the extent."""
    max_rotation_deg: float = 3.0
    """Largest rotation an ICP update may apply; larger ones are rejected as drift."""
    max_translation: float = 0.03
    """Largest translation an update may apply, as a fraction of the extent."""
    iterations: int = 50
    """ICP iterations per registration."""
    colored: bool = True
    """Use colored ICP (geometry + texture) when the clouds have colour."""


@dataclass(frozen=True, eq=False)
class ICPResult:
    corrections: list[np.ndarray]  # per view [4, 4]: new cam_to_world = correction @ old cam_to_world
    accepted: list[bool]
    fitness: list[float]
    rmse: list[float]
    notes: list[str]


def _rotation_deg(matrix: np.ndarray) -> float:
    cosine = (np.trace(matrix[:3, :3]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def refine_poses(clouds: Sequence, config: ICPConfig = ICPConfig(), fixed: int = 0) -> ICPResult:
    """Register each view's world-frame cloud to the union of the others (view ``fixed`` stays put).

    Returns a rigid correction per view. Two views: one pairwise registration. More: every view
    against the union of the rest, combined through an Open3D pose graph (multiway registration).
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    n = len(clouds)
    merged = o3d.geometry.PointCloud()
    for cloud in clouds:
        merged += cloud
    extent = float(np.linalg.norm(merged.get_max_bound() - merged.get_min_bound())) if len(merged.points) else 1.0
    voxel, distance = config.voxel * extent, config.max_distance * extent
    small = []
    for cloud in clouds:
        down = cloud.voxel_down_sample(voxel) if len(cloud.points) else cloud
        if len(down.points) >= 3 and not down.has_normals():
            down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * voxel, max_nn=30))
        small.append(down)
    corrections = [np.eye(4) for _ in range(n)]
    accepted, fitness, rmse, notes = [True] * n, [1.0] * n, [0.0] * n, [""] * n
    graph = reg.PoseGraph()
    for _ in range(n):
        graph.nodes.append(reg.PoseGraphNode(np.eye(4)))
    criteria = reg.ICPConvergenceCriteria(max_iteration=config.iterations)
    for view in range(n):
        if view == fixed:
            notes[view] = "reference"
            continue
        target = o3d.geometry.PointCloud()
        for other in range(n):
            if other != view:
                target += small[other]
        source = small[view]
        if len(source.points) < 10 or len(target.points) < 10:
            accepted[view], notes[view] = False, "too few points"
            continue
        use_color = config.colored and source.has_colors() and target.has_colors()
        try:
            if use_color:
                result = reg.registration_colored_icp(source, target, distance, np.eye(4),
                                                      reg.TransformationEstimationForColoredICP(), criteria)
            else:
                result = reg.registration_icp(source, target, distance, np.eye(4),
                                              reg.TransformationEstimationPointToPlane(), criteria)
        except RuntimeError as error:  # e.g. no correspondences within the distance
            accepted[view], notes[view] = False, f"ICP failed: {error}"
            continue
        before = reg.evaluate_registration(source, target, distance, np.eye(4))
        step = result.transformation
        rotation, shift = _rotation_deg(step), float(np.linalg.norm(step[:3, 3]))
        fitness[view], rmse[view] = float(result.fitness), float(result.inlier_rmse)
        if rotation > config.max_rotation_deg or shift > config.max_translation * extent:
            accepted[view], notes[view] = False, f"rejected as drift ({rotation:.2f} deg, {shift / extent:.3f} of extent)"
            continue
        if result.fitness < before.fitness * 0.98 or (result.fitness <= before.fitness and result.inlier_rmse >= before.inlier_rmse):
            accepted[view], notes[view] = False, "no improvement"
            continue
        information = reg.get_information_matrix_from_point_clouds(source, target, distance, step)
        graph.edges.append(reg.PoseGraphEdge(view, fixed, step, information, uncertain=False))
        notes[view] = f"{'colored' if use_color else 'point-to-plane'} ICP: {rotation:.3f} deg, fitness {result.fitness:.3f}"
    if n > 2 and len(graph.edges) > 1:
        option = reg.GlobalOptimizationOption(max_correspondence_distance=distance, edge_prune_threshold=0.25,
                                              reference_node=fixed)
        reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                                reg.GlobalOptimizationConvergenceCriteria(), option)
        for view in range(n):
            corrections[view] = np.asarray(graph.nodes[view].pose) if accepted[view] else np.eye(4)
    else:
        for edge in graph.edges:
            corrections[edge.source_node_id] = np.asarray(edge.transformation)
    return ICPResult(corrections, accepted, fitness, rmse, notes)
