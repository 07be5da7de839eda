"""Synthetic 3D contactless fingerprints with exact ground truth (``fs3d synth``)."""
from .generate import SynthConfig, SynthResult, minutiae_ground_truth, synthesize
from .render import Appearance, FingerScene, Rendering
from .ridges import BIFURCATION, ENDING, PATTERN_CLASSES, RidgePattern, make_ridge_pattern
from .rigs import RIGS, RigView, cfpose_rig, ring_rig, uwa_rig
from .shape import FingerParams, FingerSurface, make_finger_surface, random_finger_params

__all__ = [
    "SynthConfig", "SynthResult", "synthesize", "minutiae_ground_truth",
    "Appearance", "FingerScene", "Rendering",
    "PATTERN_CLASSES", "ENDING", "BIFURCATION", "RidgePattern", "make_ridge_pattern",
    "RIGS", "RigView", "uwa_rig", "cfpose_rig", "ring_rig",
    "FingerParams", "FingerSurface", "make_finger_surface", "random_finger_params",
]
