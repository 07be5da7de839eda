"""The global-alignment problem as a torch module: its parameters, and a call that returns its loss.

Unknowns (float64), in *normalised units* where the root view's median pointmap depth is 1:

* a rigid ``cam_to_world`` per view: a rotation-vector update on the initial rotation and a
  translation; the root view is fixed (the gauge). With a ``pivot`` (a point near the finger; the default of
  :func:`~fingersplat3d.align.solve.global_opt.global_align`), the translation unknown is where the pivot lies in
  the camera's frame, ``q = R^T (pivot - centre)``, rather than the camera's centre: turning a camera about the
  finger is then a straight line in the unknowns, where with the centre it is an arc (the centre swings round the
  finger). The bas-relief valley (turn, relief and focal trading) runs along such turns; on an arc each
  Gauss-Newton step only follows the tangent, and the fit had stopped partway along it after its 15 steps
  (another group's crops at rolls 45 degrees apart: 4-8 degrees off, and well within 1 with the fit run to the end);
* one shared focal length (or one per view), principal point at each image's centre;
* per view a depth surface on top of the backend's own pointmap depth ``z_v``:
  ``depth_v(p) = s_v (m_v + alpha_v (z_v(p) - m_v) + r_v F_v(p))`` where ``m_v`` is the median
  pointmap depth, ``alpha_v`` scales the relief (a wrong cross-section is too flat or too deep;
  one ``alpha`` for all views when the relief is shared: one finger, one cross-section),
  ``r_v`` is the pointmap's relief (so the field is O(1)) and ``F_v`` a cubic B-spline field
  (:mod:`fingersplat3d.align.depth_field`); ``s_root = 1`` fixes the overall scale.

Loss, over the correspondences ``(p in a, q in b)`` of every pair, each with its information
matrices (see :mod:`fingersplat3d.align.guided`; identity when a matcher gives none): the
symmetric reprojection error, a's point through a's depth into b against ``q`` and b's point
through b's depth into a against ``p``, each ``r^T I r`` in Cauchy-robust form; plus a bending
penalty on each field, a pull of ``log alpha`` toward 0 and of the focal toward its guess.
Correspondence weights are normalised to sum to 1, so the priors' strengths do not depend on
how many matches there are. Torch, with scipy.sparse for the Levenberg-Marquardt system.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sparse
import torch

from ...rotations import axis_angle_to_matrix, left_jacobian, rotation_angle, skew
from .depth_field import FieldGrid

__all__ = ["Correspondences", "InitialState", "AlignmentProblem", "median_depth"]


def median_depth(depth: np.ndarray) -> float:
    """The median of a depth map's finite values (the problem's ``m_v``), 1 when it has none."""
    finite = np.asarray(depth)[np.isfinite(depth)]
    return float(np.median(finite)) if finite.size else 1.0


@dataclass(frozen=True, eq=False)
class Correspondences:
    """All pairs' correspondences, flattened, with the pointmap depth at both ends."""

    view_a: np.ndarray  # [M] int
    view_b: np.ndarray  # [M] int
    uv_a: np.ndarray  # [M, 2]
    uv_b: np.ndarray  # [M, 2]
    z_a: np.ndarray  # [M] pointmap depth of view a at uv_a
    z_b: np.ndarray  # [M]
    weight: np.ndarray  # [M] >= 0, sums to 1
    information_a: np.ndarray  # [M, 2, 2] in a's pixels
    information_b: np.ndarray  # [M, 2, 2] in b's pixels


@dataclass(frozen=True, eq=False)
class InitialState:
    """Where the optimisation starts (normalised units)."""

    rotations: np.ndarray  # [N, 3, 3] cam_to_world rotations
    translations: np.ndarray  # [N, 3]
    log_scales: np.ndarray  # [N]
    log_alphas: np.ndarray  # [N]
    log_focals: np.ndarray  # [N] (equal when shared)
    fields: list[np.ndarray]  # per view [grid size]


