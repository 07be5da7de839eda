"""The machine line every benchmark prints: CPU, cores, load and library versions."""
from __future__ import annotations

import os
import platform
from pathlib import Path


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
    return {"cpu": model, "cores": os.cpu_count(), "load": os.getloadavg(), "python": platform.python_version(),
            "numpy": _version("numpy"), "open3d": _version("open3d"), "torch": _version("torch"),
            "kernel": platform.release()}
