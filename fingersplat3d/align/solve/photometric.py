"""Dense photometric refinement: the surface from the ridges wherever two views see the same skin.

The global alignment (:mod:`~fingersplat3d.align.solve.global_opt`) is fitted to sparse verified
matches; between them the surface is the pointmap's, bent by a coarse field. This stage takes every
``stride``-th pixel of each aligned view's finger, lifts it with the view's current surface, carries
it into every other aligned view that sees it and compares the two ridge textures there (band-passed,
unit local RMS: :func:`~fingersplat3d.align.correspond.texture.ridge_texture`), the way dense
multi-view stereo and featuremetric refinement (pixel-perfect SfM) do. Unknowns: the alignment's own
(poses, focal, scales, relief, fields) plus a finer depth field per view (``fine_knots`` across the
finger), all refined jointly by L-BFGS.

Loss: ``weight * mean rho(T_v(q) - T_u(pi_u(X_v(q))))`` over the visible samples (``rho``: Cauchy,
scale ``robust``), plus the alignment's own loss (its matches and priors, so the turn stays pinned
where the photos say nothing) and the fine fields' bending penalty. Visibility (the point lands on
u's finger and u's surface is not in front of it) is decided at the start of each of ``rounds``
rounds, without gradient. The textures are compared where ridges are in phase: the stage starts from
an alignment already within half a ridge period (after the guided rounds) and only refines it.

Pure torch (float64) + numpy; no files.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch

from ...sampling import sample_bilinear_torch
from .alignment_problem import AlignmentProblem, InitialState, _lift, _project
from .depth_field import FieldGrid
from .settings import PhotometricConfig

__all__ = ["PhotometricConfig", "PhotometricTerm", "photometric_refine", "refine_alignment", "facing_weight"]


@dataclass(frozen=True, eq=False)
class _Samples:
    """One view's samples: pixels, pointmap depth, coarse and fine field bases, own texture."""

    view: int
    uv: torch.Tensor  # [S, 2]
    z: torch.Tensor  # [S]
    index: torch.Tensor  # [S, 16] into the problem's field
    weight: torch.Tensor  # [S, 16]
    fine_index: torch.Tensor  # [S, 16] into the fine field
    fine_weight: torch.Tensor  # [S, 16]
    texture: torch.Tensor  # [S]


