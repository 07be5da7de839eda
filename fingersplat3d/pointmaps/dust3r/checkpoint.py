"""Reading and writing DUSt3R checkpoints in the official layout.

An official checkpoint (``DUSt3R_ViTLarge_BaseDecoder_512_dpt.pth`` & co.) is a ``torch.save``d dict
with ``"model"``: the state dict, and ``"args"``: the training ``argparse.Namespace`` whose
``.model`` is the network description string (see :mod:`.config`). Other entries (optimizer, epoch)
are ignored. Loading never runs code from the file: ``torch.load(weights_only=True)`` with only
``argparse.Namespace`` allowed besides tensors and plain containers, and the description is parsed,
not evaluated. The weights must match the description exactly (``strict=True``: every key and
shape); the one tolerance is upstream's: a state dict without ``dec_blocks2`` (a CroCo
initialisation) gets decoder 1's weights for decoder 2.

Every problem is an :class:`~fingersplat3d.errors.InputError` naming the file.
"""
from __future__ import annotations

import argparse
import pickle
import zipfile
from pathlib import Path
from typing import Mapping, NamedTuple

import torch

from ...errors import InputError, input_error
from .config import Dust3rArchitecture, parse_model_description
from .model import Dust3rNet

__all__ = ["Checkpoint", "read_checkpoint", "load_model", "save_checkpoint"]


class Checkpoint(NamedTuple):
    architecture: Dust3rArchitecture
    state_dict: dict[str, torch.Tensor]


def _description(args: object) -> object:
    if isinstance(args, argparse.Namespace):
        return getattr(args, "model", None)
    if isinstance(args, Mapping):
        return args.get("model")
    return args  # a bare string


def read_checkpoint(path: str | Path) -> Checkpoint:
    """The architecture and state dict of a checkpoint file (tensors memory-mapped when possible)."""
    path = Path(path)
    if not path.exists():
        raise input_error(path, "checkpoint file not found")
    if not path.is_file():
        raise input_error(path, "is not a file (expected a DUSt3R .pth checkpoint)")
    try:
        with torch.serialization.safe_globals([argparse.Namespace]):
            try:
                content = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
            except RuntimeError as error:
                if "mmap" not in str(error):  # legacy (non-zip) files cannot be memory-mapped
                    raise
                content = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as error:
        if "Unsupported global" in str(error):
            raise input_error(path, "holds Python objects other than weights and a model description, which are not "
                                    "loaded because unpickling them could run code") from None
        raise input_error(path, "is corrupt or not a PyTorch checkpoint") from None
    except (RuntimeError, EOFError, OSError, ValueError, zipfile.BadZipFile, KeyError, IndexError) as error:
        raise input_error(path, f"is corrupt or not a PyTorch checkpoint ({type(error).__name__})") from None
    if not isinstance(content, Mapping) or "model" not in content or "args" not in content:
        raise input_error(path, "is not a DUSt3R checkpoint: it needs a 'model' state dict and 'args' describing "
                                "the network")
    state = content["model"]
    if not isinstance(state, Mapping) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise input_error(path, "is not a DUSt3R checkpoint: 'model' is not a state dict of tensors")
    try:
        architecture = parse_model_description(_description(content["args"]))
    except InputError as error:
        raise input_error(path, str(error)) from None
    return Checkpoint(architecture, dict(state))


def _check_keys(path: Path, model: Dust3rNet, state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    if not any(key.startswith("dec_blocks2.") for key in state):  # upstream's rule for CroCo-initialised weights
        state = {**state, **{key.replace("dec_blocks.", "dec_blocks2.", 1): value
                             for key, value in state.items() if key.startswith("dec_blocks.")}}
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    wrong = sorted(key for key in set(expected) & set(state) if tuple(expected[key].shape) != tuple(state[key].shape))
    if missing or unexpected or wrong:
        parts = []
        for label, keys in (("missing", missing), ("unexpected", unexpected), ("wrong shape", wrong)):
            if keys:
                shown = ", ".join(f"{k} {tuple(state[k].shape)} vs {tuple(expected[k].shape)}" if label == "wrong shape"
                                  else k for k in keys[:3])
                parts.append(f"{len(keys)} {label} ({shown}{', ...' if len(keys) > 3 else ''})")
        raise input_error(path, "the weights do not match the architecture in its description: " + "; ".join(parts))
    return state


def load_model(path: str | Path, device: torch.device | str = "cpu") -> Dust3rNet:
    """Build the described network and load the weights strictly; returns it in eval mode on ``device``."""
    path = Path(path)
    architecture, state = read_checkpoint(path)
    with torch.device("meta"):  # no memory for the random initial weights: the checkpoint's are assigned
        model = Dust3rNet(architecture)
    state = _check_keys(path, model, state)
    model.load_state_dict(state, strict=True, assign=True)
    if not all(torch.isfinite(p).all() for p in model.parameters() if p.is_floating_point()):
        raise input_error(path, "the weights contain NaN or Inf")
    return model.to(device=device, dtype=torch.float32).eval()


def save_checkpoint(model: Dust3rNet, path: str | Path) -> Path:
    """Write ``model`` in the official layout (``{"model": state_dict, "args": Namespace(model=...)}``)."""
    from ...atomic import atomic_path

    path = Path(path)
    args = argparse.Namespace(model=model.architecture.describe())
    with atomic_path(path) as temporary:
        torch.save({"model": model.state_dict(), "args": args}, temporary)
    return path
