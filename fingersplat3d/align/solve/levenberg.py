"""Levenberg-Marquardt for the global-alignment problem: its sparse Jacobian, built row by row.

Why not only L-BFGS: the problem couples a few pose and focal unknowns with hundreds of depth-field
coefficients, and is badly conditioned (the turn between views, the relief and the focal trade
against each other). L-BFGS with a 30-step memory crawls along that valley: on five ring views it
was still lowering the loss after 3000 iterations, with the rotations 6 degrees off after the 300
the fuse could afford. A Gauss-Newton step solves the whole quadratic model at once.

Each correspondence's four whitened residuals (a->b and b->a, two pixels each) depend on the two
views' poses, scales, relief, focal and on one field value per end, which is a fixed combination of
16 field coefficients. So the Jacobian is built from 20 per-row derivatives (in closed form,
:mod:`~fingersplat3d.align.solve.row_jacobian`, one per local unknown) scattered into a sparse matrix,
plus the priors' rows (linear in the unknowns, or nearly). The Cauchy loss is handled by iteratively
reweighted least squares: each residual scaled by ``sqrt(w / (c^2 + e))``, so the step's gradient
is the true loss's. Steps are accepted only if the true loss (:meth:`AlignmentProblem.forward`)
decreases. Pure torch/numpy/scipy.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
import torch

from .row_jacobian import ROW_UNKNOWNS, row_residuals_and_derivatives

__all__ = ["levenberg_marquardt", "damped_least_squares", "turn_uncertainty_deg"]


def _system(problem) -> tuple[np.ndarray, sparse.csr_matrix]:
    """IRLS-weighted residual vector and its Jacobian over ``problem.unknowns()``'s flat layout."""
    local = problem.row_unknowns()  # name -> [M, k] tensors, the values each row reads
    rows, derivatives = row_residuals_and_derivatives(problem, local)  # [M, 4] whitened, [M, 4, 20]
    chain = problem.pivot_chain()
    if chain is not None:  # each end's derivative by its camera centre, carried onto its rotation and pivot unknowns
        by_omega, by_pivot = chain
        for start, view in ((0, problem.view_a), (10, problem.view_b)):
            by_centre = derivatives[:, :, start + 3:start + 6].clone()
            derivatives[:, :, start:start + 3] += by_centre @ by_omega[view]
            derivatives[:, :, start + 3:start + 6] = by_centre @ by_pivot[view]
    columns = problem.row_columns()  # name -> ([M, k, C] column indices, -1 where fixed; [M, k, C] weights)
    e = torch.stack([(rows[:, :2] ** 2).sum(1), (rows[:, 2:] ** 2).sum(1)], 1)  # [M, 2]
    irls = torch.sqrt(problem.weight[:, None] / (problem.robust_px ** 2 + e))  # [M, 2]
    scale = irls.repeat_interleave(2, dim=1)  # [M, 4]
    residual = (rows * scale).reshape(-1).numpy()
    derivatives = (derivatives * scale[:, :, None]).numpy()
    count = rows.shape[0]
    # Every local unknown's columns side by side ([M, K]), with the slot of the derivative each one takes, so that
    # the sparse entries are gathered in one pass (one mask over all of them, not one per local unknown).
    cols, weights, slots = [], [], []
    slot = 0
    for name, width in ROW_UNKNOWNS:
        for k in range(width):
            c, w = columns[name][0][:, k, :], columns[name][1][:, k, :]  # [M, C]
            cols.append(c)
            weights.append(w)
            slots += [slot] * c.shape[1]
            slot += 1
    cols, weights = np.concatenate(cols, 1), np.concatenate(weights, 1)  # [M, K]
    vals = derivatives[:, :, slots] * weights[:, None, :]  # [M, 4, K]
    keep = np.broadcast_to((cols >= 0)[:, None, :], vals.shape)
    # Straight into CSR: the entries are in row order already (a repeated column within a row is summed by every
    # product, as a Jacobian's entries must be).
    indptr = np.concatenate([[0], np.cumsum(keep.sum(2).reshape(-1))])
    prior_residual, prior_jacobian = problem.prior_system()
    size = problem.unknowns().numel()
    jacobian = sparse.csr_matrix((vals[keep], np.broadcast_to(cols[:, None, :], vals.shape)[keep], indptr),
                                 shape=(4 * count, size))
    return np.concatenate([residual, prior_residual]), sparse.vstack([jacobian, prior_jacobian]).tocsr()