class PhotometricTerm(torch.nn.Module):
    """The photometric loss of an :class:`AlignmentProblem` (see the module docstring)."""

    def __init__(self, problem: AlignmentProblem, depths: Sequence[np.ndarray], textures: Sequence[np.ndarray],
                 masks: Sequence[np.ndarray], aligned: Sequence[bool], stride: float, config: PhotometricConfig) -> None:
        super().__init__()
        self.problem, self.config = problem, config
        self.aligned = list(aligned)
        self.textures = [torch.as_tensor(np.asarray(t, np.float64)) for t in textures]
        self.masks = [np.asarray(m, bool) for m in masks]
        self.fine_grids = [FieldGrid.covering(np.isfinite(d) & m, config.fine_knots) if config.fine_knots > 0
                           else FieldGrid(0.0, 0.0, 1.0, (0, 0)) for d, m in zip(depths, self.masks)]
        self.fine_offsets = np.cumsum([0] + [g.size for g in self.fine_grids])
        self.fine = torch.nn.Parameter(torch.zeros(int(self.fine_offsets[-1]), dtype=torch.float64))
        step = max(1, int(round(stride)))
        self.samples = []
        for v, (depth, mask, texture) in enumerate(zip(depths, self.masks, textures)):
            if not aligned[v]:
                continue
            rows, cols = np.nonzero((np.isfinite(depth) & mask)[::step, ::step])
            rows, cols = rows * step, cols * step
            uv = np.stack([cols, rows], 1).astype(np.float64)
            coarse = problem.grids[v].basis(uv)
            fine = self.fine_grids[v].basis(uv)
            as_t = lambda a, kind=torch.float64: torch.as_tensor(np.ascontiguousarray(a), dtype=kind)
            self.samples.append(_Samples(
                v, as_t(uv), as_t(depth[rows, cols]), as_t(coarse.index + problem.field_offsets[v], torch.long),
                as_t(coarse.weight), as_t(fine.index + self.fine_offsets[v], torch.long), as_t(fine.weight),
                as_t(np.asarray(texture, np.float64)[rows, cols])))
        triples = [g.bending()[0] + self.fine_offsets[v] for v, g in enumerate(self.fine_grids) if g.size]
        self.bend = torch.as_tensor(np.concatenate(triples) if triples else np.zeros((0, 3), np.int64), dtype=torch.long)
        self.visible: dict[tuple[int, int], torch.Tensor] = {}
        self.weights: dict[tuple[int, int], torch.Tensor] = {}

    # -- geometry -----------------------------------------------------------------------------
    def sample_depth(self, s: _Samples, scales: torch.Tensor) -> torch.Tensor:
        p = self.problem
        depth = p.depth(torch.full_like(s.z, s.view, dtype=torch.long), s.z, s.index, s.weight, scales)
        if self.fine.numel():
            depth = depth + scales[s.view] * p.reliefs[s.view] * (self.fine[s.fine_index] * s.fine_weight).sum(-1)
        return depth

    def _carried(self, s: _Samples, u: int, cameras, scales) -> tuple[torch.Tensor, torch.Tensor]:
        """Sample pixels of view ``s.view`` lifted onto its surface and projected into view ``u``:
        ``(uv_u [S, 2], world points [S, 3])``."""
        rotations, translations, focals = cameras
        p, count = self.problem, len(s.z)
        points = _lift(rotations[s.view].expand(count, 3, 3), translations[s.view].expand(count, 3),
                       focals[s.view].expand(count), p.centres[s.view].expand(count, 2), s.uv, self.sample_depth(s, scales))
        uv = _project(rotations[u].expand(count, 3, 3), translations[u].expand(count, 3), focals[u].expand(count),
                      p.centres[u].expand(count, 2), points)
        return uv, points

    def _compared(self, min_count: int = 1):
        """For every sample set and other view that sees at least ``min_count`` of its samples: ``(samples, u,
        visible indices, u's texture where they land)``."""
        cameras, scales = self.problem.cameras(), self.problem.scales()
        for s in self.samples:
            for u in range(len(self.aligned)):
                keep = self.visible.get((s.view, u))
                if keep is None or keep.numel() < min_count:
                    continue
                uv, _ = self._carried(s, u, cameras, scales)
                yield s, u, keep, sample_bilinear_torch(self.textures[u], uv[keep])

    def update_visibility(self, dense_depths: Sequence[np.ndarray]) -> None:
        """Which samples each other view sees (on its finger, its own surface not nearer by more than 2 %), and
        how much each counts: by how squarely both views face the skin there (:func:`facing_weight`)."""
        from ...sampling import sample_nearest
        from ..transfer import surface_tolerance

        with torch.no_grad():
            cameras, scales = self.problem.cameras(), self.problem.scales()
            rotations, translations, focals = cameras
            on_finger = [np.where(mask, depth, np.nan) for mask, depth in zip(self.masks, dense_depths)]
            tolerances = [surface_tolerance(depth) for depth in dense_depths]
            for s in self.samples:
                v = s.view
                normal, points = _surface_normals(dense_depths[v], s.uv.numpy(), float(focals[v]), self.problem.centres[v].numpy())
                world_normal = normal @ rotations[v].numpy().T
                world_points = points @ rotations[v].numpy().T + translations[v].numpy()
                facing_v = np.abs(np.sum(normal * points, 1)) / np.maximum(np.linalg.norm(points, axis=1), 1e-12)
                for u in range(len(self.aligned)):
                    if u == v or not self.aligned[u]:
                        continue
                    uv, carried = self._carried(s, u, cameras, scales)
                    z = ((carried - translations[u]) @ rotations[u])[:, 2].numpy()  # depth in u's camera
                    seen = sample_nearest(on_finger[u], uv.numpy())
                    to_u = translations[u].numpy() - world_points
                    facing_u = np.abs(np.sum(world_normal * to_u, 1)) / np.maximum(np.linalg.norm(to_u, axis=1), 1e-12)
                    weight = facing_weight(np.minimum(facing_v, facing_u))
                    ok = np.isfinite(seen) & (np.abs(seen - z) <= tolerances[u]) & (weight > 0)
                    index = np.flatnonzero(ok)
                    self.visible[(v, u)] = torch.as_tensor(index)
                    self.weights[(v, u)] = torch.as_tensor(weight[index])

    def residuals(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Texture differences of every visible sample, for every other view that sees it, and their weights."""
        out, weights = [], []
        for s, u, keep, theirs in self._compared():
            out.append(theirs - s.texture[keep])
            weights.append(self.weights[(s.view, u)])
        if not out:
            return torch.zeros(0, dtype=torch.float64), torch.zeros(0, dtype=torch.float64)
        return torch.cat(out), torch.cat(weights)

    def forward(self) -> torch.Tensor:
        r, weight = self.residuals()
        loss = self.problem()
        if r.numel():
            rho = torch.log1p((r / self.config.robust) ** 2)
            loss = loss + self.config.weight * (weight * rho).sum() / weight.sum().clamp_min(1e-12)
        if self.bend.numel():
            bend = self.fine[self.bend[:, 0]] - 2 * self.fine[self.bend[:, 1]] + self.fine[self.bend[:, 2]]
            loss = loss + self.config.fine_smoothness * (bend ** 2).sum()
        return loss + self.config.fine_prior * (self.fine ** 2).sum()

    def fine_dense(self, view: int, shape: tuple[int, int]) -> np.ndarray:
        """The fine field of ``view`` on every pixel, in depth units (the alignment's scale and relief)."""
        grid = self.fine_grids[view]
        if not grid.size:
            return np.zeros(shape)
        coefficients = self.fine.detach()[self.fine_offsets[view]:self.fine_offsets[view + 1]].numpy()
        with torch.no_grad():
            scale = float(self.problem.scales()[view]) * float(self.problem.reliefs[view])
        return scale * grid.dense(coefficients, shape)

    def mean_agreement(self) -> float:
        """Correlation of the carried and own textures over every visible sample (1: ridges in phase)."""
        with torch.no_grad():
            pairs = [(s.texture[keep], theirs) for s, _, keep, theirs in self._compared(min_count=2)]
            if not pairs:
                return float("nan")
            mine, theirs = (torch.cat(side).numpy() for side in zip(*pairs))
            return float(np.corrcoef(mine, theirs)[0, 1])


FACING_LOW, FACING_HIGH = 0.25, 0.6
"""A sample counts fully where both views face the skin within ~53 degrees (cosine 0.6), not at all beyond ~75
degrees (0.25): at grazing angles the ridges are foreshortened into another frequency and the depth is steepest."""


def facing_weight(cosine: np.ndarray) -> np.ndarray:
    """0 -> 1 ramp of the smaller facing cosine between :data:`FACING_LOW` and :data:`FACING_HIGH`."""
    cosine = np.clip(np.nan_to_num(cosine, nan=0.0), -1.0, 1.0)  # a cosine is in [-1, 1]: no overflow past it
    return np.clip((cosine - FACING_LOW) / (FACING_HIGH - FACING_LOW), 0.0, 1.0)


def _surface_normals(depth: np.ndarray, uv: np.ndarray, focal: float, centre: np.ndarray, step: float = 2.0):
    """Unit normals and points ``[S, 3]`` (camera frame) of a depth map at ``uv`` from its neighbours ``step``
    pixels right and down (left or up where those have no depth); NaN where none can be made."""
    from ...sampling import sample_nearest

    def lift(at):
        z = sample_nearest(depth, at)
        return np.concatenate([(at - centre) / focal, np.ones((len(at), 1))], 1) * z[:, None]

    here = lift(uv)
    along = []
    for offset in ((step, 0.0), (0.0, step)):
        ahead, behind = lift(uv + offset), lift(uv - np.asarray(offset))
        along.append(np.where(np.isfinite(ahead).all(1, keepdims=True), ahead - here, here - behind))
    normal = np.cross(along[0], along[1])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    return normal, here


def photometric_refine(problem: AlignmentProblem, depths: Sequence[np.ndarray], textures: Sequence[np.ndarray],
                       masks: Sequence[np.ndarray], aligned: Sequence[bool], period: float, config: PhotometricConfig,
                       dense_depths) -> tuple[PhotometricTerm, dict]:
    """Refine ``problem`` in place on the photos (module docstring); returns the term (for its fine fields)
    and a record: texture agreement before and after, samples, seconds.

    ``depths``: the pointmaps' own depths; ``dense_depths()``: the current surface of every view
    (called for each round's visibility).
    """
    import time

    start = time.perf_counter()
    term = PhotometricTerm(problem, depths, textures, masks, aligned, config.stride_periods * period, config)
    record = {"samples": int(sum(len(s.z) for s in term.samples))}
    # Two blocks, each by its own L-BFGS: a turn of 1 radian moves pixels a thousand times further than a
    # field coefficient, and one curvature history across both leaves the surface where it was.
    surface = [p for p in (problem.field, term.fine) if p.numel()]
    poses = [p for p in (problem.omega, problem.translation, problem.log_scale, problem.log_alpha, problem.log_focal)
             if p.requires_grad and p.numel()] if config.poses else []
    for round_ in range(config.rounds):
        term.update_visibility(dense_depths(term))
        if round_ == 0:
            record["agreement_before"] = round(term.mean_agreement(), 3)
        for block, iterations in ((surface, config.iterations), (poses, config.pose_iterations)):
            if block and iterations > 0:
                _lbfgs(term, block, iterations)
    term.update_visibility(dense_depths(term))
    record["agreement_after"] = round(term.mean_agreement(), 3)
    record["seconds"] = round(time.perf_counter() - start, 2)
    return term, record


def refine_alignment(alignment, depths: Sequence[np.ndarray], focal_guess, pairs, align_config, textures, masks,
                     period: float, config: PhotometricConfig, min_turns: np.ndarray | None = None):
    """:func:`photometric_refine` from a :class:`~fingersplat3d.align.solve.global_opt.GlobalAlignment`:
    ``(the refined alignment, its record)``. Its depth maps carry the fine fields; its ``fields`` stay
    the coarse ones (what a later refinement starts from)."""
    from dataclasses import replace

    from .global_opt import alignment_problem, alignment_result, field_grids

    n_views = len(depths)
    guesses = np.broadcast_to(np.asarray(focal_guess, np.float64), (n_views,)).copy()
    grids = field_grids(depths, align_config)
    initial = InitialState(np.stack([p[:3, :3] for p in alignment.cam_to_world]),
                           np.stack([p[:3, 3] for p in alignment.cam_to_world]), np.log(alignment.scales),
                           np.log(alignment.relief_scale), np.log(alignment.focals),
                           [np.asarray(f, np.float64) for f in alignment.fields])
    problem, data = alignment_problem(depths, guesses, pairs, align_config, grids, initial, alignment.aligned,
                                      alignment.root, min_turns)

    def result(term: PhotometricTerm | None):
        solved = alignment_result(problem, depths, grids, data, alignment.root, alignment.tree, alignment.aligned,
                                  alignment.loss_history)
        if term is None:
            return solved
        return replace(solved, depths=[(d + term.fine_dense(v, d.shape)).astype(np.float32)
                                       for v, d in enumerate(solved.depths)],
                       turn_uncertainty_deg=alignment.turn_uncertainty_deg)

    term, record = photometric_refine(problem, depths, textures, masks, alignment.aligned, period, config,
                                      lambda t: result(t).depths)
    return result(term), record


def _lbfgs(term: PhotometricTerm, parameters: list[torch.nn.Parameter], iterations: int) -> None:
    """``iterations`` of L-BFGS on ``parameters`` alone (the others held)."""
    everything = list(term.parameters())  # the problem's too: it is a submodule of the term
    held = {id(p): p.requires_grad for p in everything}
    chosen = {id(p) for p in parameters}
    for p in everything:
        p.requires_grad_(id(p) in chosen and held[id(p)])
    optimizer = torch.optim.LBFGS(parameters, lr=1.0, max_iter=iterations, history_size=20, line_search_fn="strong_wolfe",
                                  tolerance_grad=1e-10, tolerance_change=1e-12)

    def closure():
        optimizer.zero_grad()
        loss = term()
        loss.backward()
        return loss

    try:
        optimizer.step(closure)
    finally:
        for p in everything:
            p.requires_grad_(held[id(p)])
