"""The ``renders/`` folder of a reconstruction: novel views written by ``fs3d render``.

```
renders/<name>.png          the rendered image (8-bit, gray or RGB, black background)
renders/<name>_alpha.png    accumulated opacity (8-bit)
renders/depth/<name>.npy    float32 camera-frame depth, NaN off the model (+ .png and _color.png previews)
renders/cameras.json        the novel cameras (same schema as a capture's)
renders/contact_sheet.png   all views in a grid, images above their depth maps
```
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from ..atomic import atomic_dir
from .cameras import write_cameras
from .depth import depth_colormap
from .images import write_image
from .reconstruction import write_view_depth

__all__ = ["write_renders", "renders_sheet"]


def renders_sheet(views: Sequence, tile_width: int = 320, columns: int = 4) -> np.ndarray:
    """RGB uint8 grid: each cell is a rendered view (name written on it) above its depth map."""
    cells = []
    for view in views:
        scale = tile_width / view.image.shape[1]
        size = (tile_width, max(1, round(view.image.shape[0] * scale)))
        image = view.image if view.image.ndim == 3 else np.repeat(view.image[..., None], 3, axis=2)
        image = cv2.resize((np.clip(image, 0, 1) * 255).astype(np.uint8), size, interpolation=cv2.INTER_AREA)
        depth = cv2.resize(depth_colormap(view.depth), size, interpolation=cv2.INTER_NEAREST)
        cell = np.concatenate([image, depth], axis=0)
        cv2.putText(cell, view.name, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 0), 1, cv2.LINE_AA)
        cells.append(np.pad(cell, ((0, 4), (0, 4), (0, 0))))
    while len(cells) % columns:
        cells.append(np.zeros_like(cells[0]))
    rows = [np.concatenate(cells[k:k + columns], axis=1) for k in range(0, len(cells), columns)]
    return np.concatenate(rows, axis=0)


def write_renders(folder: str | Path, views: Sequence, units: str = "arbitrary", scale_mm_per_unit: float | None = None,
                  overwrite: bool = False) -> Path:
    """Write ``views`` (:class:`fingersplat3d.splat.novel.NovelView`) as the renders folder, atomically."""
    folder = Path(folder)
    with atomic_dir(folder, overwrite=overwrite) as temporary:
        for view in views:
            write_image(temporary / f"{view.name}.png", view.image)
            write_image(temporary / f"{view.name}_alpha.png", view.alpha)
            write_view_depth(temporary, view.name, view.depth, units="mm" if units == "mm" else "arbitrary")
        write_cameras(temporary / "cameras.json", [(v.name, f"{v.name}.png", v.camera) for v in views],
                      units=units, scale_mm_per_unit=scale_mm_per_unit)
        write_image(temporary / "contact_sheet.png", renders_sheet(views).astype(np.float32) / 255.0)
    return folder
