"""Option groups several commands share (registration, splatting, dataset selection) and the configs they make."""
from __future__ import annotations

import argparse
from pathlib import Path

from .types import COUNT, POSITIVE, SEED, STEPS, number

__all__ = ["add_registration_arguments", "photometric_config", "add_splat_arguments", "add_dataset_arguments", "splat_config", "fuse_config", "ridge_px", "splat_ridge_px", "read_rig"]


def add_registration_arguments(parser) -> None:
    from ..align.registration_config import MATCHERS, RegistrationConfig
    from ..working_scale import RIDGE_PX

    parser.add_argument("--matcher", default="surface", choices=MATCHERS,
                        help="first correspondences between views: surface (default: ridge texture unwrapped on cylinder "
                             "charts, then guided matching), or a classic matcher: minutiae, sift, rootsift, akaze")
    parser.add_argument("--guided-rounds", type=STEPS, default=RegistrationConfig.guided_rounds,
                        help=f"rounds of matching guided by the 3D model after the first alignment (default {RegistrationConfig.guided_rounds}; "
                             f"two views with the focal held: up to {RegistrationConfig.extra_rounds} more while their turn still moves)")
    parser.add_argument("--photometric", action="store_true",
                        help="after the guided rounds, refine each view's surface densely on the ridge texture every other "
                             "view sees (~2 s; brings the views' ridges into phase, for texturing and prints; it does not "
                             "move the turns, and on synthetic fingers it does not make the depth better: docs/fuse.md)")
    parser.add_argument("--seed", type=SEED, default=0, help="seed of the random parts (RANSAC)")
    parser.add_argument("--ridge-px", type=number(float, 0.0, 1000.0), default=RIDGE_PX,
                        help=f"working pixels per ridge period of the geometry (default {RIDGE_PX:g}): photos that sample "
                             "the ridges more finely are scaled down for the masks, registration and alignment, and the "
                             "outputs put back on the photos' grid; 0 keeps the photos' own resolution")


def photometric_config(args: argparse.Namespace):
    """The dense photometric refinement ``--photometric`` asks for (off: no iterations)."""
    from ..align.solve.photometric import PhotometricConfig

    return PhotometricConfig() if getattr(args, "photometric", False) else PhotometricConfig(iterations=0)


def add_splat_arguments(parser) -> None:
    from ..splat.config import DEFAULT_PRESET, PRESETS
    from ..working_scale import SPLAT_RIDGE_PX

    splat = parser.add_argument_group("Gaussian splatting (fits gaussians.ply to the photos; on by default)")
    splat.add_argument("--no-splat", action="store_true", help="geometry only: skip the Gaussian-splat fit")
    splat.add_argument("--splat-preset", default=DEFAULT_PRESET, choices=tuple(PRESETS),
                       help=f"speed/accuracy trade (default {DEFAULT_PRESET}; measured in the README)")
    splat.add_argument("--splat-iterations", type=STEPS, help="override the preset's optimisation steps")
    splat.add_argument("--splat-ridge-px", type=number(float, 0.0, 1000.0), default=SPLAT_RIDGE_PX,
                       help=f"working pixels per ridge period of the splat fit (default {SPLAT_RIDGE_PX:g}: camera photos "
                            "as they are); 0 keeps the photos' own resolution")
    splat.add_argument("--splat-gaussians-per-cell", "--splat-budget-density", type=POSITIVE, dest="splat_gaussians_per_cell",
                       help="override the preset's Gaussians per (ridge period/4)^2 of finger area "
                            "(--splat-budget-density: its former name)")
    splat.add_argument("--pose-refinement", action=argparse.BooleanOptionalAction, default=None,
                       help="refine the camera poses while fitting (off by default: the registration's poses fit the "
                            "ridges better than the refinement leaves them; measured in the README)")
    splat.add_argument("--no-shading", action="store_true",
                       help="one colour per Gaussian whatever the view (the paper's plain SH degree 0), instead of the "
                            "skin darkening with the slant at which each camera sees it")
    splat.add_argument("--no-exposures", action="store_true",
                       help="fit the photos as they are (the paper's), instead of each divided by its camera's "
                            "exposure, estimated on the skin two views see, so that the Gaussians' colours are the "
                            "skin at the views' mean exposure")


def add_dataset_arguments(parser) -> None:
    parser.add_argument("dataset", type=Path, nargs="+",
                        help="a UWA or CFPose folder, a folder of capture folders, a CSV with columns name,paths, or image files")
    parser.add_argument("--select", help="a subset: subject=S, finger=F, capture=C, name=N, count=K (comma-separated)")
    parser.add_argument("--address", help="join this Ray cluster (e.g. ray://head:10001 or auto) instead of a local instance")
    parser.add_argument("--workers", type=COUNT, help="local Ray: CPUs to use (default: the cores this process may use)")
    parser.add_argument("--threads-per-task", type=COUNT, default=1,
                        help="CPUs declared per capture and torch threads inside it (default 1: one capture per core)")
    add_registration_arguments(parser)


def splat_config(args: argparse.Namespace):
    """The splat settings from ``--splat-*`` (None with ``--no-splat``)."""
    if args.no_splat:
        return None
    from ..splat.config import preset

    return preset(args.splat_preset, iterations=args.splat_iterations, gaussians_per_cell=args.splat_gaussians_per_cell,
                  refine_poses=args.pose_refinement,
                  facing_shading=False if getattr(args, "no_shading", False) else None,
                  match_exposures=False if getattr(args, "no_exposures", False) else None)


def fuse_config(args: argparse.Namespace):
    """The fuse settings shared by ``fuse``-like commands (``batch``, ``rig calibrate``)."""
    from ..align.register import RegistrationConfig
    from ..pipeline import FuseConfig

    registration = RegistrationConfig(matcher=args.matcher, guided_rounds=args.guided_rounds, seed=args.seed,
                                      photometric=photometric_config(args))
    return FuseConfig(registration=registration, splat=splat_config(args) if hasattr(args, "no_splat") else None,
                      mesh=getattr(args, "mesh", False), ridge_px=ridge_px(args), splat_ridge_px=splat_ridge_px(args))


def ridge_px(args: argparse.Namespace) -> float | None:
    """``--ridge-px`` as the fuse settings take it (0: None, the photos' own resolution)."""
    return args.ridge_px or None


def splat_ridge_px(args: argparse.Namespace) -> float | None:
    """``--splat-ridge-px`` as the fuse settings take it (0: None; the default where a command has no splat options)."""
    from ..working_scale import SPLAT_RIDGE_PX

    return getattr(args, "splat_ridge_px", SPLAT_RIDGE_PX) or None


def read_rig(path: Path | None):
    if path is None:
        return None
    from ..io.rig import read_rig

    return read_rig(path)
