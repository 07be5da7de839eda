"""The ``dust3r`` pointmap backend: a DUSt3R checkpoint run on views and pairs of views.

* ``predict_views``: the monocular mode of the paper: each image is paired with itself and head 1
  gives its pointmap in its own camera frame ``X^{v,v}``; the focal length those points imply is
  estimated (:mod:`.focal`). Points behind the camera are dropped (NaN, confidence 0).
* ``predict_pairs``: each requested pair ``(i, j)`` runs both ways (symmetrised, as upstream's
  ``make_pairs(symmetrize=True)``), giving ``X^{i,i}, X^{j,i}`` and ``X^{j,j}, X^{i,j}``.

Images are prepared as upstream (:mod:`.preprocess`) and every output is sampled back onto the
input image's own pixel grid; pixels the crop cut off get NaN points and confidence 0. Each image
goes through the encoder once per backend (cached by content), and pairs of equal-sized images
are decoded ``batch_size`` at a time. Confidences are the network's own (``>= 1`` for official
checkpoints). Time and peak memory of each call are kept in ``stats``.
"""
from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar, Iterator, Sequence

import numpy as np
import torch

from ...device import resolve_device
from ...errors import InputError
from ...scene import View
from ..base import PairPointmaps, Pointmap, register_backend
from .checkpoint import load_model
from .focal import estimate_focal
from .model import Dust3rNet, Encoded
from .preprocess import PreparedImage, prepare_image, to_input_grid
from .stats import InferenceStats, PeakMemory

__all__ = ["Dust3rBackend", "resolve_device"]

_ENCODER_CACHE = 32  # encoded images kept per backend


