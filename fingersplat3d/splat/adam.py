"""Adam for the splat fit: torch.optim.Adam's update, without its first-use cost.

Why not ``torch.optim.Adam``: constructing the first torch optimiser of a process imports
``torch._dynamo`` (``Optimizer.__init__`` is wrapped to disable it), 1.1-1.4 s on 2 cores, a tenth
of a ``fast`` fuse, for a model that is never compiled. The update below is torch's (default
options: no weight decay, no AMSGrad, bias-corrected, ``eps`` added after the square root), with
its interface where the fit uses it: ``param_groups`` (dicts with ``params``, ``lr`` and any other
keys, such as the fit's ``name``) and ``state`` (per parameter ``step``, ``exp_avg``,
``exp_avg_sq``), so the density control (:func:`~fingersplat3d.splat.strategy.replace_rows`) edits
the moments as it would torch's. ``tests/test_splat_fit.py`` checks it against ``torch.optim.Adam``.
"""
from __future__ import annotations

import math
from collections import defaultdict

import torch

__all__ = ["Adam"]


class Adam:
    """``Adam(groups, betas=(0.9, 0.999), eps=1e-8)``; ``groups``: dicts with ``params`` (a list of tensors) and ``lr``."""

    def __init__(self, groups: list[dict], betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8) -> None:
        self.param_groups = [dict(group, params=list(group["params"])) for group in groups]
        self.betas, self.eps = betas, float(eps)
        self.state: dict = defaultdict(dict)

    def zero_grad(self, set_to_none: bool = True) -> None:
        for group in self.param_groups:
            for parameter in group["params"]:
                if parameter.grad is None:
                    continue
                if set_to_none:
                    parameter.grad = None
                else:
                    parameter.grad.zero_()

    @torch.no_grad()
    def step(self) -> None:
        beta1, beta2 = self.betas
        for group in self.param_groups:
            for parameter in group["params"]:
                grad = parameter.grad
                if grad is None:
                    continue
                state = self.state[parameter]
                if not state:
                    state.update(step=0, exp_avg=torch.zeros_like(parameter), exp_avg_sq=torch.zeros_like(parameter))
                state["step"] += 1
                state["exp_avg"].lerp_(grad, 1.0 - beta1)
                state["exp_avg_sq"].mul_(beta2).addcmul_(grad, grad, value=1.0 - beta2)
                step_size = group["lr"] / (1.0 - beta1 ** state["step"])
                denominator = (state["exp_avg_sq"].sqrt() / math.sqrt(1.0 - beta2 ** state["step"])).add_(self.eps)
                parameter.addcdiv_(state["exp_avg"], denominator, value=-step_size)
