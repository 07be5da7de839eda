"""Levenberg-Marquardt for a rig's joint fit: every capture's Jacobian, chained onto the shared rig.

A :class:`~fingersplat3d.align.solve.rig.RigProblem` holds K capture problems whose cameras come
from one rig: camera ``v`` of capture ``k`` has rotation ``R_v Q_kv`` (``Q`` a quarter turn for a
portrait view), centre ``c_v exp(s_k)`` and the rig's focal (one, or camera ``v``'s own). Each capture's sparse Jacobian
(:func:`~fingersplat3d.align.solve.levenberg._system`, over its own poses, focal and surfaces) is
taken with its cameras set to the rig's current ones and its rotation updates at zero, so that a
capture's rotation column *is* a left update ``exp(w) R_v`` of the rig's camera ``v``; a capture's
translation column becomes the rig centre's (times ``exp(s_k)``) and its scale's (times the
translation); its focal columns the rig's. Stacked, these make one sparse system over the rig's
``6V + 1`` (or ``7V``) unknowns, the K capture scales and every capture's surfaces, solved as the single-capture
solver solves its own (damped Gauss-Newton, a step kept only where the true loss falls).

Why: the joint fit had been L-BFGS, which stops far from the optimum of these badly conditioned
problems (:mod:`~fingersplat3d.align.solve.levenberg`). Pure torch/numpy/scipy.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
import torch

from ...rotations import axis_angle_to_matrix
from .levenberg import _system, damped_least_squares

__all__ = ["levenberg_marquardt_rig", "rig_system"]


def _sync(rig_problem) -> None:
    """Each capture problem's cameras set to the rig's current ones, rotation updates at zero."""
    with torch.no_grad():
        rotations, focal = rig_problem.rig_rotations(), rig_problem.log_focal
        for k, problem in enumerate(rig_problem.problems):
            cameras = rig_problem.cameras(k)
            problem.base_rotation.copy_(rotations @ rig_problem.turns[k])
            problem.omega.zero_()
            problem.translation.copy_(cameras[1])
            problem.log_focal.copy_(focal.expand_as(problem.log_focal))


def _layout(rig_problem) -> tuple[int, list[int], int]:
    """Columns: rig omega ``3V``, rig centres ``3V``, rig log focal (1 or ``V``), capture scales ``K``, then each capture's own
    unknowns (log scales, log relief, fields); returns the start of the capture blocks, their starts and the size."""
    views, captures = rig_problem.base_rotation.shape[0], len(rig_problem.problems)
    first = start = 6 * views + rig_problem.log_focal.numel() + captures
    starts = []
    for problem in rig_problem.problems:
        starts.append(start)
        start += problem.unknowns().numel() - 6 * problem.medians.shape[0] - problem.log_focal.numel()
    return first, starts, start


def _chain(rig_problem, k: int, own_start: int, size: int, fixed_rig: bool) -> sparse.csr_matrix:
    """``[capture unknowns, global unknowns]``: how capture ``k``'s unknowns move with the global ones."""
    problem = rig_problem.problems[k]
    views = problem.medians.shape[0]
    local = problem.unknowns().numel()
    rows, cols, vals = [], [], []
    scale = float(torch.exp(rig_problem.log_capture_scale[k] * rig_problem.scale_free[k]).detach())
    translation = problem.translation.detach().numpy()
    if not fixed_rig:
        rows += list(range(3 * views))  # rotation updates: the rig camera's
        cols += list(range(3 * views))
        vals += [1.0] * (3 * views)
        rows += list(range(3 * views, 6 * views))  # translations: the rig centres, times the capture's scale
        cols += list(range(3 * views, 6 * views))
        vals += [scale] * (3 * views)
    focals = rig_problem.log_focal.numel()
    if float(rig_problem.scale_free[k]) > 0:
        rows += list(range(3 * views, 6 * views))
        cols += [6 * views + focals + k] * (3 * views)
        vals += translation.reshape(-1).tolist()
    at = problem._layout()
    own = [np.arange(at["log_scale"], at["log_focal"]), np.arange(at["field"], local)]
    own = np.concatenate(own)
    rows += own.tolist()
    cols += (own_start + np.arange(own.size)).tolist()
    vals += [1.0] * own.size
    if not fixed_rig:  # one focal for every camera, or one each
        own_focals = problem.log_focal.numel()
        rows += list(range(at["log_focal"], at["log_focal"] + own_focals))
        cols += [6 * views + (i if focals > 1 else 0) for i in range(own_focals)]
        vals += [1.0] * own_focals
    return sparse.csr_matrix((vals, (rows, cols)), shape=(local, size))


