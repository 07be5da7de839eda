"""CPU threads: one setting, the cores this process may use unless FS3D_THREADS says otherwise."""
import os

import pytest

from fingersplat3d.device import cpu_threads
from fingersplat3d.errors import InputError


def test_default_is_the_cores_this_process_may_use(monkeypatch):
    monkeypatch.delenv("FS3D_THREADS", raising=False)
    allowed = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert 1 <= cpu_threads() <= allowed


def test_environment_setting_wins_and_is_checked(monkeypatch):
    monkeypatch.setenv("FS3D_THREADS", "3")
    assert cpu_threads() == 3
    monkeypatch.setenv("FS3D_THREADS", "0")
    assert cpu_threads() == 1
    monkeypatch.setenv("FS3D_THREADS", "many")
    with pytest.raises(InputError, match="FS3D_THREADS"):
        cpu_threads()


def test_use_threads_sets_torch_and_the_kernels_threads(monkeypatch):
    import torch

    from fingersplat3d.device import use_threads
    from fingersplat3d.splat.cpu_raster import kernel_threads

    monkeypatch.setenv("FS3D_THREADS", "2")  # restored (removed) after the test
    before = torch.get_num_threads()
    try:
        use_threads(1)
        assert os.environ["FS3D_THREADS"] == "1" and torch.get_num_threads() == 1
        assert cpu_threads() == 1 and kernel_threads() == 1
    finally:
        torch.set_num_threads(before)
