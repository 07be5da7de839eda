"""Degraded copies of a folder of photos, for registration under worse light, noise and size than the dev captures.

    python3 tools/degrade_photos.py SRC OUT --kind noise|small|half|dark|faint|hazy|thin|thick|quarter|roll [--seed 0]
                                    [--finger-axis auto|horizontal|vertical]
    python3 tools/bench_real.py --data OUT

Every image of SRC (its own files, sorted) is written to OUT under its own name: ``noise`` adds Gaussian noise of
sigma 8 grey levels and saves at JPEG quality 60; ``small`` shrinks to 0.6x (area filter, JPEG 95), ``half`` to 0.5x (1280x1024 -> 640x512, the size of the
synthetic tables); ``dark`` keeps
0.3x the light with noise of sigma 3 (JPEG 90); ``faint`` blurs by sigma 1 px, halves the contrast about the image's
mean and adds noise of sigma 4 (JPEG 95); ``hazy`` blurs by 1.3 px, keeps 0.4 of the contrast about the mean (a dark
background lifted to a third of the skin's level, as under haze or glare) and adds noise of sigma 5 (JPEG 90). Noise draws from ``numpy.random.default_rng(seed)`` in file order.
``thin`` and ``thick`` stretch each photo across the finger by 0.8x / 1.25x about its centre (``--finger-axis``: the
finger along the photo's rows or columns; ``auto``, along its long side, as in a rig's frames, UWA's included), the
size kept (JPEG 95): the photos of a finger scaled by that factor about its axis, the rig's turns kept and the focal
scaled (:mod:`fingersplat3d.experiments.thickness`). ``quarter`` turns every photo a quarter clockwise (a phone held
upright); ``roll`` turns each photo about its centre by the angle of its camera, ``ROLLS[frame % 3]`` (0, +25, -15
degrees; the frame from a name ending ``_<frame>``, as UWA's, else the file's place), the corners filled with the
border's median: each camera rolled about its optical axis, as a hand-held phone is, and together another rig
(:mod:`fingersplat3d.experiments.turned`); both lossless but for the JPEG (quality 95).
The measured rows are in docs/measurements.md (the same captures mirrored, turned or degraded; thinner and thicker).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from fingersplat3d.errors import run_script
from fingersplat3d.experiments.thickness import FINGER_AXES, stretched_across
from fingersplat3d.experiments.turned import quarter_turned, rolled_in_plane

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff")
KINDS = ("noise", "small", "half", "dark", "faint", "hazy", "thin", "thick", "quarter", "roll")
ROLLS = (0.0, 25.0, -15.0)  # degrees, camera k % 3 of a capture


def frame_of(path: Path, place: int) -> int:
    """The camera of a photo: the number after the stem's last underscore (UWA's ``..._<frame>``), else its place."""
    tail = path.stem.rsplit("_", 1)[-1]
    return int(tail) if "_" in path.stem and tail.isdigit() else place


def degrade(image: np.ndarray, kind: str, rng: np.random.Generator, finger_axis: str = "auto",
            frame: int = 0) -> tuple[np.ndarray, int]:
    """The degraded 8-bit image and the JPEG quality to save it at (``frame``: the camera, for ``roll``)."""
    if kind == "quarter":
        return quarter_turned(image), 95
    if kind == "roll":
        return rolled_in_plane(image, ROLLS[frame % len(ROLLS)]), 95
    pixels = image.astype(np.float32)
    if kind == "noise":
        return np.clip(pixels + rng.normal(0, 8, pixels.shape), 0, 255).astype(np.uint8), 60
    if kind in ("small", "half"):
        factor = 0.6 if kind == "small" else 0.5
        return np.clip(cv2.resize(pixels, None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA), 0, 255).astype(np.uint8), 95
    if kind in ("faint", "hazy"):
        sigma, contrast, noise, quality = (1.0, 0.5, 4, 95) if kind == "faint" else (1.3, 0.4, 5, 90)
        pixels = cv2.GaussianBlur(pixels, (0, 0), sigma)
        mean = pixels.mean()
        pixels = mean + contrast * (pixels - mean) + rng.normal(0, noise, pixels.shape)
        return np.clip(pixels, 0, 255).astype(np.uint8), quality
    if kind in ("thin", "thick"):
        return stretched_across(image, 0.8 if kind == "thin" else 1.25, finger_axis), 95
    return np.clip(pixels * 0.3 + rng.normal(0, 3, pixels.shape), 0, 255).astype(np.uint8), 90


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("src", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--kind", choices=KINDS, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--finger-axis", choices=FINGER_AXES, default="auto",
                        help="thin, thick: the finger along the photos' rows, columns, or long side (auto)")
    args = parser.parse_args()
    files = sorted(p for p in args.src.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES) if args.src.is_dir() else []
    if not files:
        print(f"degrade_photos: {args.src}: no images", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    for place, path in enumerate(files):
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            print(f"degrade_photos: {path}: not a readable image", file=sys.stderr)
            return 2
        degraded, quality = degrade(image, args.kind, rng, args.finger_axis, frame_of(path, place))
        cv2.imwrite(str(args.out / (path.stem + ".jpg")), degraded, [cv2.IMWRITE_JPEG_QUALITY, quality])
    print(f"wrote {len(files)} images to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
