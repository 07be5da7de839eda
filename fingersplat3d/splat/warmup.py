"""Compile the CPU rasterizer's numba kernels ahead of the work, and say so when that takes a while.

The kernels (:mod:`.cpu_composite`, :mod:`.cpu_project`, :mod:`.cpu_shading`, and the alignment's
:mod:`~fingersplat3d.align.solve.normal_matrix`, ~1 s of it) are compiled by numba on their first call and
cached on disk beside the modules, so only the first run after an install pays (~50 s on 2 cores).
``tools/install.sh`` runs ``python3 -m fingersplat3d.splat.warmup`` so that a fresh install compiles them
once, up front. Otherwise, the splat stage calls :func:`ensure_compiled` before its first render: where no
cache is found it first tells the user what the wait is.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Callable

__all__ = ["KERNEL_NAMES", "kernels_cached", "warm_up", "ensure_compiled"]

KERNEL_NAMES = {"cpu_composite": ("radix_order", "_records", "bin_tiles", "gather_pairs", "reduce_pairs"),
                "cpu_project": ("_forward_kernel", "_forward_lanes", "project_backward", "_backward_lanes"),
                "cpu_shading": ("_facing",),
                "normal_matrix": ("_upper_gram",)}
MESSAGE = "compiling the CPU rasterizer's kernels (once per install, ~50 s; cached on disk)"
_warm = False


def _kernels() -> list:
    from ..align.solve import normal_matrix
    from . import cpu_composite, cpu_project, cpu_shading

    modules = {"cpu_composite": cpu_composite, "cpu_project": cpu_project, "cpu_shading": cpu_shading,
               "normal_matrix": normal_matrix}
    compositing = [kernel for pair in cpu_composite._KERNELS.values() for kernel in pair]
    return [getattr(modules[module], name) for module, names in KERNEL_NAMES.items() for name in names] + compositing


def kernels_cached() -> bool | None:
    """Whether every kernel has a cache index on disk (None: numba does not say where its cache is)."""
    try:
        return all(Path(kernel._cache._cache_file._index_path).is_file() for kernel in _kernels())
    except AttributeError:  # numba's cache layout is internal; not knowing is not an error
        return None


def warm_up() -> float:
    """Render a tiny scene forward and backward on the CPU, so every kernel is compiled (or loaded from
    its cache); the seconds it took."""
    import torch

    from .rasterize import rasterize

    global _warm
    start = time.perf_counter()
    generator = torch.Generator().manual_seed(0)
    count = 8
    means = (torch.rand(count, 3, generator=generator) - 0.5) * torch.tensor([1.0, 1.0, 0.2]) + torch.tensor([0.0, 0.0, 4.0])
    K = torch.tensor([[20.0, 0.0, 15.5], [0.0, 20.0, 11.5], [0.0, 0.0, 1.0]])
    for channels in (1, 3, 2):  # the compositing kernels by feature count: gray, RGB, any other (cpu_composite)
        leaves = [means, torch.randn(count, 4, generator=generator), torch.full((count, 3), 0.15),
                  torch.full((count,), 0.6), torch.rand(count, channels, generator=generator)]
        leaves = [leaf.clone().requires_grad_(True) for leaf in leaves]
        out = rasterize(*leaves, torch.eye(4), K, 32, 24, backend="numba")
        (out.color.sum() + out.depth.nan_to_num().sum()).backward()
    from .shading import facing_cosines

    facing_cosines(means, leaves[1].detach(), torch.log(leaves[2].detach()), torch.eye(4))  # the fit's shading
    import scipy.sparse as sparse

    from ..align.solve.normal_matrix import normal_matrix

    normal_matrix(sparse.eye(3, format="csr"))  # the alignment's Gauss-Newton matrix
    _warm = True
    return time.perf_counter() - start


def ensure_compiled(say: Callable[[str], None] | None = None) -> None:
    """Compile the kernels now (once per process); ``say`` (default: stderr) hears :data:`MESSAGE` first
    unless their disk cache is there."""
    if _warm:
        return
    if kernels_cached() is not True:
        (say or (lambda text: print(f"fs3d: {text}", file=sys.stderr, flush=True)))(MESSAGE)
    warm_up()


def main() -> int:
    cached = kernels_cached()
    seconds = warm_up()
    print(f"fingersplat3d: the CPU rasterizer's kernels are {'loaded from the cache' if cached else 'compiled'} "
          f"({seconds:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
