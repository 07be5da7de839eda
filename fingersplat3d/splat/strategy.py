"""Adaptive density control (3DGS): clone, split and prune Gaussians under a budget.

The optimised parameters live in one Adam optimiser (:class:`~fingersplat3d.splat.adam.Adam`), one parameter group per Gaussian field,
addressed by name (``GAUSSIAN_GROUPS``, the order of :meth:`Gaussians.tensors`); growing or shrinking the model edits the groups' tensors and
their Adam moments together (:func:`replace_rows`), so the optimiser keeps its state for the
Gaussians that stay. Statistics are the mean norm of the view-space positional gradient (in NDC
units, as 3DGS) over the views in which each Gaussian was rendered.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from .adam import Adam
from .config import SplatConfig
from .gaussians import Gaussians
from ..rotations import quaternion_to_matrix

__all__ = ["DensifyStats", "GradientStats", "densify_and_prune", "hold_rows", "replace_rows", "gaussians_of"]


@dataclass
class GradientStats:
    """Running view-space gradient statistics, one entry per Gaussian."""

    grad_sum: torch.Tensor  # [N]
    count: torch.Tensor  # [N]

    @classmethod
    def zeros(cls, n: int, device: torch.device) -> "GradientStats":
        return cls(torch.zeros(n, device=device), torch.zeros(n, device=device))

    def add(self, means2d_grad: torch.Tensor, radii: torch.Tensor, width: int, height: int) -> None:
        """Accumulate one view: ``means2d_grad`` [N, 2] in pixels, ``radii`` [N] (0 = not rendered)."""
        seen = radii > 0
        ndc = means2d_grad.detach() * torch.tensor([width / 2.0, height / 2.0], device=means2d_grad.device)
        norm = torch.linalg.vector_norm(ndc, dim=-1)
        self.grad_sum += torch.where(seen, torch.nan_to_num(norm), torch.zeros_like(norm))
        self.count += seen.to(self.count.dtype)

    def mean(self) -> torch.Tensor:
        return self.grad_sum / self.count.clamp_min(1.0)


@dataclass(frozen=True)
class DensifyStats:
    cloned: int
    split: int
    pruned: int
    total: int


GAUSSIAN_GROUPS = ("means", "quats", "log_scales", "opacity", "sh_dc")
"""Names of the optimiser's parameter groups that hold the Gaussians, in :meth:`Gaussians.tensors` order."""


def param_group(optimizer: Adam, name: str) -> dict:
    """The optimiser's parameter group called ``name`` (a ``KeyError`` naming the groups when none is)."""
    for group in optimizer.param_groups:
        if group.get("name") == name:
            return group
    raise KeyError(f"no parameter group {name!r}; the optimiser has {[g.get('name') for g in optimizer.param_groups]}")


def _gaussian_groups(optimizer: Adam) -> list[dict]:
    return [param_group(optimizer, name) for name in GAUSSIAN_GROUPS]


def gaussians_of(optimizer: Adam) -> Gaussians:
    """The model whose fields are the optimiser's parameter groups (see module docstring)."""
    return Gaussians(*(group["params"][0] for group in _gaussian_groups(optimizer)))


def hold_rows(optimizer: Adam, rows: torch.Tensor) -> None:
    """Zero the gradients of the Gaussians ``rows`` (``[N]`` bool) before a step: from zero moments Adam's update is
    zero, so those Gaussians stay as they are while the others fit around them."""
    for group in _gaussian_groups(optimizer):
        parameter = group["params"][0]
        if parameter.grad is not None:
            parameter.grad[rows] = 0.0


def replace_rows(optimizer: Adam, keep: torch.Tensor, new_rows: tuple[torch.Tensor, ...]) -> None:
    """Keep rows ``keep`` (bool [N]) of every Gaussian group and append ``new_rows`` (one tensor per
    group); Adam moments of kept rows are kept, those of new rows start at zero."""
    for group, extra in zip(_gaussian_groups(optimizer), new_rows):
        old = group["params"][0]
        data = torch.cat([old.detach()[keep], extra.detach().to(old.dtype)])
        parameter = torch.nn.Parameter(data.requires_grad_(True))
        state = optimizer.state.pop(old, None)
        if state:
            for key in ("exp_avg", "exp_avg_sq"):
                moment = state[key]
                state[key] = torch.cat([moment[keep], torch.zeros_like(extra, dtype=moment.dtype)])
            optimizer.state[parameter] = state
        group["params"][0] = parameter


def densify_and_prune(optimizer: Adam, stats: GradientStats, config: SplatConfig,
                      extent: float, budget: int, generator: torch.Generator, densify: bool = True) -> DensifyStats:
    """One adaptive-density pass: clone small / split large high-gradient Gaussians (within
    ``budget``), then prune transparent, huge or non-finite ones."""
    model = gaussians_of(optimizer)
    with torch.no_grad():
        n = len(model)
        device = model.means.device
        scales = model.scales
        max_scale = scales.max(dim=-1).values
        finite = torch.stack([torch.isfinite(t.reshape(n, -1)).all(-1) for t in model.tensors()]).all(0)
        prune = (model.opacities < config.prune_opacity) | (max_scale > config.prune_scale * extent) | ~finite
        cloned = split = 0
        new_rows: tuple[torch.Tensor, ...] = tuple(t[:0] for t in model.tensors())
        if densify:
            grad = stats.mean()
            candidates = (grad >= config.grad_threshold) & ~prune
            room = max(0, budget - int((~prune).sum()))
            if int(candidates.sum()) > room:  # keep the strongest gradients within the budget
                order = torch.argsort(torch.where(candidates, grad, torch.full_like(grad, -1.0)), descending=True)
                limited = torch.zeros_like(candidates)
                limited[order[:room]] = True
                candidates &= limited
            large = max_scale > config.percent_dense * extent
            to_clone = candidates & ~large
            to_split = candidates & large
            cloned, split = int(to_clone.sum()), int(to_split.sum())
            clones = tuple(t[to_clone] for t in model.tensors())
            children = _split_children(model.subset(to_split), generator)
            new_rows = tuple(torch.cat([c, s]) for c, s in zip(clones, children))
            prune |= to_split  # the parents are replaced by their two children
        replace_rows(optimizer, ~prune, new_rows)
        total = len(gaussians_of(optimizer))
        stats.grad_sum = torch.zeros(total, device=device)
        stats.count = torch.zeros(total, device=device)
    return DensifyStats(cloned, split, int(prune.sum()) - split, total)


def _split_children(parents: Gaussians, generator: torch.Generator) -> tuple[torch.Tensor, ...]:
    """Two children per parent, centres drawn from the parent's Gaussian, scales / 1.6 (3DGS)."""
    if len(parents) == 0:
        return tuple(t[:0] for t in parents.tensors())
    rotation = quaternion_to_matrix(parents.quats)  # [M, 3, 3]
    noise = torch.randn((2, len(parents), 3), generator=generator, device=parents.means.device,
                        dtype=parents.means.dtype)
    offsets = torch.einsum("mij,kmj->kmi", rotation, noise * parents.scales)
    means = (parents.means + offsets).reshape(-1, 3)
    twice = lambda t: t.repeat(2, *([1] * (t.ndim - 1)))  # noqa: E731
    log_scales = twice(parents.log_scales) - torch.log(torch.tensor(1.6, dtype=parents.log_scales.dtype))
    return means, twice(parents.quats), log_scales, twice(parents.opacity_logits), twice(parents.sh_dc)
