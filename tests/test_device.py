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
    from threadpoolctl import threadpool_info, threadpool_limits

    from fingersplat3d.device import numba_threads, use_threads

    monkeypatch.setenv("FS3D_THREADS", "2")  # restored (removed) after the test
    before = torch.get_num_threads()
    blas_before = {pool["prefix"]: pool["num_threads"] for pool in threadpool_info()}
    try:
        use_threads(1)
        assert os.environ["FS3D_THREADS"] == "1" and torch.get_num_threads() == 1
        assert cpu_threads() == 1 and numba_threads() == 1
        assert all(pool["num_threads"] == 1 for pool in threadpool_info() if pool["user_api"] == "blas")  # numpy's, scipy's
    finally:
        torch.set_num_threads(before)
        threadpool_limits(limits=blas_before)


def test_single_threaded_holds_torch_opencv_and_blas_to_one_thread_and_restores_them():
    """Many small solves beside a busy process: BLAS threads spin on the cores it needs (a registration took 4.4x as
    long); inside ``single_threaded`` every pool runs one thread, and after it each has its own count back."""
    import cv2
    import numpy as np  # noqa: F401  (loads numpy's BLAS, so that threadpoolctl sees it)
    import scipy.linalg  # noqa: F401
    import torch
    from threadpoolctl import threadpool_info

    from fingersplat3d.device import single_threaded

    before = ({p["prefix"]: p["num_threads"] for p in threadpool_info()}, torch.get_num_threads(), cv2.getNumThreads())
    with single_threaded():
        assert threadpool_info() and all(pool["num_threads"] == 1 for pool in threadpool_info())
        assert torch.get_num_threads() == 1 and cv2.getNumThreads() == 1
    after = ({p["prefix"]: p["num_threads"] for p in threadpool_info()}, torch.get_num_threads(), cv2.getNumThreads())
    assert after == before


@pytest.mark.parametrize("threads", ["1", "2", "3"])
def test_per_item_keeps_the_items_order_raises_the_first_error_and_restores_the_threads(monkeypatch, threads):
    import threading

    import cv2
    import torch

    from fingersplat3d.device import per_item

    monkeypatch.setenv("FS3D_THREADS", threads)
    torch_before, cv_before = torch.get_num_threads(), cv2.getNumThreads()
    seen = set()

    def square(item):
        seen.add(threading.get_ident())
        assert torch.get_num_threads() == 1  # the libraries on one thread under each item, one core or several
        return item * item

    assert per_item(square, range(7)) == [item * item for item in range(7)]
    assert per_item(square, []) == []
    assert len(seen) <= int(threads)

    def fails_on_odd(item):
        if item % 2:
            raise InputError(f"item {item}")
        return item

    with pytest.raises(InputError, match="item 1"):
        per_item(fails_on_odd, range(6))
    assert (torch.get_num_threads(), cv2.getNumThreads()) == (torch_before, cv_before)
