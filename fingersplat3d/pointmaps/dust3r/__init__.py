"""DUSt3R pointmaps from an official (or same-layout) checkpoint: network, checkpoint I/O, backend.

Importing this package imports torch but loads no weights; :class:`Dust3rBackend` loads the
checkpoint the user passes (nothing is ever downloaded).
"""
from .backend import Dust3rBackend, resolve_device
from .checkpoint import Checkpoint, load_model, read_checkpoint, save_checkpoint
from .config import Dust3rArchitecture, parse_model_description
from .model import Dust3rNet, Encoded, PairPrediction
from .preprocess import PreparedImage, prepare_image, to_input_grid
from .stats import InferenceStats

__all__ = ["Dust3rBackend", "resolve_device", "Checkpoint", "load_model", "read_checkpoint", "save_checkpoint",
           "Dust3rArchitecture", "parse_model_description", "Dust3rNet", "Encoded", "PairPrediction",
           "PreparedImage", "prepare_image", "to_input_grid", "InferenceStats"]
