"""A generic optimisation loop for a problem written as a torch module whose call returns its loss.

Adam with a cosine-decayed step finds the basin robustly (DUSt3R's schedule for global
alignment); its steps stay ~``learning_rate`` in every parameter, coarser than a pixel, so L-BFGS
with a strong-Wolfe line search then converges precisely. Either part can be switched off (0 steps).
Pure torch.
"""
from __future__ import annotations

import torch

__all__ = ["minimize"]


def minimize(problem: torch.nn.Module, adam_steps: int = 0, learning_rate: float = 0.01,
             lbfgs_iterations: int = 100, lbfgs_rounds: int = 1) -> list[float]:
    """Minimise ``problem()`` over its trainable parameters; returns the loss after each Adam step and L-BFGS round."""
    params = [p for p in problem.parameters() if p.requires_grad]
    history: list[float] = []
    if not params:
        return history
    if adam_steps > 0:
        optimizer = torch.optim.Adam(params, lr=learning_rate)
        schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, adam_steps, eta_min=1e-5)
        for _ in range(adam_steps):
            optimizer.zero_grad()
            loss = problem()
            loss.backward()
            optimizer.step()
            schedule.step()
            history.append(float(loss.detach()))
    if lbfgs_iterations > 0:
        polish = torch.optim.LBFGS(params, lr=1.0, max_iter=lbfgs_iterations, tolerance_grad=1e-12,
                                   tolerance_change=1e-15, history_size=30, line_search_fn="strong_wolfe")

        def closure():
            polish.zero_grad()
            loss = problem()
            loss.backward()
            return loss

        for _ in range(lbfgs_rounds):
            polish.step(closure)
            with torch.no_grad():
                history.append(float(problem()))
    return history