@dataclass(eq=False)
class Dust3rBackend:
    """Pointmaps from a DUSt3R checkpoint (see the module docstring). The weights load at construction."""

    name: ClassVar[str] = "dust3r"

    checkpoint: str | Path | None = None
    """Path of the checkpoint (official ``DUSt3R_ViTLarge_BaseDecoder_*.pth`` or the same layout). Required."""
    device: str = "auto"
    """``auto`` (CUDA when available, else CPU), ``cpu``, ``cuda`` or ``cuda:N``."""
    batch_size: int = 4
    """Image pairs decoded together (equal-sized images only). Larger batches amortise per-call
    overhead on a GPU; on CPU they mostly add memory (see the README's table)."""
    image_size: int | None = None
    """Network input size: 224 (short side, square crop) or e.g. 512 (long side). None: the
    checkpoint's training size (``max(img_size)``)."""
    model: Dust3rNet | None = field(default=None, repr=False)
    """An already built network (tests, benchmarks); used instead of loading ``checkpoint``."""
    stats: list[InferenceStats] = field(default_factory=list, init=False, repr=False)
    """Time and memory of each call, oldest first."""

    def __post_init__(self) -> None:
        if not (isinstance(self.batch_size, int) and self.batch_size >= 1):
            raise InputError(f"dust3r backend: batch size must be a positive integer, got {self.batch_size!r}")
        self._device = resolve_device(self.device)
        if self.model is None:
            if self.checkpoint is None:
                raise InputError("the dust3r backend needs a checkpoint: pass --checkpoint PATH to a DUSt3R .pth file "
                                 "(nothing is downloaded)")
            self.model = load_model(self.checkpoint, self._device)
        else:
            self.model = self.model.to(self._device).eval()
        arch = self.model.architecture
        if self.image_size is None:
            self.image_size = max(arch.img_size)
        if not (isinstance(self.image_size, int) and self.image_size >= arch.patch_size):
            raise InputError(f"dust3r backend: image size must be an integer of at least {arch.patch_size}, "
                             f"got {self.image_size!r}")
        self._encoded: OrderedDict[str, Encoded] = OrderedDict()

    # -- public protocol -------------------------------------------------------------------------

    def predict_views(self, views: Sequence[View]) -> list[Pointmap]:
        """Own-frame pointmaps ``X^{v,v}`` (each image paired with itself), on each view's pixel grid."""
        with self._measure("views", len(views)) as record:
            prepared = [self._prepare(view) for view in views]
            record["size"] = prepared[0].size if prepared else (0, 0)
            results: list[Pointmap | None] = [None] * len(views)
            for batch in self._batches([(v, v) for v in range(len(views))], prepared):
                encoded = self._encode_batch(batch, prepared, record)
                layers1, _ = self.model.decode(*encoded)
                points, confidence = self.model.head(1, layers1, encoded[0].image_size)
                for k, (v, _) in enumerate(batch):
                    grid_points, grid_conf, inside = self._to_grid(points[k], confidence[k], prepared[v])
                    keep = inside & torch.isfinite(grid_points).all(-1) & (grid_points[..., 2] > 0)
                    focal = estimate_focal(grid_points, keep)
                    results[v] = Pointmap(v, *self._numpy(grid_points, grid_conf, keep), focal)
        return results

    def predict_pairs(self, views: Sequence[View], pairs: Sequence[tuple[int, int]] | None = None) -> list[PairPointmaps]:
        """Symmetrised pairwise pointmaps: for each ``(i, j)`` (default: all ``i < j``), the
        :class:`PairPointmaps` ``(i, j)`` followed by ``(j, i)``."""
        if pairs is None:
            pairs = [(i, j) for i in range(len(views)) for j in range(i + 1, len(views))]
        for i, j in pairs:
            if not (0 <= i < len(views) and 0 <= j < len(views)):
                raise InputError(f"pair ({i}, {j}) refers to a view that does not exist ({len(views)} views)")
        ordered = [p for i, j in pairs for p in ((i, j), (j, i))]
        results: dict[tuple[int, int], PairPointmaps] = {}
        with self._measure("pairs", len(ordered)) as record:
            prepared = [self._prepare(view) for view in views]
            record["size"] = prepared[0].size if prepared else (0, 0)
            for batch in self._batches(ordered, prepared):
                encoded = self._encode_batch(batch, prepared, record)
                prediction = self.model.predict(*encoded)
                for k, (i, j) in enumerate(batch):
                    pts_i, conf_i, inside_i = self._to_grid(prediction.points1[k], prediction.confidence1[k], prepared[i])
                    pts_j, conf_j, inside_j = self._to_grid(prediction.points2[k], prediction.confidence2[k], prepared[j])
                    points_i, confidence_i = self._numpy(pts_i, conf_i, inside_i & torch.isfinite(pts_i).all(-1))
                    points_j, confidence_j = self._numpy(pts_j, conf_j, inside_j & torch.isfinite(pts_j).all(-1))
                    results[(i, j)] = PairPointmaps(i, j, points_i, points_j, confidence_i, confidence_j)
        return [results[p] for p in ordered]

    # -- internals -------------------------------------------------------------------------------

    def _prepare(self, view: View) -> PreparedImage:
        try:
            return prepare_image(view.image, self.image_size, self.model.patch_size)
        except ValueError as error:
            raise InputError(f"view {view.name!r}: {error}") from None

    def _batches(self, ordered: list[tuple[int, int]], prepared: list[PreparedImage]) -> Iterator[list[tuple[int, int]]]:
        """Ordered pairs grouped by (size of first image, size of second), ``batch_size`` at a time."""
        groups: dict[tuple, list[tuple[int, int]]] = {}
        for a, b in ordered:
            groups.setdefault((prepared[a].size, prepared[b].size), []).append((a, b))
        for group in groups.values():
            for start in range(0, len(group), self.batch_size):
                yield group[start:start + self.batch_size]

    def _encode_batch(self, batch_pairs: list[tuple[int, int]], prepared: list[PreparedImage],
                      record: dict) -> tuple[Encoded, Encoded]:
        """Encoder outputs of both sides of ``batch_pairs``, stacked (each distinct image encoded once)."""
        side1 = [self._encode(prepared[a], record) for a, _ in batch_pairs]
        side2 = [self._encode(prepared[b], record) for _, b in batch_pairs]
        return self._stack(side1), self._stack(side2)

    @staticmethod
    def _stack(items: list[Encoded]) -> Encoded:
        return Encoded(torch.cat([e.tokens for e in items]), torch.cat([e.positions for e in items]), items[0].image_size)

    @staticmethod
    def _key(prepared: PreparedImage) -> str:
        return hashlib.blake2b(prepared.tensor.numpy().tobytes(), digest_size=16).hexdigest()

    def _encode(self, prepared: PreparedImage, record: dict) -> Encoded:
        key = self._key(prepared)
        if key in self._encoded:
            self._encoded.move_to_end(key)
            return self._encoded[key]
        encoded = self.model.encode(prepared.tensor[None].to(self._device))
        record["encoded"] += 1
        self._encoded[key] = encoded
        while len(self._encoded) > _ENCODER_CACHE:
            self._encoded.popitem(last=False)
        return encoded

    @staticmethod
    def _to_grid(points: torch.Tensor, confidence: torch.Tensor, prepared: PreparedImage):
        values, inside = to_input_grid(torch.cat([points, confidence[..., None]], dim=-1), prepared)
        return values[..., :3], values[..., 3], inside

    @staticmethod
    def _numpy(points: torch.Tensor, confidence: torch.Tensor, keep: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
        points = torch.where(keep[..., None], points, torch.full_like(points, float("nan")))
        confidence = torch.where(keep, confidence.clamp_min(0.0), torch.zeros_like(confidence))
        return points.cpu().numpy().astype(np.float32), confidence.cpu().numpy().astype(np.float32)

    @contextmanager
    def _measure(self, task: str, passes: int) -> Iterator[dict]:
        """Run the body without autograd; append its :class:`InferenceStats` to ``stats``."""
        record = {"encoded": 0, "size": (0, 0)}
        with PeakMemory(self._device) as peak, torch.inference_mode():
            started = time.perf_counter()
            yield record
            seconds = time.perf_counter() - started
        self.stats.append(InferenceStats(task, str(self._device), passes, record["encoded"], round(seconds, 4),
                                         round(seconds / max(passes, 1), 4), round(peak.megabytes, 1), record["size"]))


register_backend("dust3r", Dust3rBackend)
