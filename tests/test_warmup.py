"""The CPU rasterizer's kernels compiled ahead of the work, with a message when that takes a while."""
import os
import subprocess
import sys

import pytest

from fingersplat3d.splat import warmup


def _in_fresh_cache(tmp_path, code: str) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                          timeout=600).stdout


def test_an_empty_cache_is_seen_as_not_compiled(tmp_path):
    out = _in_fresh_cache(tmp_path, "from fingersplat3d.splat.warmup import kernels_cached; print(kernels_cached())")
    assert out.strip() == "False"


def test_the_message_comes_first_only_without_a_cache(monkeypatch):
    heard, calls = [], []
    monkeypatch.setattr(warmup, "_warm", False)
    monkeypatch.setattr(warmup, "warm_up", lambda: calls.append(1) or 0.0)
    monkeypatch.setattr(warmup, "kernels_cached", lambda: False)
    warmup.ensure_compiled(heard.append)
    assert heard == [warmup.MESSAGE] and calls == [1]
    monkeypatch.setattr(warmup, "kernels_cached", lambda: True)
    warmup.ensure_compiled(heard.append)
    assert heard == [warmup.MESSAGE] and calls == [1, 1]
    monkeypatch.setattr(warmup, "_warm", True)  # once per process
    warmup.ensure_compiled(heard.append)
    assert calls == [1, 1]


def test_no_kernel_closes_over_a_dispatcher():
    # numba keys a closure's disk cache on its cells, pickled; a dispatcher pickles differently in every process,
    # so a kernel that closed over one would be compiled again by every process (16 s a fuse, measured).
    from numba.core.dispatcher import Dispatcher

    for kernel in warmup._kernels():
        cells = [cell.cell_contents for cell in kernel.py_func.__closure__ or ()]
        assert not any(isinstance(value, Dispatcher) for value in cells), kernel.py_func.__qualname__


@pytest.mark.slow
def test_warm_up_compiles_into_the_cache_and_the_next_process_loads_it(tmp_path):
    code = ("from fingersplat3d.splat.warmup import _kernels, kernels_cached, warm_up; before = kernels_cached(); "
            "seconds = warm_up(); misses = sum(sum(k.stats.cache_misses.values()) for k in _kernels()); "
            "print(before, kernels_cached(), round(seconds, 1), misses)")
    first = _in_fresh_cache(tmp_path, code).split()
    second = _in_fresh_cache(tmp_path, code).split()
    assert first[:2] == ["False", "True"] and second[:2] == ["True", "True"]
    assert float(second[2]) < float(first[2])
    assert int(first[3]) > 0 and second[3] == "0"  # the next process compiles nothing
