"""Images in and pointmaps out as upstream DUSt3R does it, and the map back to each input's pixel grid.

Upstream (``dust3r.utils.image.load_images``) converts to RGB and, for ``size == 224``, resizes
the short side to 224 and centre-crops a square; for any other size it resizes the long side to
``size`` and centre-crops each side down to a multiple of the patch size (a square image to 4:3).
Resizing is PIL's: Lanczos when shrinking, bicubic otherwise, with PIL's kernel support scaling
(antialiasing). Pixels are then mapped to [-1, 1] (``(x - 0.5) / 0.5``).

Here the same resampling kernels are computed in float64 (:func:`resize_weights` follows PIL's
coefficient rule exactly), so 16-bit inputs keep their precision; PIL's 8-bit path rounds to 1/255
(clipping to [0, 1] after each pass is kept). The network's outputs live on the crop; :func:`to_input_grid`
samples them (bilinear) at every pixel of the original image, and pixels the crop cut off get none.
Pixel centres are at integer coordinates (the project's convention).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

__all__ = ["PreparedImage", "prepare_image", "resize_weights", "resize_image", "crop_box", "to_input_grid"]


@dataclass(frozen=True, eq=False)
class PreparedImage:
    """One image as the network sees it, and where that crop lies in the original."""

    tensor: torch.Tensor  # [3, h, w] float32 in [-1, 1], h and w multiples of the patch size
    original_size: tuple[int, int]
    """(W, H) of the input image."""
    resized_size: tuple[int, int]
    """(W, H) after resizing, before cropping."""
    crop: tuple[int, int, int, int]
    """(left, top, right, bottom) of the crop in resized pixels (right/bottom exclusive)."""

    @property
    def size(self) -> tuple[int, int]:
        """(w, h) of the network input."""
        return (int(self.tensor.shape[2]), int(self.tensor.shape[1]))

    def to_network(self, uv: np.ndarray) -> np.ndarray:
        """Original pixel coordinates ``[..., 2]`` -> network-input pixel coordinates ``[..., 2]``."""
        scale = np.array([self.resized_size[0] / self.original_size[0], self.resized_size[1] / self.original_size[1]])
        return (np.asarray(uv, np.float64) + 0.5) * scale - 0.5 - np.array(self.crop[:2], np.float64)


def _lanczos(x: np.ndarray) -> np.ndarray:
    inside = (x >= -3.0) & (x < 3.0)  # PIL's half-open support
    return np.where(inside, np.sinc(x) * np.sinc(x / 3.0), 0.0)


def _bicubic(x: np.ndarray) -> np.ndarray:
    a = -0.5
    x = np.abs(x)
    return np.where(x < 1.0, ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0,
                    np.where(x < 2.0, (((x - 5.0) * x + 8.0) * x - 4.0) * a, 0.0))


_FILTERS = {"lanczos": (_lanczos, 3.0), "bicubic": (_bicubic, 2.0)}


def resize_weights(in_size: int, out_size: int, kernel: str) -> np.ndarray:
    """``[out_size, in_size]`` float64 resampling matrix, PIL's ``precompute_coeffs`` rule.

    Output pixel ``i`` is centred on input coordinate ``(i + 0.5) * in / out`` (pixel edges at
    integers here); when shrinking, the kernel is stretched by ``in / out`` (antialiasing).
    """
    function, support = _FILTERS[kernel]
    scale = in_size / out_size
    stretch = max(scale, 1.0)
    support = support * stretch
    weights = np.zeros((out_size, in_size))
    for index in range(out_size):
        centre = (index + 0.5) * scale
        low = max(int(centre - support + 0.5), 0)  # C's (int) truncation, as PIL
        high = min(int(centre + support + 0.5), in_size)
        taps = np.arange(low, high)
        values = function((taps - centre + 0.5) / stretch)
        total = values.sum()
        weights[index, low:high] = values / total if total != 0.0 else values
    return weights


def resize_image(image: np.ndarray, size: tuple[int, int], kernel: str) -> np.ndarray:
    """Resize ``[H, W, C]`` float to ``size = (W', H')`` like PIL (horizontal pass, then vertical), clipped to [0, 1]."""
    height, width = image.shape[:2]
    out = np.asarray(image, np.float64)
    if size[0] != width:  # [W', W] @ [W, H * C] -> [W', H, C] -> [H, W', C]
        channels = out.shape[2]
        out = resize_weights(width, size[0], kernel) @ out.transpose(1, 0, 2).reshape(width, -1)
        out = np.clip(out.reshape(size[0], height, channels).transpose(1, 0, 2), 0.0, 1.0)
    if size[1] != height:  # [H', H] @ [H, W' * C]
        channels = out.shape[2]
        out = resize_weights(height, size[1], kernel) @ out.reshape(height, -1)
        out = np.clip(out.reshape(size[1], -1, channels), 0.0, 1.0)
    return out


def crop_box(resized: tuple[int, int], size: int, patch_size: int, square_ok: bool = False) -> tuple[int, int, int, int]:
    """Upstream's centre crop of a resized image ``(W, H)``: ``(left, top, right, bottom)``."""
    width, height = resized
    cx, cy = width // 2, height // 2
    if size == 224:
        half_w = half_h = min(cx, cy)
    else:
        half_w = ((2 * cx) // patch_size) * patch_size / 2
        half_h = ((2 * cy) // patch_size) * patch_size / 2
        if not square_ok and width == height:
            half_h = 3 * half_w / 4
    box = [int(round(value)) for value in (cx - half_w, cy - half_h, cx + half_w, cy + half_h)]  # PIL's crop rounding
    # Upstream would stop on a crop that is not a patch multiple (a 224 short side rounded to 223);
    # trim such a crop to the multiple below instead.
    for lo, hi in ((0, 2), (1, 3)):
        excess = (box[hi] - box[lo]) % patch_size
        box[lo] += excess // 2
        box[hi] -= excess - excess // 2
    return tuple(box)


def prepare_image(image: np.ndarray, size: int, patch_size: int = 16, square_ok: bool = False) -> PreparedImage:
    """Resize, crop and normalise one ``[H, W]`` or ``[H, W, 3]`` float image in [0, 1] (see the module)."""
    image = np.asarray(image, np.float32)
    if image.ndim == 2:
        image = image[..., None]
    if image.shape[2] == 1:
        image = np.repeat(image, 3, axis=2)  # upstream converts to RGB
    height, width = image.shape[:2]
    long_side = max(width, height)
    target = round(size * max(width / height, height / width)) if size == 224 else size
    resized = tuple(int(round(side * target / long_side)) for side in (width, height))
    kernel = "lanczos" if long_side > target else "bicubic"
    pixels = resize_image(image, resized, kernel)
    box = crop_box(resized, size, patch_size, square_ok)
    if box[2] <= box[0] or box[3] <= box[1]:
        raise ValueError(f"an image of {width}x{height} pixels is too small for {size}-pixel DUSt3R input")
    crop = pixels[box[1]:box[3], box[0]:box[2]]
    tensor = torch.from_numpy(((crop - 0.5) / 0.5).astype(np.float32)).permute(2, 0, 1).contiguous()
    return PreparedImage(tensor, (width, height), resized, box)


def to_input_grid(maps: torch.Tensor, prepared: PreparedImage) -> tuple[torch.Tensor, torch.Tensor]:
    """Sample network-grid maps ``[h, w, C]`` at every original pixel: ``[H, W, C]`` and ``inside [H, W]`` bool.

    Bilinear between network pixels, nearest in the half pixel along the crop's edge; pixels outside
    the crop are marked not inside (their values are the nearest edge's and must be discarded).
    """
    h, w = maps.shape[:2]
    width, height = prepared.original_size
    device = maps.device
    sx = prepared.resized_size[0] / width
    sy = prepared.resized_size[1] / height
    u = (torch.arange(width, device=device, dtype=torch.float64) + 0.5) * sx - 0.5 - prepared.crop[0]
    v = (torch.arange(height, device=device, dtype=torch.float64) + 0.5) * sy - 0.5 - prepared.crop[1]
    inside = ((v >= -0.5) & (v <= h - 0.5))[:, None] & ((u >= -0.5) & (u <= w - 0.5))[None, :]
    gx = (2.0 * u / max(w - 1, 1) - 1.0).float()
    gy = (2.0 * v / max(h - 1, 1) - 1.0).float()
    grid = torch.stack(torch.broadcast_tensors(gx[None, :], gy[:, None]), dim=-1)[None]  # [1, H, W, 2] (x, y)
    sampled = F.grid_sample(maps.permute(2, 0, 1)[None].float(), grid, mode="bilinear", padding_mode="border",
                            align_corners=True)
    return sampled[0].permute(1, 2, 0), inside
