"""Regenerate the shipped sample captures in ``data_samples/`` (deterministic).

    python tools/make_samples.py            # writes data_samples/<name>/ for each sample below

Each sample is a full capture folder with ground truth (depth, cameras, minutiae, mesh), small
enough to ship: two UWA-like three-view captures at 640x512 and one CFPose-like capture.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tqdm import tqdm

from fingersplat3d.errors import run_script
from fingersplat3d.io.capture import write_capture
from fingersplat3d.synth import SynthConfig, synthesize

SAMPLES = {
    "uwa_seed0": (0, SynthConfig(rig="uwa", size=(640, 512), pattern="loop", mesh_detail=0.6)),
    "uwa_seed1": (1, SynthConfig(rig="uwa", size=(640, 512), pattern="whorl", mesh_detail=0.6)),
    "cfpose_seed2": (2, SynthConfig(rig="cfpose", size=(320, 400), poses=6, mesh_detail=0.6)),
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "data_samples")
    args = parser.parse_args(argv)
    for name, (seed, config) in tqdm(SAMPLES.items(), desc="samples", unit="capture"):
        result = synthesize(seed, config)
        write_capture(result.capture, args.out / name, minutiae=result.minutiae, mesh=result.surface.to_open3d(),
                      rolled_print=result.rolled.image, overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