def _normal_matrix(jacobian) -> np.ndarray:
    """``JᵀJ``, dense (:mod:`.normal_matrix`, imported here: numba only loads when a fit runs, not for every command)."""
    from .normal_matrix import normal_matrix

    return normal_matrix(jacobian)


def _solve_positive(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``matrix^-1 rhs`` for the damped Gauss-Newton matrix, symmetric positive definite by construction: Cholesky
    (half an LU's work: 0.07 s against 0.13 s at ten views' 2,500 unknowns), LU where rounding leaves it not quite
    positive. Raises ``LinAlgError`` where neither solves it."""
    import scipy.linalg

    try:
        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(matrix, check_finite=False), rhs, check_finite=False)
    except np.linalg.LinAlgError:
        return np.linalg.solve(matrix, rhs)


def damped_least_squares(system, loss, snapshot, step_to, iterations: int = 15, tolerance: float = 1e-5) -> list[float]:
    """Levenberg-Marquardt over a problem given as callables; returns the loss after each accepted step.

    ``system()``: the (IRLS-weighted) residuals and their sparse Jacobian at the current point;
    ``loss()``: the true loss there; ``snapshot()``: the current point; ``step_to(point, step)``: move
    to ``point + step`` (``step`` None: back to ``point``). A step is kept only where the true loss
    falls; the damping (a share of the Gauss-Newton diagonal) adapts to how steps fare.
    """
    current = loss()
    history = [current]
    damping = 1e-4
    for _ in range(iterations):
        residual, jacobian = system()
        hessian = _normal_matrix(jacobian)
        gradient = jacobian.T @ residual
        diagonal = np.diag(hessian).copy()
        active = diagonal > 0
        if not active.any():
            break
        start = snapshot()
        improved = False
        for _ in range(8):
            matrix = hessian[np.ix_(active, active)] + np.diag(damping * diagonal[active] + 1e-12)
            try:
                solved = _solve_positive(matrix, -gradient[active])
            except np.linalg.LinAlgError:
                damping *= 10
                continue
            step = np.zeros_like(diagonal)
            step[active] = solved
            step_to(start, step)
            trial = loss()
            if np.isfinite(trial) and trial < current:
                improved = True
                damping = max(damping / 3.0, 1e-9)
                break
            damping *= 4.0
        if not improved:
            step_to(start, None)
            break
        decrease = (current - trial) / max(abs(current), 1e-300)
        current = trial
        history.append(current)
        if decrease < tolerance:
            break
    return history


def levenberg_marquardt(problem, iterations: int = 15, tolerance: float = 1e-5) -> list[float]:
    """Minimise ``problem()`` (an :class:`~fingersplat3d.align.solve.alignment_problem.AlignmentProblem`);
    returns the loss after each accepted step."""

    def loss() -> float:
        with torch.no_grad():
            return float(problem())

    def step_to(point: torch.Tensor, step: np.ndarray | None) -> None:
        problem.set_unknowns(point if step is None else point + torch.as_tensor(step, dtype=point.dtype))

    return damped_least_squares(lambda: _system(problem), loss, lambda: problem.unknowns().clone(), step_to,
                                iterations, tolerance)


def turn_uncertainty_deg(problem, aligned) -> np.ndarray:
    """``[N, N]`` degrees: the standard deviation of each view pair's relative rotation, in its least sure
    direction, from the curvature of the solved problem (Gauss-Newton covariance ``s^2 (J^T J)^-1``,
    ``s^2`` the residual variance), every other unknown marginalised out: the turn, the relief and the
    focal trading against each other shows as a large value. NaN where a view is not ``aligned`` (the
    root is aligned and is the gauge: its rotation has no variance of its own)."""
    residual, jacobian = _system(problem)
    hessian = _normal_matrix(jacobian)
    active = np.diag(hessian) > 0
    variance = float(residual @ residual) / max(jacobian.shape[0] - int(active.sum()), 1)
    covariance = np.zeros_like(hessian)
    covariance[np.ix_(active, active)] = variance * np.linalg.pinv(hessian[np.ix_(active, active)], hermitian=True)
    n = problem.medians.shape[0]
    solved = [bool(a) for a in aligned]
    result = np.full((n, n), np.nan)
    for a in range(n):
        for b in range(n):
            if a == b or not (solved[a] and solved[b]):
                continue
            ia, ib = slice(3 * a, 3 * a + 3), slice(3 * b, 3 * b + 3)
            block = covariance[ia, ia] + covariance[ib, ib] - covariance[ia, ib] - covariance[ib, ia]
            result[a, b] = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(block).max(), 0.0))))
    return result
