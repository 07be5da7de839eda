"""Picture of ``fs3d fuse`` on a real UWA capture (for the README): photos, recovered depth, cameras.

    python3 tools/figure_real.py ../shared/data/uwa-real-dev 2_2_8_1 out/real_2_2_8_1.png

The picture shows real fingerprints: write it outside the repository (the captures are read at
run time only, never kept in it).

Top row: the three photos with their finger outline; bottom row: each view's recovered depth
(colour-mapped, as the depth previews of a reconstruction folder) and the relative angles the
registration found. Geometry only.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from fingersplat3d.errors import run_script
from fingersplat3d.eval.poses import rotation_angle_deg
from fingersplat3d.io import depth_colormap, write_image
from fingersplat3d.io.datasets import load_uwa
from fingersplat3d.pipeline import FuseConfig, fuse


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("data", type=Path)
    parser.add_argument("capture")
    parser.add_argument("output", type=Path)
    parser.add_argument("--width", type=int, default=400, help="tile width in pixels")
    args = parser.parse_args()
    (capture,) = [c for c in load_uwa(args.data) if c.metadata["name"] == args.capture]
    result = fuse(capture, FuseConfig(splat=None))
    rotations = [camera.rotation for camera in result.cameras]
    tiles_top, tiles_bottom = [], []
    for index, (view, depth) in enumerate(zip(result.capture.views, result.depths)):
        photo = cv2.cvtColor((np.clip(view.image, 0, 1) * 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
        contours, _ = cv2.findContours(view.mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(photo, contours, -1, (0, 200, 255), 3)
        colour = (depth_colormap(depth) * 255).astype(np.uint8)[..., ::-1]
        label = f"{view.name}" if index == 0 else f"{view.name}: {rotation_angle_deg(rotations[index], rotations[0]):.1f} deg from f0"
        for tiles, image in ((tiles_top, photo), (tiles_bottom, colour)):
            scale = args.width / image.shape[1]
            small = cv2.resize(image, (args.width, int(round(image.shape[0] * scale))), interpolation=cv2.INTER_AREA)
            tiles.append(small)
        cv2.putText(tiles_top[-1], label, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 255, 255), 1, cv2.LINE_AA)
    height = max(t.shape[0] for t in tiles_top + tiles_bottom)
    pad = [lambda t: np.pad(t, ((0, height - t.shape[0]), (0, 0), (0, 0)))]
    rows = [np.hstack([pad[0](t) for t in row]) for row in (tiles_top, tiles_bottom)]
    write_image(args.output, np.vstack(rows)[..., ::-1].astype(np.float32) / 255.0)
    print(f"wrote {args.output}: {', '.join(p['a'] + '-' + p['b'] + (' ok' if p['ok'] else ' failed') for p in result.report['pairs'])}")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
