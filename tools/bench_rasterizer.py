"""Throughput of the fast rasterizer on a finger-like scene.

    python tools/bench_rasterizer.py [--quick] [--out FILE.md] [--repeats 5] [--threads 2]
                                     [--paths numba,compiled,eager] [--tile-size 4] [--device cuda]

Paths: ``numba`` = the compiled CPU kernels (``backend="numba"``, the default on the CPU, early
termination at 1e-4), ``compiled`` = the torch backend through torch.compile, ``eager`` = the
torch backend as it is, ``gsplat`` = gsplat's CUDA kernels (``--device cuda``, gsplat installed).

The scene is a fitted-surface stand-in: Gaussians spread evenly over the camera-facing half of a
cylinder (a finger, axis vertical) that fills ~40 % of a 640x512 image, flat disks tangent to the
surface whose in-plane scale is the point spacing (neighbours overlap, as after fitting), opacity
0.5..1 and a grayscale ridge pattern. The main figure is forward+backward of one 640x512 view with
200k Gaussians (target <= 0.12 s on the project's 2-core machine); a sweep varies N, the scale and
the image size (zoom 2: 1280x1024 with the focal length doubled, the same finger filling the same
part of the picture).

Throughput is counted in Gaussian-pixel pairs: ``pairs`` are the pairs with alpha >= 1/255 (the
work the result depends on), ``evaluated`` the pairs the tiled compositor actually computes
(tile_size**2 pixels per tile-Gaussian pair, plus padding). Times are medians over repeats.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import torch

from fingersplat3d.errors import run_script
from fingersplat3d.eval.machine import machine
from fingersplat3d.splat import matrix_to_quaternion, rasterize
from fingersplat3d.splat.binning import bin_gaussians
from fingersplat3d.splat.composite import _grid, _tile_centres, pair_alpha
from fingersplat3d.splat.project import _project

WIDTH, HEIGHT = 640, 512
FOCAL = 1320.0
DISTANCE = 60.0  # mm, camera to cylinder axis
RADIUS = 8.0  # mm
LENGTH = 16.9  # mm along the axis: the finger covers ~45 % of the image


def finger_scene(n: int, scale_factor: float = 1.0, channels: int = 1, seed: int = 0, zoom: int = 1):
    """``(means, quats, scales, opacities, colors, world_to_cam, K)`` float32, camera at the origin."""
    g = torch.Generator().manual_seed(seed)
    theta = (torch.rand(n, generator=g) - 0.5) * math.pi  # facing the camera: -90..90 degrees
    height = (torch.rand(n, generator=g) - 0.5) * LENGTH
    normal = torch.stack([torch.sin(theta), torch.zeros(n), -torch.cos(theta)], -1)  # towards the camera
    means = torch.stack([RADIUS * torch.sin(theta), height, DISTANCE - RADIUS * torch.cos(theta)], -1)
    spacing = math.sqrt(math.pi * RADIUS * LENGTH / n)
    axis = torch.tensor([0.0, 1.0, 0.0]).expand(n, 3)
    tangent = torch.cross(axis, normal, dim=-1)
    rotation = torch.stack([tangent, axis, normal], -1)  # columns: the Gaussian's local axes
    quats = matrix_to_quaternion(rotation)
    scales = torch.stack([torch.full((n,), spacing), torch.full((n,), spacing), torch.full((n,), 0.1 * spacing)], -1)
    scales = scales * scale_factor * torch.exp(0.2 * torch.randn(n, 3, generator=g))
    opacities = 0.5 + 0.5 * torch.rand(n, generator=g)
    ridges = 0.5 + 0.4 * torch.sin(2 * math.pi * (means[:, 0] + 0.3 * means[:, 1]) / 0.45)
    colors = ridges[:, None].expand(n, channels).contiguous()
    K = torch.tensor([[FOCAL * zoom, 0, (WIDTH * zoom - 1) / 2], [0, FOCAL * zoom, (HEIGHT * zoom - 1) / 2], [0, 0, 1]])
    return means, quats, scales, opacities, colors, torch.eye(4), K


def count_pairs(scene, tile_size: int, zoom: int = 1) -> tuple[int, int, float]:
    """(pairs with alpha >= 1/255, pairs the compositor evaluates, fraction of the image covered)."""
    means, quats, scales, opacities, _, world_to_cam, K = scene
    with torch.no_grad():
        width, height = WIDTH * zoom, HEIGHT * zoom
        proj, boxes = _project(means, quats, scales, world_to_cam, K, width, height, 0.01, 0.3, opacities)
        bins = bin_gaussians(boxes, proj.valid, proj.depths, width, height, tile_size)
        table = torch.cat([proj.means2d, proj.conics, opacities[:, None]], 1)
        table = torch.cat([table, table.new_zeros(1, 6)])
        grid, _ = _grid(tile_size, torch.float32, means.device)
        pairs = evaluated = 0
        for group in bins.groups:
            for members, tiles in zip(torch.split(group.gaussians, 2048), torch.split(group.tiles, 2048)):
                params = table[members]
                params[..., :2] -= _tile_centres(tiles, bins, torch.float32)[:, None, :]
                pairs += int((pair_alpha(params, grid)[0] > 0).sum())
                evaluated += members.numel() * tile_size ** 2
        covered = float((rasterize(*scene, width, height).alpha > 0.5).float().mean())
    return pairs, evaluated, covered


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def time_render(scene, repeats: int, tile_size: int, path: str, zoom: int = 1) -> tuple[float, float, float]:
    """(median forward s, median backward s, fastest forward+backward s) of a render plus a loss."""
    leaves = [t.clone().requires_grad_() for t in scene[:5]] + list(scene[5:])
    device = leaves[0].device
    backend = path if path in ("numba", "gsplat") else "torch"
    forward, backward = [], []
    for _ in range(repeats + 1):  # the first is a warm-up (and compiles, for the compiled path)
        for t in leaves[:5]:
            t.grad = None
        _sync(device)
        start = time.perf_counter()
        out = rasterize(*leaves, WIDTH * zoom, HEIGHT * zoom, tile_size=tile_size, compiled=path == "compiled",
                        backend=backend)
        loss = out.color.sum() + out.depth.sum()
        _sync(device)
        middle = time.perf_counter()
        loss.backward()
        _sync(device)
        end = time.perf_counter()
        forward.append(middle - start)
        backward.append(end - middle)
    forward, backward = forward[1:], backward[1:]
    fastest = min(f + b for f, b in zip(forward, backward))
    return sorted(forward)[len(forward) // 2], sorted(backward)[len(backward) // 2], fastest


def calibration_seconds(repeats: int) -> float:
    """Median seconds of a fixed torch workload on this machine with the same threads, so that rasterizer times read
    as a machine-independent ratio (issue 24's target: fwd+bwd of the main case <= 1.0 times this). The workload is
    dense float32 work of a splat step's size: forward and backward of a 5x5 convolution, 8 -> 8 channels, over one
    640x512 image, and four 1024x1024 matrix products."""
    g = torch.Generator().manual_seed(0)
    image = torch.rand(1, 8, HEIGHT, WIDTH, generator=g, requires_grad=True)
    kernel = torch.rand(8, 8, 5, 5, generator=g, requires_grad=True)
    a, b = torch.rand(1024, 1024, generator=g), torch.rand(1024, 1024, generator=g)
    times = []
    for _ in range(repeats + 1):  # the first is a warm-up
        start = time.perf_counter()
        torch.nn.functional.conv2d(image, kernel, padding=2).square().sum().backward()
        for _ in range(4):
            a = (a @ b) / 1024.0
        times.append(time.perf_counter() - start)
    return sorted(times[1:])[len(times[1:]) // 2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="main figure only")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--tile-size", type=int, default=4)
    parser.add_argument("--paths", default="numba,compiled,eager",
                        help="comma-separated: numba, compiled, eager, gsplat (CUDA)")
    parser.add_argument("--device", default="cpu", help="cpu (default) or cuda: where the scene lives")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    os.environ["FS3D_THREADS"] = str(args.threads)  # the numba kernels' thread count
    info = machine()
    start_load = tuple(round(x, 2) for x in info["load"])
    header = ("| path | N | scale x | image | covered | pairs (M) | evaluated (M) | forward s | backward s | fwd+bwd s (best) | "
              "fwd+bwd / calibration | fwd Mpairs/s | bwd Mpairs/s | load |")
    gpu = f", GPU {info['gpu']} (scene on {args.device})" if args.device != "cpu" else ""
    lines = [(f"Machine: {info['cpu']}, {info['cores']} cores{gpu}, torch {info['torch']}, {args.threads} threads, "
              f"tile {args.tile_size}, load average at start {start_load}"), "", header,
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    calibration = calibration_seconds(args.repeats)
    lines[0] += f"; calibration workload {calibration:.3f} s (`calibration_seconds`)"
    print(lines[0], flush=True)
    cases = [(200_000, 1.0, 1)]
    if not args.quick:
        cases += [(25_000, 1.0, 1), (50_000, 1.0, 1), (100_000, 1.0, 1), (400_000, 1.0, 1), (200_000, 0.5, 1),
                  (200_000, 2.0, 1), (200_000, 4.0, 1), (200_000, 1.0, 2), (400_000, 1.0, 2), (800_000, 1.0, 2)]
    for path in args.paths.split(","):
        for n, factor, zoom in cases:
            scene = tuple(t.to(args.device) for t in finger_scene(n, factor, zoom=zoom))
            pairs, evaluated, covered = count_pairs(scene, args.tile_size, zoom)
            fwd, bwd, best = time_render(scene, args.repeats, args.tile_size, path, zoom)
            evaluated_text = "–" if path == "numba" else f"{evaluated / 1e6:.1f}"
            row = (f"| {path} | {n // 1000}k | {factor:g} | {WIDTH * zoom}x{HEIGHT * zoom} | {covered:.0%} | "
                   f"{pairs / 1e6:.1f} | {evaluated_text} | "
                   f"{fwd:.3f} | {bwd:.3f} | {fwd + bwd:.3f} ({best:.3f}) | {(fwd + bwd) / calibration:.2f} | {pairs / fwd / 1e6:.0f} | "
                   f"{pairs / bwd / 1e6:.0f} | {os.getloadavg()[0]:.1f} |")
            lines.append(row)
            print(row, flush=True)
    lines += ["", ("Times are medians over the repeats (best fwd+bwd in brackets); pairs/s = alpha >= 1/255 pairs "
                   "per second. The machine is shared: the load column is the 1-minute load average after each row.")]
    if args.out:
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(run_script(main))
