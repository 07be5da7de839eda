"""Benchmark ``fs3d batch``: throughput on Ray vs a plain loop, Ray's overhead, a two-node local cluster, resume.

    python3 tools/bench_batch.py [--data ../shared/data/uwa-real-dev] [--out /tmp/fs3d-bench-batch] [--json out.json]

All runs are geometry only (``--no-splat``) on the real dev captures, except the last (``--splat-preset fast``
with 12 novel views, on 2 captures):

1. **plain loop**: one process, the captures one after another (torch on all cores);
2. **Ray, local**: ``fs3d batch --workers N`` (N = the cores), one capture per core;
3. **Ray overhead**: 40 empty tasks through the same engine: the time per task Ray adds, and ``ray.init``;
4. **two-node cluster**: ``ray start --head`` and a second ``ray start`` on this machine (each 1 CPU),
   standing in for two machines, and ``fs3d batch --address``;
5. **resume**: ``fs3d batch`` killed (SIGKILL) once the second capture is complete, then run again:
   what was complete before the kill is not redone, nothing is half-written, all end complete;
6. **full run**: fuse + splat (``fast``) + 12 novel views per capture.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from bench_real import DEFAULT_DATA  # tools/ is the script's folder

from fingersplat3d.errors import run_script


def _batch(args: list[str], env=None) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "fingersplat3d.cli", "batch", *args], check=False, env=env,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def _rows(out: Path) -> list[dict]:
    import csv

    with open(out / "results.csv") as handle:
        return list(csv.DictReader(handle))


def plain_loop(data: Path, out: Path) -> dict:
    import torch

    from fingersplat3d.batch.task import BatchOptions, process_capture
    from fingersplat3d.device import cpu_threads
    from fingersplat3d.io.jobs import list_jobs
    from fingersplat3d.pipeline import FuseConfig

    options = BatchOptions(fuse=FuseConfig(splat=None), render=0, threads=cpu_threads())
    torch.set_num_threads(cpu_threads())
    jobs = list_jobs([data])
    start = time.perf_counter()
    rows = [process_capture(job, str(out), options) for job in jobs]
    wall = time.perf_counter() - start
    return {"captures": len(jobs), "wall_s": wall, "per_hour": 3600 * len(jobs) / wall,
            "task_s": [r["seconds"] for r in rows], "done": sum(r["status"] == "done" for r in rows)}


def _noop(item):
    return item


def overhead() -> dict:
    import ray

    from fingersplat3d.batch.engine import ray_map

    start = time.perf_counter()
    ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False, configure_logging=False)
    init_s = time.perf_counter() - start
    ray_map(_noop, list(range(4)), (), lambda *a: None, progress=False)  # workers started
    start = time.perf_counter()
    ray_map(_noop, list(range(40)), (), lambda *a: None, progress=False)
    per_task = (time.perf_counter() - start) / 40
    ray.shutdown()
    return {"ray_init_s": init_s, "per_task_s": per_task}


def two_nodes(data: Path, out: Path) -> dict:
    port = "6391"
    env = {**os.environ, "RAY_ADDRESS": ""}
    subprocess.run(["ray", "start", "--head", "--num-cpus", "1", "--port", port, "--include-dashboard", "false"],
                   check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        subprocess.run(["ray", "start", "--address", f"127.0.0.1:{port}", "--num-cpus", "1"], check=True, env=env,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = _batch([str(data), "-o", str(out), "--no-splat", "--address", f"127.0.0.1:{port}"])
    finally:
        subprocess.run(["ray", "stop", "--force"], check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rows = _rows(out)
    return {"nodes": 2, "wall_s": wall, "per_hour": 3600 * len(rows) / wall, "done": sum(r["status"] == "done" for r in rows)}


def resume(data: Path, out: Path) -> dict:
    process = subprocess.Popen([sys.executable, "-m", "fingersplat3d.cli", "batch", str(data), "-o", str(out), "--no-splat"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    start = time.perf_counter()
    while len(list(out.glob("*/batch.json"))) < 2 and process.poll() is None and time.perf_counter() - start < 600:
        time.sleep(0.2)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    subprocess.run(["ray", "stop", "--force"], check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(1)
    complete = {p.parent.name: p.stat().st_mtime_ns for p in out.glob("*/batch.json")}
    partial = [p.name for p in out.iterdir() if ".tmp-" in p.name]
    folders_without_row = [p.name for p in out.iterdir() if p.is_dir() and not p.name.startswith(".") and not (p / "batch.json").exists()]
    wall = _batch([str(data), "-o", str(out), "--no-splat"])
    after = {p.parent.name: p.stat().st_mtime_ns for p in out.glob("*/batch.json")}
    return {"complete_at_kill": len(complete), "temporary_folders_at_kill": len(partial),
            "incomplete_capture_folders_at_kill": folders_without_row, "redone": [n for n in complete if after.get(n) != complete[n]],
            "complete_after_resume": len(after), "leftover_temporary": len([p for p in out.iterdir() if ".tmp-" in p.name]),
            "resume_wall_s": wall}


def main() -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.io.jobs import list_jobs

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=Path("/tmp/fs3d-bench-batch"))
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if not args.data.is_dir():
        print(f"bench_batch: {args.data}: no such folder", file=sys.stderr)
        return 2
    shutil.rmtree(args.out, ignore_errors=True)
    figures = {"machine": machine(), "captures": len(list_jobs([args.data]))}
    figures["plain_loop"] = plain_loop(args.data, args.out / "loop")
    wall = _batch([str(args.data), "-o", str(args.out / "ray"), "--no-splat"])
    rows = _rows(args.out / "ray")
    figures["ray_local"] = {"wall_s": wall, "per_hour": 3600 * len(rows) / wall, "task_s": [float(r["seconds"]) for r in rows],
                            "done": sum(r["status"] == "done" for r in rows)}
    figures["overhead"] = overhead()
    figures["two_nodes"] = two_nodes(args.data, args.out / "two-nodes")
    figures["resume"] = resume(args.data, args.out / "resume")
    wall = _batch([str(args.data), "-o", str(args.out / "full"), "--select", "count=2", "--splat-preset", "fast"])
    rows = _rows(args.out / "full")
    figures["full_fast"] = {"captures": len(rows), "wall_s": wall, "per_hour": 3600 * len(rows) / wall,
                            "task_s": [float(r["seconds"]) for r in rows], "peak_rss_mb": [float(r["peak_rss_mb"]) for r in rows]}
    print(json.dumps(figures, indent=1, default=float))
    if args.json:
        args.json.write_text(json.dumps(figures, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
