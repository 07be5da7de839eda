"""The machine every benchmark names: CPU, cores (and those this process may use), GPU, load, library versions.

Used by ``fs3d bench`` and ``tools/bench_*.py``; no files written.
"""
from __future__ import annotations

import os
import platform
from pathlib import Path

__all__ = ["machine"]


def _version(module: str) -> str:
    try:
        return __import__(module).__version__
    except Exception:  # pragma: no cover - a missing optional library
        return "n/a"


def machine() -> dict:
    """CPU model, cores, load average and the versions the figures depend on."""
    model = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    from ..device import cpu_threads

    return {"cpu": model, "cores": os.cpu_count(), "usable_cores": cpu_threads(), "load": os.getloadavg(), "python": platform.python_version(),
            "numpy": _version("numpy"), "open3d": _version("open3d"), "torch": _version("torch"),
            "kernel": platform.release(), "gpu": _gpu()}


def _gpu() -> str:
    """The first CUDA device's name, or "none" (torch is imported only if it already was)."""
    import sys

    torch = sys.modules.get("torch")
    if torch is None or not torch.cuda.is_available():
        return "none"
    return torch.cuda.get_device_name(0)
