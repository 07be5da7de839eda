"""``fs3d``: the command line. Thin: parses arguments, calls the library, reports errors in one line."""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

from . import __version__
from .align.global_opt import GlobalAlignConfig
from .atomic import atomic_dir, check_free
from .align.register import MATCHERS, RegistrationConfig
from .errors import EXIT_INCOMPLETE, EXIT_INPUT, EXIT_NOT_REGISTERED, FS3DError, InputError
from .splat.config import DEFAULT_PRESET, PRESETS, preset

__all__ = ["main", "build_parser"]


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(part) for part in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x512, got {text!r}") from None
    return width, height


def _angles(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"angles must be comma-separated degrees like -30,0,30, got {text!r}") from None


def _number(kind, low: float, high: float = float("inf"), low_inclusive: bool = True):
    """An argparse type: a ``kind`` (int or float) within ``[low, high]`` (``(low, high]`` when not ``low_inclusive``)."""
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'a whole number' if kind is int else 'a number'}, got {text!r}") from None
        if not (value == value and (value >= low if low_inclusive else value > low) and value <= high):
            bound = f"{'at least' if low_inclusive else 'more than'} {low:g}" + ("" if high == float("inf") else f" and at most {high:g}")
            raise argparse.ArgumentTypeError(f"must be {bound}, got {text}")
        return value
    return parse


_COUNT = _number(int, 1)
_STEPS = _number(int, 0, 1_000_000)
_POSITIVE = _number(float, 0.0, 1e6, low_inclusive=False)


