"""Shared, session-scoped test data: synthetic captures are generated once per session.

``uwa640``: a real-looking UWA-like three-view capture at 640x512 (seed 1) with its ground truth;
``real_dev``: the folder of real UWA captures (tests using it skip, saying why, when it is absent).
"""
import os
from pathlib import Path

import pytest

if os.environ.get("PYTEST_XDIST_WORKER"):  # each of pytest -n N's workers gets one core's worth of threads
    import torch

    os.environ.setdefault("FS3D_THREADS", "1")
    torch.set_num_threads(1)

from fingersplat3d.synth import SynthConfig, synthesize

REAL_DEV = Path(__file__).resolve().parents[2] / "shared" / "data" / "uwa-real-dev"
IMPOSE_DEV = Path(__file__).resolve().parents[2] / "shared" / "data" / "impose-dev"


@pytest.fixture(scope="session")
def uwa640():
    return synthesize(1, SynthConfig(size=(640, 512))).capture


@pytest.fixture(scope="session")
def impose_dev() -> Path:
    if not IMPOSE_DEV.is_dir():
        pytest.skip(f"another group's renders are not at {IMPOSE_DEV} (they are read at run time, never shipped)")
    return IMPOSE_DEV


@pytest.fixture(scope="session")
def real_dev() -> Path:
    if not REAL_DEV.is_dir():
        pytest.skip(f"the real UWA dev captures are not at {REAL_DEV} (they are read at run time, never shipped)")
    return REAL_DEV