def _state(rig_problem) -> list[torch.Tensor]:
    tensors = [rig_problem.base_rotation, rig_problem.center, rig_problem.log_focal, rig_problem.log_capture_scale]
    return [t.detach().clone() for t in tensors] + [p.unknowns() for p in rig_problem.problems]


def _restore(rig_problem, state) -> None:
    with torch.no_grad():
        for tensor, value in zip((rig_problem.base_rotation, rig_problem.center, rig_problem.log_focal,
                                  rig_problem.log_capture_scale), state[:4]):
            tensor.copy_(value)
        for problem, values in zip(rig_problem.problems, state[4:]):
            problem.set_unknowns(values)
    _sync(rig_problem)


def _apply(rig_problem, start_state, step: np.ndarray, fixed_rig: bool, starts: list[int]) -> None:
    _restore(rig_problem, start_state)
    views, focals = rig_problem.base_rotation.shape[0], rig_problem.log_focal.numel()
    free = rig_problem.free.numpy()[:, None]
    with torch.no_grad():
        if not fixed_rig:
            turn = torch.as_tensor(step[:3 * views].reshape(views, 3) * free)
            rig_problem.base_rotation.copy_(axis_angle_to_matrix(turn) @ rig_problem.base_rotation)
            rig_problem.center.add_(torch.as_tensor(step[3 * views:6 * views].reshape(views, 3) * free))
            rig_problem.log_focal.add_(torch.as_tensor(step[6 * views:6 * views + focals]).reshape(rig_problem.log_focal.shape))
        scales = step[6 * views + focals:6 * views + focals + len(rig_problem.problems)] * rig_problem.scale_free.numpy()
        rig_problem.log_capture_scale.add_(torch.as_tensor(scales))
        for problem, values, begin in zip(rig_problem.problems, start_state[4:], starts):
            at = problem._layout()
            own = np.concatenate([np.arange(at["log_scale"], at["log_focal"]), np.arange(at["field"], values.numel())])
            updated = values.clone()
            updated[own] += torch.as_tensor(step[begin:begin + own.size])
            problem.set_unknowns(updated)
    _sync(rig_problem)


def rig_system(rig_problem, fixed_rig: bool = False) -> tuple[np.ndarray, sparse.csr_matrix]:
    """The IRLS-weighted residuals of every capture and their Jacobian over the global unknowns (see :func:`_layout`);
    the captures' cameras must be synced to the rig (:func:`_sync`)."""
    _, starts, size = _layout(rig_problem)
    residuals, blocks = [], []
    for k, problem in enumerate(rig_problem.problems):
        residual, jacobian = _system(problem)
        residuals.append(residual)
        blocks.append(jacobian @ _chain(rig_problem, k, starts[k], size, fixed_rig))
    return np.concatenate(residuals), sparse.vstack(blocks).tocsr()


def levenberg_marquardt_rig(rig_problem, iterations: int = 15, tolerance: float = 1e-5, fixed_rig: bool = False) -> list[float]:
    """Minimise ``rig_problem()`` (see the module); returns the loss after each accepted step. ``fixed_rig``: only
    the captures' scales and surfaces move."""
    for problem in rig_problem.problems:  # their pose and focal columns are the rig's, chained
        for parameter in (problem.omega, problem.translation, problem.log_focal):
            parameter.requires_grad_(True)
    _sync(rig_problem)
    _, starts, _ = _layout(rig_problem)

    def loss() -> float:
        with torch.no_grad():
            return float(rig_problem())

    def step_to(point, step: np.ndarray | None) -> None:
        if step is None:
            _restore(rig_problem, point)
        else:
            _apply(rig_problem, point, step, fixed_rig, starts)

    try:
        return damped_least_squares(lambda: rig_system(rig_problem, fixed_rig), loss, lambda: _state(rig_problem), step_to,
                                    iterations, tolerance)
    finally:
        for problem in rig_problem.problems:
            for parameter in (problem.omega, problem.translation, problem.log_focal):
                parameter.requires_grad_(False)