class AlignmentProblem(torch.nn.Module):
    """See the module docstring. ``free[v]`` is False for the root and for views no pair reaches."""

    def __init__(self, depths: Sequence[np.ndarray], grids: Sequence[FieldGrid], data: Correspondences,
                 initial: InitialState, free: Sequence[bool], *, shared_focal: bool, optimize_focal: bool,
                 focal_guess: np.ndarray, robust_px: float, alpha_prior: float, field_smoothness: float,
                 field_prior: float, focal_prior: float, shared_relief: bool = False,
                 min_turns: np.ndarray | None = None, turn_bound_weight: float = 0.0,
                 pivot: np.ndarray | None = None) -> None:
        super().__init__()
        dtype = torch.float64
        n_views = len(depths)
        finite = [d[np.isfinite(d)] for d in depths]
        medians = [median_depth(d) for d in depths]
        reliefs = [max(float(np.percentile(np.abs(f - m), 90)) if f.size else 0.0, 1e-6 * abs(m) + 1e-12)
                   for f, m in zip(finite, medians)]
        self.grids = list(grids)
        offsets = np.cumsum([0] + [g.size for g in self.grids])
        self.field_offsets = offsets
        self.shared_focal = shared_focal
        self.robust_px = robust_px
        self.alpha_prior, self.field_smoothness = alpha_prior, field_smoothness
        self.field_prior, self.focal_prior = field_prior, focal_prior
        centres = [[(d.shape[1] - 1) / 2.0, (d.shape[0] - 1) / 2.0] for d in depths]

        def buffer(name, value, kind=dtype):
            self.register_buffer(name, torch.as_tensor(np.asarray(value), dtype=kind))

        buffer("medians", medians)
        buffer("reliefs", reliefs)
        buffer("centres", centres)
        buffer("free", np.asarray(free, np.float64))
        buffer("base_rotation", initial.rotations)
        buffer("base_translation", initial.translations)
        buffer("base_log_scale", initial.log_scales)
        buffer("log_focal_guess", np.log(np.broadcast_to(np.asarray(focal_guess, np.float64), (n_views,))))
        for end in ("a", "b"):
            view = getattr(data, f"view_{end}")
            index, weight = np.zeros((len(view), 16), np.int64), np.zeros((len(view), 16))
            for v in np.unique(view):
                rows = view == v
                basis = self.grids[v].basis(getattr(data, f"uv_{end}")[rows])
                index[rows], weight[rows] = basis.index + offsets[v], basis.weight
            buffer(f"view_{end}", view, torch.long)
            buffer(f"uv_{end}", getattr(data, f"uv_{end}"))
            buffer(f"z_{end}", getattr(data, f"z_{end}"))
            buffer(f"info_{end}", getattr(data, f"information_{end}"))
            buffer(f"white_{end}", _whitening(getattr(data, f"information_{end}")))
            buffer(f"basis_index_{end}", index, torch.long)
            buffer(f"basis_weight_{end}", weight)
        buffer("weight", data.weight)
        triples, coefficients = zip(*[g.bending() for g in self.grids]) if self.grids else ((), ())
        bend = np.concatenate([t + offsets[v] for v, t in enumerate(triples)]) if triples else np.zeros((0, 3), np.int64)
        buffer("bend_index", bend, torch.long)
        self.omega = torch.nn.Parameter(torch.zeros((n_views, 3), dtype=dtype))
        self.pivoted = pivot is not None
        buffer("pivot", np.zeros(3) if pivot is None else np.asarray(pivot, np.float64).reshape(3))
        translations = np.asarray(initial.translations, np.float64)
        if self.pivoted:  # the pivot in each camera's frame: q = R^T (pivot - centre)
            translations = np.einsum("nji,nj->ni", np.asarray(initial.rotations, np.float64), self.pivot.numpy() - translations)
        self.translation = torch.nn.Parameter(torch.as_tensor(translations, dtype=dtype).clone())
        self.log_scale = torch.nn.Parameter(torch.as_tensor(initial.log_scales, dtype=dtype).clone())
        alphas = np.asarray(initial.log_alphas, np.float64)
        self.log_alpha = torch.nn.Parameter(torch.as_tensor([alphas.mean()] if shared_relief else alphas, dtype=dtype).clone())
        focal = np.asarray(initial.log_focals, np.float64)
        self.log_focal = torch.nn.Parameter(torch.as_tensor([focal.mean()] if shared_focal else focal, dtype=dtype).clone(),
                                            requires_grad=optimize_focal)
        self.field = torch.nn.Parameter(torch.as_tensor(np.concatenate(initial.fields) if initial.fields else np.zeros(0), dtype=dtype).clone())
        # Least turns between views (radians, from their silhouettes: align/width_check.py), kept as hinge rows.
        bounds = np.full((n_views, n_views), np.nan) if min_turns is None else np.asarray(min_turns, np.float64)
        pairs = [(a, b) for a in range(n_views) for b in range(a + 1, n_views) if np.isfinite(bounds[a, b]) and bounds[a, b] > 0]
        buffer("bound_pairs", np.asarray(pairs, np.int64).reshape(-1, 2), torch.long)
        buffer("bound_turns", np.asarray([bounds[a, b] for a, b in pairs], np.float64))
        self.turn_bound_weight = float(turn_bound_weight) if pairs else 0.0

    # -- the current unknowns -------------------------------------------------------------------
    def rotations(self) -> torch.Tensor:
        """``[N, 3, 3]`` cam_to_world rotations (the root and unreached views keep their initial rotation)."""
        return axis_angle_to_matrix(self.omega * self.free[:, None]) @ self.base_rotation

    def translations(self) -> torch.Tensor:
        """``[N, 3]`` camera centres (the root and unreached views keep their initial ones)."""
        free = self.free[:, None]
        moving = self.pivot - torch.einsum("nij,nj->ni", self.rotations(), self.translation) if self.pivoted else self.translation
        return moving * free + self.base_translation * (1 - free)

    def scales(self) -> torch.Tensor:
        return torch.exp(self.log_scale * self.free + self.base_log_scale * (1 - self.free))

    def log_alphas(self) -> torch.Tensor:
        """``[N]`` log relief scales (one shared value, expanded, when the relief is shared)."""
        return self.log_alpha.expand(self.medians.shape[0]) if self.log_alpha.shape[0] == 1 else self.log_alpha

    def focals(self) -> torch.Tensor:
        count = self.medians.shape[0]
        return torch.exp(self.log_focal.expand(count) if self.shared_focal else self.log_focal)

    def depth(self, view: torch.Tensor, z: torch.Tensor, index: torch.Tensor, weight: torch.Tensor,
              scales: torch.Tensor | None = None) -> torch.Tensor:
        """Depth of view ``view``'s surface at pointmap depth ``z`` with field basis ``(index, weight)``."""
        scales = self.scales() if scales is None else scales
        field = (self.field[index] * weight).sum(-1) if self.field.numel() else torch.zeros_like(z)
        return _surface_depth(scales[view], self.log_alphas()[view], self.medians[view], self.reliefs[view], z, field)

    def _world_points(self, cameras: tuple, view: torch.Tensor, uv: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
        rotations, translations, focals = cameras
        return _lift(rotations[view], translations[view], focals[view], self.centres[view], uv, depth)

    def _project(self, cameras: tuple, view: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
        rotations, translations, focals = cameras
        return _project(rotations[view], translations[view], focals[view], self.centres[view], points)

    # -- the loss -------------------------------------------------------------------------------
    def cameras(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(rotations [N, 3, 3], translations [N, 3], focals [N])``: the cameras as this problem holds them."""
        return self.rotations(), self.translations(), self.focals()

    def correspondence_terms(self, cameras: tuple | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """World points of both ends ``[M, 3]`` and the information-weighted squared errors ``[M]`` a->b and b->a.

        ``cameras``: ``(rotations, translations, focals)`` from elsewhere (a rig shared by several
        captures, :mod:`~fingersplat3d.align.rig`) instead of this problem's own poses.
        """
        cameras = self.cameras() if cameras is None else cameras  # once per evaluation
        scales = self.scales()
        depth_a = self.depth(self.view_a, self.z_a, self.basis_index_a, self.basis_weight_a, scales)
        depth_b = self.depth(self.view_b, self.z_b, self.basis_index_b, self.basis_weight_b, scales)
        x_a = self._world_points(cameras, self.view_a, self.uv_a, depth_a)
        x_b = self._world_points(cameras, self.view_b, self.uv_b, depth_b)
        r_ab = self._project(cameras, self.view_b, x_a) - self.uv_b
        r_ba = self._project(cameras, self.view_a, x_b) - self.uv_a
        e_ab = torch.einsum("ni,nij,nj->n", r_ab, self.info_b, r_ab)
        e_ba = torch.einsum("ni,nij,nj->n", r_ba, self.info_a, r_ba)
        return x_a, x_b, e_ab, e_ba

    # -- per correspondence, for Levenberg-Marquardt (:mod:`fingersplat3d.align.solve.levenberg`) ---------------
    def row_unknowns(self) -> dict[str, torch.Tensor]:
        """The values each correspondence reads, per end: ``[M, k]`` tensors (``f_*``: its field value)."""
        with torch.no_grad():
            omega, translations = self.omega * self.free[:, None], self.translations()
            log_scales, log_alphas, log_focals = torch.log(self.scales()), self.log_alphas(), torch.log(self.focals())
            values = {}
            for end in ("a", "b"):
                view = getattr(self, f"view_{end}")
                field = ((self.field[getattr(self, f"basis_index_{end}")] * getattr(self, f"basis_weight_{end}")).sum(-1)
                         if self.field.numel() else torch.zeros_like(getattr(self, f"z_{end}")))
                values.update({f"omega_{end}": omega[view], f"t_{end}": translations[view],
                               f"ls_{end}": log_scales[view][:, None], f"la_{end}": log_alphas[view][:, None],
                               f"lf_{end}": log_focals[view][:, None], f"f_{end}": field[:, None]})
            return values

    def row_residuals(self, omega_a, omega_b, t_a, t_b, ls_a, ls_b, la_a, la_b, lf_a, lf_b, f_a, f_b) -> torch.Tensor:
        """``[M, 4]``: the whitened reprojection errors a->b and b->a (``e = |.|^2``) from per-row values."""
        ends = {}
        for end, omega, t, ls, la, lf, f in (("a", omega_a, t_a, ls_a, la_a, lf_a, f_a), ("b", omega_b, t_b, ls_b, la_b, lf_b, f_b)):
            view = getattr(self, f"view_{end}")
            rotation = axis_angle_to_matrix(omega) @ self.base_rotation[view]
            depth = _surface_depth(torch.exp(ls[:, 0]), la[:, 0], self.medians[view], self.reliefs[view],
                                   getattr(self, f"z_{end}"), f[:, 0])
            ends[end] = (rotation, t, torch.exp(lf[:, 0]), self.centres[view], depth)
        x_a = _lift(*ends["a"][:4], self.uv_a, ends["a"][4])
        x_b = _lift(*ends["b"][:4], self.uv_b, ends["b"][4])
        r_ab = _project(*ends["b"][:4], x_a) - self.uv_b
        r_ba = _project(*ends["a"][:4], x_b) - self.uv_a
        return torch.cat([torch.einsum("nij,nj->ni", self.white_b, r_ab), torch.einsum("nij,nj->ni", self.white_a, r_ba)], 1)

    def _layout(self) -> dict[str, int]:
        n = self.medians.shape[0]
        alphas, focals = self.log_alpha.numel(), self.log_focal.numel()
        return {"omega": 0, "translation": 3 * n, "log_scale": 6 * n, "log_alpha": 7 * n, "log_focal": 7 * n + alphas,
                "field": 7 * n + alphas + focals}

    def row_columns(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """For each of :meth:`row_unknowns`' values, the columns of :meth:`unknowns` it is made of
        (``[M, k, C]``, -1 where fixed) and their weights."""
        at, free = self._layout(), self.free.numpy() > 0
        shared_alpha, shared_focal = self.log_alpha.numel() == 1, self.log_focal.numel() == 1
        columns = {}
        for end in ("a", "b"):
            view = getattr(self, f"view_{end}").numpy()
            count, ones = len(view), np.ones((len(view), 1, 1))
            fixed = np.where(free[view], 0, -1)[:, None]

            def per_view(start, width):
                cols = start + width * view[:, None] + np.arange(width)[None, :]
                return np.where(fixed < 0, -1, cols)[:, :, None], np.ones((count, width, 1))

            columns[f"omega_{end}"] = per_view(at["omega"], 3)
            columns[f"t_{end}"] = per_view(at["translation"], 3)  # the centre's; see pivot_chain when pivoted
            columns[f"ls_{end}"] = per_view(at["log_scale"], 1)
            columns[f"la_{end}"] = ((at["log_alpha"] + (0 * view if shared_alpha else view))[:, None, None] * ones).astype(np.int64), ones
            focal_cols = (at["log_focal"] + (0 * view if shared_focal else view))[:, None, None] * ones
            columns[f"lf_{end}"] = (focal_cols if self.log_focal.requires_grad else -ones).astype(np.int64), ones
            if self.field.numel():
                columns[f"f_{end}"] = ((at["field"] + getattr(self, f"basis_index_{end}").numpy())[:, None, :],
                                       getattr(self, f"basis_weight_{end}").numpy()[:, None, :])
            else:
                columns[f"f_{end}"] = -ones.astype(np.int64), ones
        return columns

    def pivot_chain(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        """How each view's camera centre ``c = pivot - R q`` (``R = Exp(omega) R0``) moves with its unknowns when
        pivoted: ``dc = [R q]_x J_l(omega) d omega - R dq``, as ``(d c / d omega, d c / d q)`` ``[N, 3, 3]`` each;
        None when the translation unknown is the centre itself. The Levenberg-Marquardt system applies it to each
        row's derivative by its centre (:func:`~fingersplat3d.align.solve.levenberg._system`)."""
        if not self.pivoted:
            return None
        with torch.no_grad():
            omega = self.omega * self.free[:, None]
            rotations = axis_angle_to_matrix(omega) @ self.base_rotation
            turned = torch.einsum("nij,nj->ni", rotations, self.translation)
            return skew(turned) @ left_jacobian(omega), -rotations

    def unknowns(self) -> torch.Tensor:
        """Every unknown, flat: omega, translation, log scale, log relief, log focal, field coefficients."""
        return torch.cat([p.detach().reshape(-1) for p in (self.omega, self.translation, self.log_scale, self.log_alpha,
                                                           self.log_focal, self.field)]).clone()

    def set_unknowns(self, values: torch.Tensor) -> None:
        with torch.no_grad():
            start = 0
            for p in (self.omega, self.translation, self.log_scale, self.log_alpha, self.log_focal, self.field):
                p.copy_(values[start:start + p.numel()].reshape(p.shape))
                start += p.numel()

    def prior_system(self) -> tuple[np.ndarray, sparse.csr_matrix]:
        """The priors as residual rows (their squares sum to the priors' part of the loss) and their Jacobian."""

        at, size = self._layout(), self.unknowns().numel()
        residuals, rows, cols, vals = [], [], [], []

        def add(values: np.ndarray, entries: list[tuple[np.ndarray, np.ndarray]]):
            first = sum(len(r) for r in residuals)
            residuals.append(values)
            for column, weight in entries:
                rows.append(first + np.arange(len(values)))
                cols.append(column)
                vals.append(np.broadcast_to(weight, len(values)).astype(np.float64))

        field = self.field.detach().numpy()
        if self.bend_index.numel():
            bend, root = self.bend_index.numpy(), np.sqrt(self.field_smoothness)
            add(root * (field[bend[:, 0]] - 2 * field[bend[:, 1]] + field[bend[:, 2]]),
                [(at["field"] + bend[:, 0], root), (at["field"] + bend[:, 1], -2 * root), (at["field"] + bend[:, 2], root)])
        if field.size:
            add(np.sqrt(self.field_prior) * field, [(at["field"] + np.arange(field.size), np.sqrt(self.field_prior))])
        alphas = self.log_alpha.detach().numpy()
        repeat = self.medians.shape[0] if alphas.size == 1 else 1  # a shared relief is counted once per view
        add(np.sqrt(self.alpha_prior * repeat) * alphas, [(at["log_alpha"] + np.arange(alphas.size), np.sqrt(self.alpha_prior * repeat))])
        if self.log_focal.requires_grad:
            guess = (self.log_focal_guess.mean() if self.shared_focal else self.log_focal_guess).numpy()
            focal = self.log_focal.detach().numpy()
            add(np.sqrt(self.focal_prior) * (focal - guess), [(at["log_focal"] + np.arange(focal.size), np.sqrt(self.focal_prior))])
        if self.turn_bound_weight > 0:
            omega = self.omega.detach().clone()
            rows_value = self.turn_bound_rows(omega).detach().numpy()
            # a few rows of 3N unknowns: plain reverse mode (functorch's jacrev cost ~0.1 s a call here)
            derivative = torch.autograd.functional.jacobian(self.turn_bound_rows, omega).detach().numpy().reshape(len(rows_value), -1)
            add(rows_value, [(np.full(len(rows_value), at["omega"] + c), derivative[:, c]) for c in range(derivative.shape[1])])
        total = sum(len(r) for r in residuals)
        jacobian = sparse.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(total, size))
        return np.concatenate(residuals), jacobian.tocsr()

    def forward(self, cameras: tuple | None = None) -> torch.Tensor:
        _, _, e_ab, e_ba = self.correspondence_terms(cameras)
        scale = self.robust_px ** 2
        loss = (self.weight * (torch.log1p(e_ab / scale) + torch.log1p(e_ba / scale))).sum()
        if self.bend_index.numel():
            bend = self.field[self.bend_index[:, 0]] - 2 * self.field[self.bend_index[:, 1]] + self.field[self.bend_index[:, 2]]
            loss = loss + self.field_smoothness * (bend ** 2).sum()
        loss = loss + self.field_prior * (self.field ** 2).sum() + self.alpha_prior * (self.log_alphas() ** 2).sum()  # per view, shared or not
        guess = self.log_focal_guess.mean() if self.shared_focal else self.log_focal_guess
        # The pull is on the focal in use: a rig's (``cameras``) when it holds the cameras.
        log_focal = self.log_focal if cameras is None else torch.log(cameras[2][:self.log_focal.numel()])
        loss = loss + self.focal_prior * ((log_focal - guess) ** 2).sum()
        if self.turn_bound_weight > 0 and cameras is None:
            loss = loss + (self.turn_bound_rows(self.omega) ** 2).sum()
        return loss

    def turn_bound_rows(self, omega: torch.Tensor) -> torch.Tensor:
        """``sqrt(weight) * max(0, least turn - turn)`` (radians) per bounded view pair: zero while a turn keeps
        to what the silhouettes allow."""
        rotations = axis_angle_to_matrix(omega * self.free[:, None]) @ self.base_rotation
        turn = rotation_angle(rotations[self.bound_pairs[:, 0]], rotations[self.bound_pairs[:, 1]])
        return float(np.sqrt(self.turn_bound_weight)) * torch.relu(self.bound_turns - turn)


def _surface_depth(scale, log_alpha, median, relief, z, field) -> torch.Tensor:
    """A view's surface depth at pointmap depth ``z`` (the module docstring's ``depth_v``), per row."""
    return scale * (median + torch.exp(log_alpha) * (z - median) + relief * field)


def _lift(rotation, translation, focal, centre, uv, depth) -> torch.Tensor:
    """Per row: pixel ``uv`` at ``depth`` in a camera (cam_to_world ``rotation``, ``translation``) -> world point."""
    rays = torch.cat([(uv - centre) / focal[:, None], torch.ones_like(uv[:, :1])], dim=1)
    return torch.einsum("nij,nj->ni", rotation, depth[:, None] * rays) + translation


def _project(rotation, translation, focal, centre, points) -> torch.Tensor:
    """Per row: world point -> pixel of a camera (cam_to_world ``rotation``, ``translation``)."""
    camera = torch.einsum("nji,nj->ni", rotation, points - translation)
    z = camera[:, 2].clamp_min(1e-9)
    return camera[:, :2] / z[:, None] * focal[:, None] + centre


def _whitening(information: np.ndarray) -> np.ndarray:
    """``W [M, 2, 2]`` with ``W^T W = I`` for each information matrix ``I`` (so ``r^T I r = |W r|^2``)."""
    information = np.asarray(information, np.float64)
    if len(information) == 0:
        return np.zeros((0, 2, 2))
    values, vectors = np.linalg.eigh(0.5 * (information + np.swapaxes(information, 1, 2)))
    return np.sqrt(np.clip(values, 0.0, None))[:, :, None] * np.swapaxes(vectors, 1, 2)