class _Parser(argparse.ArgumentParser):
    """Argument errors as one sentence (``fs3d fuse: error: ...``), exit status 2; ``--help`` shows the usage."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="fs3d",
        description="fingersplat3d: 3D fingerprints from 2-3 uncalibrated photos of a finger.",
        epilog="Run 'fs3d COMMAND --help' for the options of each command.",
    )
    parser.add_argument("--version", action="version", version=f"fingersplat3d {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    _add_synth(commands)
    _add_fuse(commands)
    _add_info(commands)
    _add_preview(commands)
    _add_render(commands)
    _add_batch(commands)
    _add_rig(commands)
    _add_eval(commands)
    _add_register(commands)
    _add_bench(commands)
    return parser


def _add_synth(commands) -> None:
    """``fs3d synth``: its arguments."""
    synth = commands.add_parser(
        "synth", help="generate synthetic 3D fingers photographed by a rig, with exact ground truth",
        description="Generate procedural 3D fingertips with fingerprint ridges and photograph them with a "
                    "capture rig. Writes one capture folder per finger: images/, masks/, depth/ (camera-frame "
                    "z in mm), cameras.json, minutiae.json (3D and per-view pixels), mesh.ply, manifest.json. "
                    "Deterministic in --seed.")
    synth.add_argument("output", type=Path, help="capture folder to write (with --count > 1: a parent folder)")
    synth.add_argument("--rig", default="uwa", choices=("uwa", "cfpose", "ring"),
                       help="uwa: 3 cameras at -45/0/+45 deg, finger horizontal, gray 1280x1024; "
                            "cfpose: one camera, finger rolled/pitched per shot, RGB 1024x1280; "
                            "ring: cameras at --angles (default: uwa)")
    synth.add_argument("--seed", type=int, default=0, help="random seed of the first finger (default 0)")
    synth.add_argument("--count", type=_COUNT, default=1, help="number of fingers (seeds seed..seed+count-1)")
    synth.add_argument("--size", type=_size, help="image size WxH (default: the rig's)")
    synth.add_argument("--focal", type=_POSITIVE, help="focal length in pixels (default: ~36 mm of finger across the long side)")
    synth.add_argument("--angles", type=_angles, help="ring rig: camera angles in degrees around the finger axis, written with = when the first is negative: --angles=-60,-20,20,60")
    synth.add_argument("--poses", type=_COUNT, default=10, help="cfpose rig: number of shots (default 10)")
    synth.add_argument("--pattern", default="random", choices=("random", "arch", "loop", "whorl"), help="fingerprint class")
    colour = synth.add_mutually_exclusive_group()
    colour.add_argument("--rgb", dest="gray", action="store_false", default=None, help="colour images")
    colour.add_argument("--gray", dest="gray", action="store_true", help="grayscale images")
    synth.add_argument("--bits", type=int, default=8, choices=(8, 16), help="image bit depth (default 8)")
    synth.add_argument("--no-noise", action="store_true", help="no sensor noise and no blur")
    synth.add_argument("--specular", type=float, help="highlight strength (default 0.12; 0 = matte)")
    synth.add_argument("--overwrite", action="store_true", help="replace existing output folders")
    synth.set_defaults(run=_run_synth)


def _add_fuse(commands) -> None:
    """``fs3d fuse``: its arguments."""
    fuse = commands.add_parser(
        "fuse", help="3D finger from 2-N uncalibrated photos: cameras, fused point cloud, Gaussians, depth maps, mesh",
        description="Recover the cameras and one fused 3D finger surface from photos with no camera "
                    "parameters: per-view pointmaps, pairwise registration on ridge-texture correspondences, "
                    "joint global alignment (poses, focal, depth), optional ICP, then a Gaussian-splat fit to the "
                    "photos cleaned with the finger masks. Writes OUT/fused.ply, gaussians.ply (3DGS layout), "
                    "cameras.json, depth/<view>.npy (+ .png previews), report.json and, with --mesh, mesh.ply. "
                    "Without a metric hint the units are arbitrary (and say so).")
    fuse.add_argument("inputs", type=Path, nargs="+",
                      help="a capture folder, a folder of images, or image files (2-3 views of one finger)")
    fuse.add_argument("-o", "--output", type=Path, required=True, help="reconstruction folder to write")
    fuse.add_argument("--backend", default="prior", choices=("prior", "dust3r"),
                      help="pointmap backend: prior (default, needs no weights) or dust3r (needs --checkpoint)")
    fuse.add_argument("--checkpoint", type=Path,
                      help="dust3r backend: DUSt3R checkpoint file, e.g. DUSt3R_ViTLarge_BaseDecoder_512_dpt.pth "
                           "(nothing is downloaded)")
    fuse.add_argument("--device", default="auto",
                      help="where the dust3r backend and the splat fit run: auto (CUDA when available, default), cpu, "
                           "cuda or cuda:N")
    fuse.add_argument("--pair-batch", type=_COUNT, default=4, help="dust3r backend: image pairs per network batch (default 4)")
    _add_registration_arguments(fuse)
    hint = fuse.add_mutually_exclusive_group()
    hint.add_argument("--px-per-mm", type=_POSITIVE, help="metric hint: pixels per millimetre at the finger")
    hint.add_argument("--finger-width-mm", type=_POSITIVE, help="metric hint: the finger's width in millimetres")
    fuse.add_argument("--mesh", action="store_true", help="also write mesh.ply (Poisson, cleaned)")
    _add_splat_arguments(fuse)
    fuse.add_argument("--icp", action="store_true",
                      help="refine poses with Open3D ICP (guarded; off by default: on near-cylindrical fingers "
                           "it slides about the axis, see the README)")
    fuse.add_argument("--polish-iterations", "--alignment-iterations", type=_STEPS, dest="polish_iterations",
                      default=GlobalAlignConfig.polish_iterations,
                      help=f"L-BFGS iterations of each global alignment round (default {GlobalAlignConfig.polish_iterations}; "
                           "--alignment-iterations: its former name)")
    fuse.add_argument("--rig", type=Path, help="rig.json from 'fs3d rig calibrate': keep its camera poses and focal fixed "
                                               "(the views are its cameras in order)")
    fuse.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    fuse.set_defaults(run=_run_fuse)


def _add_info(commands) -> None:
    """``fs3d info``: its arguments."""
    info = commands.add_parser("info", help="describe a capture folder or a dataset folder",
                               description="Print what a capture folder (or a UWA / CFPose / plain image folder) holds.")
    info.add_argument("path", type=Path, nargs="+", help="capture folder, dataset folder or image files")
    info.add_argument("--json", action="store_true", help="machine-readable output")
    info.set_defaults(run=_run_info)


def _add_preview(commands) -> None:
    """``fs3d preview``: its arguments."""
    preview = commands.add_parser("preview", help="save a contact-sheet picture of a capture",
                                  description="Save a PNG with, for each view, the photo (ground-truth minutiae drawn: "
                                              "endings red, bifurcations blue), the mask and the depth map.")
    preview.add_argument("capture", type=Path, help="capture folder")
    preview.add_argument("-o", "--output", type=Path, help="PNG to write (default: CAPTURE/preview.png)")
    preview.add_argument("--tile-width", type=_number(int, 16, 8192), default=480, help="width of each tile in pixels")
    preview.set_defaults(run=_run_preview)


def _add_render(commands) -> None:
    """``fs3d render``: its arguments."""
    render = commands.add_parser(
        "render", help="render novel views of a fitted finger (gaussians.ply) at any angle",
        description="Render new views of the Gaussian-splat model of a reconstruction folder written by "
                    "'fs3d fuse': by default COUNT views at equal steps on the arc from the leftmost through "
                    "the front to the rightmost input camera (the paper's 12), or the views at --angles "
                    "(degrees about the finger axis, relative to the middle input camera). Writes "
                    "renders/<name>.png, <name>_alpha.png, depth/<name>.npy (+ previews), cameras.json and "
                    "contact_sheet.png.")
    render.add_argument("reconstruction", type=Path, help="reconstruction folder (holds gaussians.ply and cameras.json)")
    render.add_argument("-o", "--output", type=Path, help="folder to write (default: RECONSTRUCTION/renders)")
    render.add_argument("--count", type=_number(int, 1, 1000), default=12, help="views on the arc (default 12)")
    render.add_argument("--angles", type=_angles, help="render at these angles instead, written with = when the first "
                                                       "is negative: --angles=-22.5,22.5")
    render.add_argument("--scale", type=_number(float, 0.01, 8.0), default=1.0, help="image size relative to the input views (default 1)")
    render.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    render.set_defaults(run=_run_render)



def _run_synth(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .io.capture import write_capture
    from .synth import Appearance, SynthConfig, synthesize

    appearance = Appearance()
    if args.no_noise:
        appearance = replace(appearance, noise=0.0, blur_px=0.0)
    if args.specular is not None:
        appearance = replace(appearance, specular=args.specular)
    config = SynthConfig(rig=args.rig, size=args.size, focal=args.focal, angles=args.angles, poses=args.poses,
                         pattern=args.pattern, appearance=appearance, gray=args.gray)
    seeds = range(args.seed, args.seed + args.count)
    targets = [args.output] if args.count == 1 else [args.output / f"{args.rig}_{seed:05d}" for seed in seeds]
    for target in targets:
        check_free(target, args.overwrite)
    progress = tqdm(list(zip(seeds, targets)), desc="fs3d synth", unit="finger", disable=None if args.count == 1 else False)  # one finger: only on a terminal
    for seed, target in progress:
        start = time.perf_counter()
        result = synthesize(seed, config)
        write_capture(result.capture, target, minutiae=result.minutiae, mesh=result.surface.to_open3d(),
                      overwrite=args.overwrite, image_bits=args.bits,
                      extra_manifest={"timing_s": {**result.seconds, "total": time.perf_counter() - start}})
        if args.count == 1:
            visible = {name: sum(m["visible"] for m in entries) for name, entries in result.minutiae["views"].items()}
            print(f"wrote {target}: {len(result.capture)} views, {result.capture.metadata['pattern_class']}, "
                  f"{len(result.minutiae['minutiae_3d'])} minutiae (visible per view: {visible}) "
                  f"in {time.perf_counter() - start:.1f} s")
    return 0


def _run_fuse(args: argparse.Namespace) -> int:
    from .device import resolve_device
    from .io.datasets import load_any
    from .pipeline import FuseConfig, fuse, write_reconstruction

    check_free(args.output, args.overwrite)
    if args.backend == "dust3r" and args.checkpoint is None:
        raise InputError("--backend dust3r needs --checkpoint PATH (a DUSt3R .pth file; nothing is downloaded)")
    if args.backend != "dust3r" and args.checkpoint is not None:
        raise InputError(f"--checkpoint is only used by --backend dust3r (the {args.backend} backend has no weights)")
    resolve_device(args.device)  # an unusable device is an error before any work
    captures = load_any(args.inputs)
    if len(captures) != 1:
        raise InputError(f"{args.inputs[0]}: holds {len(captures)} captures; fuse one at a time (pass one capture's files)")
    registration = RegistrationConfig(matcher=args.matcher, guided_rounds=args.guided_rounds, seed=args.seed,
                                      global_align=GlobalAlignConfig(polish_iterations=args.polish_iterations))
    config = FuseConfig(backend=args.backend, checkpoint=None if args.checkpoint is None else str(args.checkpoint),
                        device=args.device, pair_batch=args.pair_batch, registration=registration, icp=args.icp,
                        px_per_mm=args.px_per_mm, finger_width_mm=args.finger_width_mm, mesh=args.mesh,
                        splat=_splat_config(args))
    rig = _read_rig(args.rig)
    start = time.perf_counter()
    result = fuse(captures[0], config, progress=True, rig=rig)
    write_reconstruction(result, args.output, overwrite=args.overwrite)
    alignment = result.report["alignment"]
    residual = "one view: nothing to align" if len(result.capture) == 1 else (
        "identical images: monocular mode" if alignment["mode"] == "monocular" else f"alignment residual {alignment['residual_px']:.2f} px")
    print(f"wrote {args.output}: {len(result.capture)} views, {result.report['points']} points, units {result.units}, "
          f"{residual}, {time.perf_counter() - start:.1f} s")
    if "splat" in result.report:
        splat = result.report["splat"]
        psnr = ", ".join(f"{name} {value:.1f}" for name, value in splat["psnr_in_mask_db"].items())
        print(f"  {splat['gaussians']} Gaussians ({args.splat_preset}); PSNR in the finger mask (dB): {psnr}")
    if not result.registered:
        missing = alignment.get("not_registered")
        what = f"view(s) {', '.join(missing)} could not be registered" if missing else "the views were not registered reliably"
        print(f"fs3d fuse: {what} ({alignment['reason']}); the outputs in {args.output} hold each such view "
              "apart, with depth from its pointmap alone", file=sys.stderr)
        return EXIT_NOT_REGISTERED
    return 0


def _read_rig(path: Path | None):
    if path is None:
        return None
    from .io.rig import read_rig

    return read_rig(path)


def _fuse_config(args: argparse.Namespace):
    """The fuse settings shared by ``fuse``-like commands (``batch``, ``rig calibrate``)."""
    from .pipeline import FuseConfig

    registration = RegistrationConfig(matcher=args.matcher, guided_rounds=args.guided_rounds, seed=args.seed)
    return FuseConfig(registration=registration, splat=_splat_config(args) if hasattr(args, "no_splat") else None,
                      mesh=getattr(args, "mesh", False))


def _add_registration_arguments(parser) -> None:
    parser.add_argument("--matcher", default="surface", choices=MATCHERS,
                        help="first correspondences between views: surface (default: ridge texture unwrapped on cylinder "
                             "charts, then guided matching), or a classic matcher: minutiae, sift, rootsift, akaze")
    parser.add_argument("--guided-rounds", type=_STEPS, default=RegistrationConfig.guided_rounds,
                        help=f"rounds of matching guided by the 3D model after the first alignment (default {RegistrationConfig.guided_rounds})")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random parts (RANSAC)")


def _add_splat_arguments(parser) -> None:
    splat = parser.add_argument_group("Gaussian splatting (fits gaussians.ply to the photos; on by default)")
    splat.add_argument("--no-splat", action="store_true", help="geometry only: skip the Gaussian-splat fit")
    splat.add_argument("--splat-preset", default=DEFAULT_PRESET, choices=tuple(PRESETS),
                       help=f"speed/accuracy trade (default {DEFAULT_PRESET}; measured in the README)")
    splat.add_argument("--splat-iterations", type=_STEPS, help="override the preset's optimisation steps")
    splat.add_argument("--splat-gaussians-per-cell", "--splat-budget-density", type=_POSITIVE, dest="splat_gaussians_per_cell",
                       help="override the preset's Gaussians per (ridge period/4)^2 of finger area "
                            "(--splat-budget-density: its former name)")
    splat.add_argument("--no-pose-refinement", action="store_true", help="keep the cameras fixed while fitting")


def _add_dataset_arguments(parser) -> None:
    parser.add_argument("dataset", type=Path, nargs="+",
                        help="a UWA or CFPose folder, a folder of capture folders, a CSV with columns name,paths, or image files")
    parser.add_argument("--select", help="a subset: subject=S, finger=F, capture=C, name=N, count=K (comma-separated)")
    parser.add_argument("--address", help="join this Ray cluster (e.g. ray://head:10001 or auto) instead of a local instance")
    parser.add_argument("--workers", type=_COUNT, help="local Ray: CPUs to use (default: the cores this process may use)")
    parser.add_argument("--threads-per-task", type=_COUNT, default=1,
                        help="CPUs declared per capture and torch threads inside it (default 1: one capture per core)")
    _add_registration_arguments(parser)


def _add_batch(commands) -> None:
    """``fs3d batch``: its arguments."""
    batch = commands.add_parser(
        "batch", help="reconstruct every capture of a dataset on Ray, resumable, with a results table and an HTML report",
        description="Fuse (and splat and render) every capture of a dataset, each as one Ray task (a local Ray "
                    "instance by default, --address to join a cluster). OUT/<capture>/ is written exactly as "
                    "'fs3d fuse' writes it (+ renders/ and thumbs/) and appears only when complete; a re-run "
                    "skips complete captures. A failing capture is recorded (OUT/.failed/, results.csv) and the "
                    "run goes on. Writes OUT/results.csv and OUT/report.html.")
    _add_dataset_arguments(batch)
    batch.add_argument("-o", "--output", type=Path, required=True, help="folder of the capture folders and results")
    batch.add_argument("--rig", type=Path, help="rig.json from 'fs3d rig calibrate': fixed camera poses and focal")
    batch.add_argument("--device", default="cpu",
                       help="where each capture's splat fit runs: cpu (default) or cuda (each task then declares one GPU)")
    _add_splat_arguments(batch)
    batch.add_argument("--render-count", type=_number(int, 0, 1000), default=12, help="novel views per capture (0 = none; default 12)")
    batch.add_argument("--mesh", action="store_true", help="also write mesh.ply per capture")
    batch.add_argument("--force", action="store_true", help="redo complete captures")
    batch.add_argument("--retry-failed", action="store_true", help="run again the captures that failed before")
    batch.set_defaults(run=_run_batch)


def _add_rig(commands) -> None:
    """``fs3d rig calibrate``: its arguments."""
    rig = commands.add_parser("rig", help="a fixed camera rig: calibrate it from many captures",
                              description="Tools for a fixed multi-camera rig (UWA's three cameras).")
    actions = rig.add_subparsers(dest="action", metavar="ACTION", required=True)
    calibrate = actions.add_parser(
        "calibrate", help="estimate the rig's camera poses and focal from many captures (no target needed)",
        description="Register every capture (on Ray), then fit one set of camera poses and one focal length to "
                    "the correspondences of all captures jointly, leaving out captures that disagree. Writes "
                    "rig.json (the cameras.json schema without the finger) for 'fs3d fuse --rig' and 'fs3d batch --rig'.")
    _add_dataset_arguments(calibrate)
    calibrate.add_argument("-o", "--output", type=Path, required=True, help="rig.json to write")
    calibrate.add_argument("--rounds", type=_number(int, 0, 20), default=0,
                           help="then re-match every capture through the calibrated rig and fit again, this many times "
                                "(default 0; each round costs one more registration per capture, see the README)")
    calibrate.add_argument("--overwrite", action="store_true", help="replace an existing file")
    calibrate.set_defaults(run=_run_rig_calibrate)


def _add_register(commands) -> None:
    """``fs3d register``: its arguments."""
    register = commands.add_parser(
        "register", help="carry pixel positions (minutiae) and image A into view B through the 3D model",
        description="Lift pixels of view A onto the reconstructed surface (A's depth and camera) and project them "
                    "into view B; points off the surface, outside B or hidden in B are marked, not dropped. Also "
                    "warps image A into B's frame. Writes points.csv (with --points) and warp.png.")
    register.add_argument("reconstruction", type=Path, help="a reconstruction folder from 'fs3d fuse'")
    register.add_argument("view_a", help="the view the points and the image come from")
    register.add_argument("view_b", help="the view to carry them into")
    register.add_argument("--points", type=Path, help="CSV with x,y columns (pixels of view A); other columns are kept")
    register.add_argument("--image", type=Path,
                          help="view A's photo (default: the path in cameras.json, absolute or relative to the folder)")
    register.add_argument("-o", "--output", type=Path, help="folder to write (default: REC/register_A_to_B)")
    register.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    register.set_defaults(run=_run_register)


def _find_image(folder: Path, listed: str, given: Path | None) -> Path | None:
    if given is not None:
        return given
    for candidate in (Path(listed), folder / listed, folder.parent / listed):
        if candidate.is_file():
            return candidate
    return None


def _run_register(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from .align.transfer import STATUSES, transfer_points, warp_image
    from .io.cameras import read_cameras
    from .io.depth import read_depth
    from .io.images import read_image
    from .io.points_csv import read_points_csv, write_points_csv

    folder = args.reconstruction
    if not (folder / "cameras.json").is_file():
        raise InputError(f"{folder}: not a reconstruction folder (no cameras.json; make one with 'fs3d fuse')")
    cameras = read_cameras(folder / "cameras.json")
    for name in (args.view_a, args.view_b):
        if name not in cameras.cameras:
            raise InputError(f"{folder / 'cameras.json'}: no view named {name!r}; views: {', '.join(cameras.names)}")
    if args.view_a == args.view_b:
        raise InputError("view A and view B are the same view")
    cam_a, cam_b = cameras.cameras[args.view_a], cameras.cameras[args.view_b]
    depth_a = read_depth(folder / "depth" / f"{args.view_a}.npy", (cam_a.height, cam_a.width))
    depth_b = read_depth(folder / "depth" / f"{args.view_b}.npy", (cam_b.height, cam_b.width))
    points = read_points_csv(args.points) if args.points is not None else None
    image_path = _find_image(folder, cameras.images[args.view_a], args.image)
    if points is None and image_path is None:
        raise InputError(f"nothing to carry: give --points CSV, or --image (view {args.view_a!r}'s photo "
                         f"{cameras.images[args.view_a]!r} was not found)")
    output = args.output or folder / f"register_{args.view_a}_to_{args.view_b}"
    with atomic_dir(output, overwrite=args.overwrite) as temporary:
        if points is not None:
            rows, xy = points
            uv_b, status = transfer_points(xy, depth_a, cam_a, depth_b, cam_b)
            write_points_csv(temporary / "points.csv", rows, uv_b, status)
            counts = ", ".join(f"{int((status == s).sum())} {s}" for s in STATUSES)
            print(f"{len(xy)} points from {args.view_a} to {args.view_b}: {counts}")
        if image_path is not None:
            image = read_image(image_path)
            if image.shape[:2] != (cam_a.height, cam_a.width):
                raise InputError(f"{image_path}: {image.shape[1]}x{image.shape[0]}, but view {args.view_a!r} is "
                                 f"{cam_a.width}x{cam_a.height}")
            warped, valid = warp_image(image, depth_a, cam_a, depth_b, cam_b)
            picture = np.clip(np.rint(warped * 255.0), 0, 255).astype(np.uint8)  # read_image gives [0, 1]
            if picture.ndim == 3:
                picture = picture[..., ::-1]
            cv2.imwrite(str(temporary / "warp.png"), picture)
            print(f"warped {args.view_a} into {args.view_b}'s frame: {valid.mean():.0%} of its pixels")
    print(f"wrote {output}")
    return 0


def _finished(command: str, failed: int, total: int, what: str, output: Path) -> int:
    """Exit status of an experiment that wrote its results: 0, or 4 with one line when some failed."""
    if failed:
        print(f"{command}: {failed} of {total} {what} (see {output / 'summary.md'})", file=sys.stderr)
        return EXIT_INCOMPLETE
    return 0


def _add_bench(commands) -> None:
    """``fs3d bench``: its arguments."""
    from .experiments.bench import sweep

    knobs = ("preset", "resolution", "iterations", "gaussians", "views")
    bench = commands.add_parser(
        "bench", help="the speed / accuracy trade: presets and knobs swept, time and memory against error",
        description="Fuse synthetic captures (ring rig, varied finger shapes by seed) under a baseline preset and "
                    "under a sweep of one knob at a time (presets, working resolution, fit iterations, Gaussian "
                    "budget, number of views), each run in a fresh process: stage times and peak memory against "
                    "depth error, rotation error and held-out PSNR; with --real, the rig consistency of real "
                    "captures per working resolution. Writes bench.csv, summary.md, trade_depth.png and trade_psnr.png.")
    bench.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    bench.add_argument("--seeds", type=int, default=2, help="synthetic fingers per setting (default 2)")
    bench.add_argument("--size", type=_size, default=(640, 512), help="synthetic image size WxH (default 640x512)")
    bench.add_argument("--preset", choices=sorted(PRESETS), default="fast", help="the baseline preset (default fast)")
    bench.add_argument("--presets", default="fast,balanced",
                       help="presets the preset knob compares, comma-separated (default fast,balanced)")
    bench.add_argument("--knobs", default=",".join(knobs),
                       help=f"knobs to sweep, comma-separated, from {','.join(knobs)} (default all)")
    bench.add_argument("--real", type=Path, help="a folder of real rig captures (UWA naming) for rig consistency")
    bench.add_argument("--device", default="auto", help="where the fits run: auto (CUDA when available), cpu, cuda")
    bench.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    bench.set_defaults(run=_run_bench, sweep=sweep, all_knobs=knobs)


def _run_bench(args: argparse.Namespace) -> int:
    from .experiments.bench import run_bench

    knobs = tuple(k.strip() for k in args.knobs.split(",") if k.strip())
    unknown = [k for k in knobs if k not in args.all_knobs]
    presets = tuple(p.strip() for p in args.presets.split(",") if p.strip())
    unknown_presets = [p for p in presets if p not in PRESETS]
    if unknown or unknown_presets:
        raise InputError(f"unknown {'knob' if unknown else 'preset'} {(unknown or unknown_presets)[0]!r}: choose from "
                         f"{', '.join(args.all_knobs if unknown else sorted(PRESETS))}")
    if args.seeds < 1:
        raise InputError(f"--seeds {args.seeds}: give at least 1")
    if args.real is not None and not args.real.is_dir():
        raise InputError(f"{args.real}: not a folder of real captures")
    check_free(args.output, args.overwrite)
    settings = args.sweep(args.preset, presets, knobs)
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        result = run_bench(settings, list(range(args.seeds)), folder, size=args.size, real=args.real, device=args.device)
    failed = [r for r in result["rows"] if r["status"] != "done"]
    print(f"wrote {args.output}: {len(result['rows']) - len(failed)} of {len(result['rows'])} runs")
    return _finished("fs3d bench", len(failed), len(result["rows"]), "runs failed", args.output)


def _add_eval(commands) -> None:
    """``fs3d eval depth|match|register|quality``: their arguments."""
    evaluate = commands.add_parser("eval", help="the paper's experiments: depth error, matching, view registration, image quality",
                                   description="Evaluate reconstructions against ground truth.")
    actions = evaluate.add_subparsers(dest="action", metavar="ACTION", required=True)
    depth = actions.add_parser(
        "depth", help="depth error against PolyU 3D+ height maps or a capture's depth/",
        description="Reconstruct each image alone (monocular mode) and compare its depth with the height map of the "
                    "same name in --truth (PolyU 3D+ .mat files: the variable 'fc', flipped upside down), or fuse "
                    "capture folders and compare every view with its depth/. Mean absolute error after a "
                    "least-squares scale + shift, after a scale only, and weighted by the reconstruction's "
                    "confidence. Writes depth_errors.csv, summary.md and error_maps/.")
    depth.add_argument("inputs", nargs="+", type=Path, help="images or folders of images (with --truth), or capture folders")
    depth.add_argument("--truth", type=Path, help="folder of .mat height maps named after the images")
    depth.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    depth.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    depth.set_defaults(run=_run_eval_depth)
    _add_eval_match(actions)
    _add_eval_register(actions)
    _add_eval_quality(actions)


def _add_eval_quality(actions) -> None:
    quality = actions.add_parser(
        "quality", help="leave-one-view-out renders against the real views: PSNR, SSIM, NFIQ2",
        description="Register every view of each capture, then for each view fit Gaussians to the other views only, "
                    "render the left-out view at its camera (placed, and aligned to the photo with the model frozen) "
                    "and score it against the photo inside the finger mask: PSNR, SSIM, and NFIQ2 of the photo and "
                    "of the render as contact-like prints. Writes quality.csv, views/ and summary.md.")
    quality.add_argument("inputs", nargs="+", type=Path,
                         help="capture folders, folders of UWA / CFPose images, or image files of one capture")
    quality.add_argument("--splat-preset", choices=sorted(PRESETS), default="fast",
                         help="Gaussian fit preset for the left-out fits (default fast)")
    quality.add_argument("--no-nfiq2", action="store_true", help="PSNR and SSIM only")
    quality.add_argument("--device", default="auto", help="where the fits run: auto (CUDA when available), cpu, cuda")
    quality.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    quality.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    quality.set_defaults(run=_run_eval_quality)


def _named_captures(inputs: list[Path]) -> list[tuple[str, object]]:
    """``(name, capture)`` for everything the inputs hold (a capture folder is named after it)."""
    from .io.capture import is_capture_folder
    from .io.datasets import load_any

    folders = [p for p in inputs if p.is_dir()]
    files = [p for p in inputs if not p.is_dir()]
    named = []
    for folder in folders:
        captures = load_any(folder)
        for index, capture in enumerate(captures):
            name = capture.metadata.get("name") or (folder.name if len(captures) == 1 else f"{folder.name}_{index}")
            named.append((folder.name if is_capture_folder(folder) else name, capture))
    if files:
        captures = load_any(files)
        for index, capture in enumerate(captures):
            named.append((capture.metadata.get("name") or (files[0].stem if len(captures) == 1 else f"{files[0].stem}_{index}"),
                          capture))
    return named


def _run_eval_quality(args: argparse.Namespace) -> int:
    from .experiments.quality import run_quality_evaluation
    from .pipeline import FuseConfig

    if not args.no_nfiq2:
        _nbis_needed("fs3d eval quality (or give --no-nfiq2)")
    check_free(args.output, args.overwrite)
    captures = _named_captures(args.inputs)
    config = FuseConfig(splat=preset(args.splat_preset), device=args.device)
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        rows = run_quality_evaluation(captures, folder, config, nfiq2=not args.no_nfiq2)
    done = [r for r in rows if r["status"] == "done"]
    if done:
        print(f"{len(done)} views: mean PSNR {statistics.mean(r['psnr'] for r in done):.2f} dB, "
              f"SSIM {statistics.mean(r['ssim'] for r in done):.3f} (aligned)")
    print(f"wrote {args.output}")
    return _finished("fs3d eval quality", len(rows) - len(done), len(rows), "views could not be scored", args.output)


def _add_eval_register(actions) -> None:
    register = actions.add_parser(
        "register", help="minutiae carried between views: 3D model vs rigid 2D and TPS baselines",
        description="Carry minutiae of view A into view B through each reconstruction (depth + cameras) and with "
                    "the paper's 2D baselines (a RANSAC similarity and a thin-plate spline, fitted to the mates and "
                    "cross-validated), and measure the mean pixel distance to their mates in B. Mates: --mates CSV, "
                    "else ground truth (minutiae.json beside the capture's images/, or --truth), else mindtct minutiae "
                    "of both photos paired as bozorth3 pairs them (the paper's UWA* protocol). Writes "
                    "register_errors.csv, mates/, pictures/ and summary.md.")
    register.add_argument("reconstructions", nargs="+", type=Path, help="reconstruction folders from 'fs3d fuse'")
    register.add_argument("--pairs", type=_view_pairs,
                          help="view pairs as A:B, comma-separated (default: the middle camera to each other camera)")
    register.add_argument("--mates", type=Path, help="CSV with columns view_a, view_b, x_a, y_a, x_b, y_b")
    register.add_argument("--truth", type=Path, help="minutiae.json with per-view ground truth (fs3d synth)")
    register.add_argument("--matcher", action="store_true",
                          help="mates from mindtct + bozorth3-style pairing even where ground truth exists (UWA*)")
    register.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    register.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    register.set_defaults(run=_run_eval_register)


def _view_pairs(text: str) -> list[tuple[str, str]]:
    pairs = []
    for item in text.split(","):
        a, colon, b = item.strip().partition(":")
        if not colon or not a or not b or a == b:
            raise argparse.ArgumentTypeError(f"{item!r}: give pairs of two different views as A:B, e.g. center:left")
        pairs.append((a, b))
    return pairs


def _run_eval_register(args: argparse.Namespace) -> int:
    from .experiments.register import run_register_evaluation

    check_free(args.output, args.overwrite)
    if args.matcher and (args.mates is not None or args.truth is not None):
        raise InputError("--matcher takes the mates from the photos: leave out --mates and --truth")
    if args.mates is None and args.truth is None:
        _nbis_needed("fs3d eval register (without --mates or --truth)")
    if args.mates is not None and len(args.reconstructions) > 1:
        raise InputError("--mates holds one reconstruction's mates: give one reconstruction with it")
    for path in (args.mates, args.truth):
        if path is not None and not path.is_file():
            raise InputError(f"{path}: not found")
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        rows = run_register_evaluation(args.reconstructions, folder, pairs=args.pairs, mates_csv=args.mates,
                                       truth=args.truth, matcher=args.matcher)
    done = [r for r in rows if r["status"] == "done"]
    for method in ("3D", "rigid 2D", "TPS"):
        values = [r["mean_px"] for r in done if r["method"] == method]
        if values:
            print(f"{method}: mean {statistics.mean(values):.2f} px over {len(values)} view pair(s)")
    print(f"wrote {args.output}")
    return _finished("fs3d eval register", len(rows) - len(done), len(rows), "could not be scored", args.output)


def _add_eval_match(actions) -> None:
    from .experiments.match import DEFAULT_ANGLES, UWA_NAMING

    match = actions.add_parser(
        "match", help="mindtct + bozorth3 matching of photos and synthesized views: EER, FMR, DET",
        description="Make a contact-like print (8-bit gray, ridges dark, ~500 ppi, tip up) of every photo, find its "
                    "minutiae (mindtct) and NFIQ2, and score every two photos of different captures seen by the same "
                    "camera with bozorth3: genuine when the finger is the same (read from the file names), impostor "
                    "otherwise. With --reconstructions, each model is rendered at --angles about its rig axis and "
                    "compared with the real photos of the finger's other captures (and of other fingers). Writes "
                    "scores.csv, prints.csv, prints/, summary.md (EER, FNMR at FMR 1 %% and 0.01 %%, FMR_zero, "
                    "scores by angle) and det.png.")
    match.add_argument("inputs", nargs="+", type=Path, help="photos, or folders of photos")
    match.add_argument("--reconstructions", nargs="+", type=Path, default=[], metavar="REC",
                       help="reconstruction folders from 'fs3d fuse' (with their Gaussians) to synthesize views from")
    match.add_argument("--naming", default=UWA_NAMING,
                       help="regular expression on file stems with named groups 'capture' and 'finger' (or "
                            "'subject' and 'hand'), optional 'view' and 'session'; default: the UWA 3D/2D naming "
                            "subject_finger_capture_session_frame")
    match.add_argument("--views", help="comma-separated view labels to use (e.g. 0,1,2: UWA's plain-light frames)")
    match.add_argument("--angles", type=_angle_list, default=DEFAULT_ANGLES,
                       help="render angles in degrees about the rig axis, comma-separated, as --angles=-30,0,30 (default "
                            f"{','.join(f'{a:g}' for a in DEFAULT_ANGLES)})")
    match.add_argument("--ridges", choices=("bright", "dark"), default="bright",
                       help="how ridge crests look in the photos (default bright: contactless rigs' plain light)")
    match.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    match.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    match.set_defaults(run=_run_eval_match)


def _angle_list(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give angles in degrees separated by commas, e.g. -30,0,30") from None
    if not values or not all(abs(v) < 180 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: give angles between -180 and 180 degrees")
    return values


def _nbis_needed(command: str) -> None:
    from .eval.fingerprint import nbis_available

    if not nbis_available():
        raise InputError(f"'{command}' needs NIST's tools from the nbis-py package: pip install nbis-py==0.1.3")


def _run_eval_match(args: argparse.Namespace) -> int:
    from .experiments.match import parse_samples, run_match_evaluation
    from .io.images import find_files

    _nbis_needed("fs3d eval match")
    check_free(args.output, args.overwrite)
    views = {v.strip() for v in args.views.split(",") if v.strip()} if args.views else None
    samples, unparsed = parse_samples(find_files(args.inputs), args.naming, views)
    for path in unparsed:
        print(f"fs3d eval match: {path.name} does not follow the naming pattern; skipped", file=sys.stderr)
    if len({s.capture for s in samples}) < 2:
        raise InputError(f"{len(samples)} photos from {len({s.capture for s in samples})} capture(s): matching needs "
                         "photos of at least two captures, named so that the finger and capture can be read")
    for folder in args.reconstructions:
        if not (folder / "cameras.json").is_file():
            raise InputError(f"{folder}: not a reconstruction folder (no cameras.json; make one with 'fs3d fuse')")
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        summary = run_match_evaluation(samples, folder, reconstructions=args.reconstructions, angles=args.angles,
                                       naming=args.naming, ridges=args.ridges)
    for protocol, rates in summary["protocols"].items():
        eer = "no EER (genuine or impostor pairs missing)" if rates.get("eer") is None else f"EER {rates['eer']:.1%}"
        print(f"{protocol}: {rates['genuine']} genuine, {rates['impostor']} impostor comparisons; {eer}")
    print(f"wrote {args.output}")
    if not summary["protocols"]:
        print("fs3d eval match: no two prints could be compared (see summary.md)", file=sys.stderr)
        return EXIT_INCOMPLETE
    return _finished("fs3d eval match", len(summary["failed"]), summary["prints"], "photos or renders gave no print",
                     args.output)


def _run_eval_depth(args: argparse.Namespace) -> int:
    from .experiments.depth import capture_cases, polyu_cases, run_depth_evaluation
    from .pipeline import FuseConfig

    check_free(args.output, args.overwrite)
    unpaired = ([], [])
    if args.truth is not None:
        cases, *unpaired = polyu_cases(args.inputs, args.truth)
        if not cases:
            raise InputError(f"no image in {', '.join(map(str, args.inputs))} has a height map of the same name in {args.truth}")
        for path in unpaired[0]:
            print(f"fs3d eval depth: {path} has no height map in {args.truth}; skipped", file=sys.stderr)
        for path in unpaired[1]:
            print(f"fs3d eval depth: {path} has no image; skipped", file=sys.stderr)
    else:
        cases = capture_cases(args.inputs)
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:  # complete or absent
        rows = run_depth_evaluation(cases, folder, FuseConfig(splat=None), unpaired=tuple(unpaired))
    done = [r for r in rows if r["status"] == "done"]
    if done:
        print(f"wrote {args.output}: {len(done)} of {len(rows)} scored; mean MAE after scale + shift "
              f"{statistics.mean(r['mae_scale_shift'] for r in done):.4f}, confidence-weighted "
              f"{statistics.mean(r['mae_weighted'] for r in done):.4f} (ground-truth units)")
    return _finished("fs3d eval depth", len(rows) - len(done), len(rows), "could not be scored", args.output)


def _run_batch(args: argparse.Namespace) -> int:
    from .batch.run import run_batch
    from .batch.task import BatchOptions
    from .io.jobs import list_jobs

    jobs = list_jobs(args.dataset, args.select)
    if args.device not in ("cpu", "cuda") and not args.device.startswith("cuda:"):
        raise InputError(f"--device {args.device!r}: use cpu or cuda")
    config = replace(_fuse_config(args), device=args.device)
    options = BatchOptions(fuse=config, render=0 if args.no_splat else args.render_count, rig=_read_rig(args.rig),
                           threads=args.threads_per_task, force=args.force)
    run = run_batch(jobs, args.output, options, address=args.address, num_cpus=args.workers, retry_failed=args.retry_failed)
    done = sum(row["status"] == "done" for row in run.rows)
    print(f"wrote {args.output}: {done} of {len(jobs)} captures complete ({run.submitted} run now, {run.skipped_complete} "
          f"complete before, {run.skipped_failed} failed before) in {run.engine['wall_s']:.1f} s; "
          f"{args.output / 'results.csv'}, {args.output / 'report.html'}")
    if done < len(jobs):
        print(f"fs3d batch: {len(jobs) - done} of {len(jobs)} captures failed or were not registered; "
              f"{args.output / 'results.csv'} says why", file=sys.stderr)
        return EXIT_INCOMPLETE
    return 0


def _run_rig_calibrate(args: argparse.Namespace) -> int:
    from .align.rig import calibrate_rig
    from .batch.engine import ray_map
    from .io.jobs import list_jobs
    from .io.rig import write_rig

    check_free(args.output, args.overwrite)
    jobs = list_jobs(args.dataset, args.select)
    config = _fuse_config(args)
    captures, failures = [], {}

    def on_result(job, capture, error):
        if error is not None:
            failures[job.name] = error
        elif not all(capture.alignment.aligned):
            failures[job.name] = "not every view registered"
        else:
            captures.append(capture)

    def register(selected, rig=None, desc="fs3d rig calibrate"):
        return ray_map(_register_job, selected, (config, args.threads_per_task, rig), on_result, address=args.address,
                       cpus_per_task=args.threads_per_task, num_cpus=args.workers, desc=desc)

    run = register(jobs)
    names = sorted({c.view_names for c in captures})
    if len(captures) < 2:
        print(f"fs3d rig calibrate: only {len(captures)} of {len(jobs)} captures registered with all their views; "
              "a rig needs at least 2", file=sys.stderr)
        return EXIT_NOT_REGISTERED
    if len(names) != 1:
        raise InputError(f"the captures do not share one set of view names ({names}); a rig's captures must")
    start = time.perf_counter()
    fit = replace(GlobalAlignConfig(), polish_iterations=400, polish_rounds=3)
    calibration = calibrate_rig(sorted(captures, key=lambda c: c.name), names[0], fit)
    for round_ in range(args.rounds):  # re-match through the rig, fit again (its matches snap to the right ridges)
        used = [job for job in jobs if job.name in calibration.used]
        captures.clear()
        register(used, calibration.rig, desc=f"fs3d rig calibrate: round {round_ + 1}")
        if len(captures) < 2:
            break
        calibration = calibrate_rig(sorted(captures, key=lambda c: c.name), names[0], fit)
    rig = calibration.rig
    rig.info.update(failed=failures, rounds=args.rounds, register_seconds=round(run["wall_s"], 1),
                    fit_seconds=round(time.perf_counter() - start, 1))
    write_rig(args.output, rig)
    from .eval.poses import rotation_angle_deg

    angles = ", ".join(f"{rig.names[i]}-{rig.names[j]} {rotation_angle_deg(rig.rotations[i], rig.rotations[j]):.2f} deg"
                       for i in range(len(rig.names)) for j in range(i + 1, len(rig.names)))
    print(f"wrote {args.output}: {len(calibration.used)} captures used ({len(calibration.left_out)} left out, "
          f"{len(failures)} not registered), focal {rig.focal:.1f} px, {angles}")
    return 0


def _register_job(job, config, threads: int, rig=None):
    """A Ray task of 'fs3d rig calibrate': one capture registered (what the calibration pools)."""
    from .device import use_threads
    from .io.jobs import load_job
    from .pipeline import register_capture

    use_threads(threads)
    return register_capture(load_job(job), config, rig)


def _splat_config(args: argparse.Namespace):
    """The splat settings from ``--splat-*`` (None with ``--no-splat``)."""
    if args.no_splat:
        return None
    return preset(args.splat_preset, iterations=args.splat_iterations, gaussians_per_cell=args.splat_gaussians_per_cell,
                  refine_poses=False if args.no_pose_refinement else None)


def _describe(capture) -> dict:
    views = [{"name": v.name, "size": f"{v.width}x{v.height}", "channels": v.channels,
              "mask": v.mask is not None, "camera": v.camera is not None, "depth": v.depth is not None}
             for v in capture.views]
    keys = ("dataset", "rig", "seed", "pattern_class", "ridge_period_mm", "units", "subject", "finger", "capture")
    return {"views": views, **{k: capture.metadata[k] for k in keys if k in capture.metadata}}


def _run_info(args: argparse.Namespace) -> int:
    from .io.capture import capture_files, is_capture_folder, read_capture
    from .io.minutiae import read_minutiae

    paths = args.path
    if len(paths) == 1 and is_capture_folder(paths[0]):
        capture = read_capture(paths[0])
        report = {"path": str(paths[0]), "kind": "capture folder", **_describe(capture)}
        files = capture_files(paths[0])
        if files.minutiae is not None:
            minutiae = read_minutiae(files.minutiae)
            report["minutiae"] = len(minutiae.get("minutiae_3d", []))
            report["visible_minutiae"] = {k: sum(e["visible"] for e in v) for k, v in minutiae.get("views", {}).items()}
        captures = [report]
    else:
        from .io.datasets import load_any

        captures = [{"kind": "dataset capture", **_describe(c)} for c in load_any(paths)]
    if args.json:
        print(json.dumps(captures, indent=2))
    else:
        for report in captures:
            head = {k: v for k, v in report.items() if k != "views"}
            print(", ".join(f"{k}: {v}" for k, v in head.items()))
            for view in report["views"]:
                flags = [k for k in ("mask", "camera", "depth") if view[k]]
                print(f"  {view['name']}: {view['size']}, {'gray' if view['channels'] == 1 else 'RGB'}"
                      + (f", with {', '.join(flags)}" if flags else ""))
    return 0


def _run_preview(args: argparse.Namespace) -> int:
    from .io.capture import capture_files, read_capture
    from .io.images import write_image
    from .io.minutiae import read_minutiae
    from .viz import contact_sheet

    capture = read_capture(args.capture)
    files = capture_files(args.capture)
    minutiae = read_minutiae(files.minutiae) if files.minutiae is not None else None
    sheet = contact_sheet(capture, minutiae, tile_width=args.tile_width)
    output = args.output or args.capture / "preview.png"
    write_image(output, sheet.astype("float32") / 255.0)
    print(f"wrote {output}")
    return 0


def _run_render(args: argparse.Namespace) -> int:
    from .io.cameras import read_cameras
    from .io.gaussians_ply import read_gaussians_ply
    from .io.renders import write_renders
    from .splat.camera_path import cameras_at_angles
    from .device import resolve_device
    from .splat.novel import arc_views, render_views

    folder = args.reconstruction
    for needed in ("gaussians.ply", "cameras.json"):
        if not (folder / needed).is_file():
            hint = " (fuse it without --no-splat)" if needed == "gaussians.ply" else ""
            raise InputError(f"{folder / needed}: missing; 'fs3d render' needs a reconstruction folder from 'fs3d fuse'{hint}")
    output = args.output or folder / "renders"
    check_free(output, args.overwrite)
    cameras = read_cameras(folder / "cameras.json")
    gaussians = read_gaussians_ply(folder / "gaussians.ply").to(resolve_device("auto"))
    inputs = [c.scaled(args.scale) if args.scale != 1 else c for c in cameras.cameras.values()]
    start = time.perf_counter()
    try:
        if args.angles:
            names = [f"angle_{a:+07.2f}".replace(".", "p") for a in args.angles]
            views = render_views(gaussians, list(zip(names, cameras_at_angles(inputs, args.angles))))
        else:
            views = arc_views(gaussians, inputs, args.count)
    except ValueError as error:  # one camera, or cameras that did not align: no rig axis to turn about
        raise InputError(f"{folder / 'cameras.json'}: cannot place novel views: {error}") from None
    write_renders(output, views, cameras.units, cameras.scale_mm_per_unit, overwrite=args.overwrite)
    print(f"wrote {output}: {len(views)} views of {len(gaussians)} Gaussians in {time.perf_counter() - start:.1f} s")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # --help and --version exit 0 as argparse does; argument errors return 2
        if stop.code == EXIT_INPUT:
            return EXIT_INPUT
        raise
    try:
        return args.run(args)
    except (FS3DError, FileExistsError, FileNotFoundError) as error:
        print(f"fs3d {args.command}: error: {error}", file=sys.stderr)
        return EXIT_INPUT
    except BrokenPipeError:  # output piped into head & co.
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print("fs3d: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
