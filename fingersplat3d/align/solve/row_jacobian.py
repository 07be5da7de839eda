"""The global alignment's per-correspondence residuals and their derivatives, in closed form.

Each correspondence ``(p in a, q in b)`` gives four whitened residuals, ``W_b (proj_b(lift_a(p)) - q)``
and ``W_a (proj_a(lift_b(q)) - p)`` (:meth:`AlignmentProblem.row_residuals`), and depends on 20 local
unknowns: per end a rotation update ``omega`` (3), a translation (3), a log scale, a log relief, a
log focal and its field value. For one direction, source ``s`` and target ``t``:

* lift: ``w = R_s d_s ray_s``, ``x = w + t_s``, ``ray_s = ((uv_s - c_s) / f_s, 1)``,
  ``d_s = e^ls (m + e^la (z - m) + rho F)``, ``R_s = Exp(omega_s) R0_s``;
* project: ``y = R_t^T (x - t_t)``, ``proj = f_t y_xy / y_z + c_t``; ``A = d proj / d x``
  ``= f_t / y_z [[1, 0, -y_x / y_z], [0, 1, -y_y / y_z]] R_t^T``;
* rotation updates through the left Jacobian of SO(3) (:func:`~fingersplat3d.rotations.left_jacobian`):
  ``d x / d omega_s = -[w]_x J_l(omega_s)`` and ``d proj / d omega_t = A [x - t_t]_x J_l(omega_t)``;
* ``d/dt_s = A``, ``d/dt_t = -A``, ``d/dlf_t = proj - c_t``, ``d/dlf_s = A R_s d_s (-(uv_s - c_s) / f_s, 0)``,
  and the depth unknowns through ``A R_s ray_s``.

Why by hand: forward-mode autodiff of the same residuals (20 batched tangents through every op) was
half of the global alignment's time; these products are a few einsums. ``tests/test_levenberg.py``
checks them against autodiff in float64, near and away from ``omega = 0``. Pure torch.
"""
from __future__ import annotations

import torch

from ...rotations import axis_angle_to_matrix, left_jacobian, skew

__all__ = ["ROW_UNKNOWNS", "row_residuals_and_derivatives"]

# The local unknowns of one correspondence, in the order of the derivative's last axis, with their widths.
ROW_UNKNOWNS = (("omega_a", 3), ("t_a", 3), ("ls_a", 1), ("la_a", 1), ("lf_a", 1), ("f_a", 1),
                ("omega_b", 3), ("t_b", 3), ("ls_b", 1), ("la_b", 1), ("lf_b", 1), ("f_b", 1))


def _direction(source: dict, target: dict, uv_s, uv_t, white_t) -> tuple[torch.Tensor, torch.Tensor]:
    """One direction's whitened residuals ``[M, 2]`` and their derivatives ``[M, 2, 20]`` over the source's then the
    target's local unknowns (each end's 10, in :data:`ROW_UNKNOWNS` order)."""
    focal_s = torch.exp(source["lf"][:, 0])
    offset = (uv_s - source["centre"]) / focal_s[:, None]
    ray = torch.cat([offset, torch.ones_like(offset[:, :1])], 1)
    scale, alpha = torch.exp(source["ls"][:, 0]), torch.exp(source["la"][:, 0])
    median, z = source["median"], source["z"]
    depth = scale * (median + alpha * (z - median) + source["relief"] * source["f"][:, 0])
    turned_ray = torch.einsum("nij,nj->ni", source["R"], ray)  # R_s ray_s
    w = depth[:, None] * turned_ray
    q = w + source["t"] - target["t"]
    y = torch.einsum("nji,nj->ni", target["R"], q)
    clamped = y[:, 2] < 1e-9
    y_z = y[:, 2].clamp_min(1e-9)
    focal_t = torch.exp(target["lf"][:, 0])
    projected = y[:, :2] / y_z[:, None] * focal_t[:, None]
    residual = projected + target["centre"] - uv_t
    gain = focal_t / y_z
    zero = torch.zeros_like(gain)
    perspective = torch.stack([torch.stack([gain, zero, torch.where(clamped, zero, -gain * y[:, 0] / y_z)], -1),
                               torch.stack([zero, gain, torch.where(clamped, zero, -gain * y[:, 1] / y_z)], -1)], 1)
    A = torch.einsum("nik,njk->nij", perspective, target["R"])  # [M, 2, 3] = P R_t^T
    along_ray = torch.einsum("nij,nj->ni", A, turned_ray)
    focal_ray = torch.cat([-offset, torch.zeros_like(offset[:, :1])], 1)
    columns = [
        -A @ skew(w) @ left_jacobian(source["omega"]),  # omega_s
        A,  # t_s
        (depth[:, None] * along_ray)[:, :, None],  # ls_s
        (scale * alpha * (z - median))[:, None, None] * along_ray[:, :, None],  # la_s
        (depth[:, None] * torch.einsum("nij,nj->ni", A, torch.einsum("nij,nj->ni", source["R"], focal_ray)))[:, :, None],  # lf_s
        (scale * source["relief"])[:, None, None] * along_ray[:, :, None],  # f_s
        A @ skew(q) @ left_jacobian(target["omega"]),  # omega_t
        -A,  # t_t
        torch.zeros_like(A[:, :, :2]),  # ls_t, la_t: the target's depth does not enter
        projected[:, :, None],  # lf_t
        torch.zeros_like(A[:, :, :1]),  # f_t
    ]
    derivative = torch.cat(columns, 2)
    return torch.einsum("nij,nj->ni", white_t, residual), torch.einsum("nij,njk->nik", white_t, derivative)


def row_residuals_and_derivatives(problem, local: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """``[M, 4]`` whitened residuals (a->b, then b->a) and ``[M, 4, 20]`` their derivatives over ``local``
    (:meth:`AlignmentProblem.row_unknowns`' values, ordered as :data:`ROW_UNKNOWNS`)."""
    with torch.no_grad():
        ends = {}
        for end in ("a", "b"):
            view = getattr(problem, f"view_{end}")
            omega = local[f"omega_{end}"]
            ends[end] = {"omega": omega, "R": axis_angle_to_matrix(omega) @ problem.base_rotation[view],
                         "t": local[f"t_{end}"], "ls": local[f"ls_{end}"], "la": local[f"la_{end}"],
                         "lf": local[f"lf_{end}"], "f": local[f"f_{end}"], "centre": problem.centres[view],
                         "median": problem.medians[view], "relief": problem.reliefs[view], "z": getattr(problem, f"z_{end}")}
        r_ab, d_ab = _direction(ends["a"], ends["b"], problem.uv_a, problem.uv_b, problem.white_b)
        r_ba, d_ba = _direction(ends["b"], ends["a"], problem.uv_b, problem.uv_a, problem.white_a)
        # d_ab is over (a's 10, b's 10); d_ba over (b's 10, a's 10): swap its halves into (a, b) order.
        d_ba = torch.cat([d_ba[:, :, 10:], d_ba[:, :, :10]], 2)
        return torch.cat([r_ab, r_ba], 1), torch.cat([d_ab, d_ba], 1)
