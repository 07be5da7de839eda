"""Capture rigs: where the cameras (or the finger) are, and where the light comes from.

All rigs are expressed in the finger frame of :mod:`fingersplat3d.synth.shape` (axis +x, tip
pole at ``tip_x``, pad toward -z), so every view's ``world_to_cam`` is a consistent multi-view
geometry of one rigid finger, even when it is the finger that moved (``cfpose``).

* ``uwa``: three simultaneous cameras at -45, 0, +45 degrees around the rig axis, finger
  horizontal with the tip to the left, 1280x1024 grayscale, one light fixed in the world (like
  the UWA 3D/2D database's raw frames); with an ``rng`` the finger lies in the rig as a real one
  does, rolled, pitched, turned and shifted a little (:func:`random_finger_pose`), so the rig
  axis is not the finger's.
* ``cfpose``: one fixed camera, the finger vertical (tip up) and rolled/pitched at random between
  shots; the light moves with the camera (like CFPose), 10 poses by default.
* ``ring``: N cameras on a ring around the finger axis at chosen angles (degrees, 0 = facing the pad).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import Camera, look_at
from .shape import FingerParams

__all__ = ["RigView", "RIGS", "DEFAULT_SIZES", "ring_rig", "uwa_rig", "cfpose_rig", "rotation_about",
           "random_finger_pose", "default_focal"]

RIGS = ("uwa", "cfpose", "ring")
DEFAULT_SIZES = {"uwa": (1280, 1024), "ring": (1280, 1024), "cfpose": (1024, 1280)}
CAMERA_DISTANCE_MM = 120.0
FIELD_OF_VIEW_MM = 36.0  # object-side field across the long image side, at the finger


@dataclass(frozen=True, eq=False)
class RigView:
    """One shot: its name, camera, the light direction (world, toward the light) and the pose label."""

    name: str
    camera: Camera
    light_world: np.ndarray  # [3]
    pose: dict


def rotation_about(axis: np.ndarray, degrees: float) -> np.ndarray:
    """3x3 rotation about a unit axis (right-handed)."""
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    angle = np.deg2rad(degrees)
    cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def default_focal(size: tuple[int, int], distance: float = CAMERA_DISTANCE_MM) -> float:
    """The focal that frames :data:`FIELD_OF_VIEW_MM` across the long side from ``distance`` mm."""
    return max(size) / FIELD_OF_VIEW_MM * distance


def _target(params: FingerParams) -> np.ndarray:
    """The point the cameras aim at: on the axis, far enough back that the whole tip is in frame."""
    return np.array([params.tip_x - 0.42 * FIELD_OF_VIEW_MM, 0.0, -0.3 * params.bend])


def random_finger_pose(params: FingerParams, rng: np.random.Generator, max_roll: float = 20.0,
                       max_tilt: float = 6.0, max_shift_mm: float = 2.0) -> tuple[np.ndarray, dict]:
    """A finger laid in a rig by hand: ``finger_to_rig`` 4x4 and its description.

    Roll about its own axis within ``+-max_roll`` degrees, pitch and yaw within ``+-max_tilt``
    (about the point the cameras aim at) and a shift within ``+-max_shift_mm`` on each axis.
    """
    roll, pitch, yaw = rng.uniform(-max_roll, max_roll), rng.uniform(-max_tilt, max_tilt), rng.uniform(-max_tilt, max_tilt)
    shift = rng.uniform(-max_shift_mm, max_shift_mm, 3)
    pivot = _target(params)
    rotation = rotation_about([0, 0, 1], yaw) @ rotation_about([0, 1, 0], pitch) @ rotation_about([1, 0, 0], roll)
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = pivot - rotation @ pivot + shift
    return pose, {"roll_deg": float(roll), "pitch_deg": float(pitch), "yaw_deg": float(yaw),
                  "shift_mm": [float(v) for v in shift]}


def ring_rig(params: FingerParams, angles_deg, size: tuple[int, int] = (1280, 1024),
             focal: float | None = None, names=None, finger_to_rig: np.ndarray | None = None,
             tip_left: bool = False, pose: dict | None = None, distance: float = CAMERA_DISTANCE_MM) -> list[RigView]:
    """Cameras on a ring around the rig axis (+x); 0 degrees faces the pad, positive toward +y.

    ``finger_to_rig`` places the finger in the rig (default: its axis on the rig axis); the light
    is fixed in the rig. ``tip_left`` turns every camera by 180 degrees about its optical axis, so
    the tip points left in the images (UWA's raw frames). ``distance``: camera to the rig axis (mm).
    """
    focal = default_focal(size, distance) if focal is None else float(focal)
    target = _target(params)
    placement = np.eye(4) if finger_to_rig is None else np.asarray(finger_to_rig, np.float64)
    light = placement[:3, :3].T @ np.array([0.25, -0.2, -1.0])  # in front of the pad, a little toward the tip
    views = []
    for index, angle in enumerate(angles_deg):
        rotation = rotation_about([1.0, 0.0, 0.0], float(angle))
        eye = target + rotation @ np.array([0.0, 0.0, -distance])
        up = rotation @ np.array([0.0, 1.0 if tip_left else -1.0, 0.0])  # image right = -x (tip left) or +x
        camera = Camera.from_focal(focal, size[0], size[1], look_at(eye, target, up) @ placement)
        name = names[index] if names else f"v{index}"
        views.append(RigView(name, camera, light, {"ring_angle_deg": float(angle), **(pose or {})}))
    return views


def uwa_rig(params: FingerParams, size: tuple[int, int] = (1280, 1024), focal: float | None = None,
            rng: np.random.Generator | None = None, distance: float = CAMERA_DISTANCE_MM) -> list[RigView]:
    """UWA 3D/2D-like: three simultaneous cameras at -45, 0, +45 degrees, tip left; a hand-placed finger with ``rng``."""
    placement, pose = random_finger_pose(params, rng) if rng is not None else (None, None)
    # Tip left: image right is -x, so the camera turned +45 degrees about +x is the one on the left.
    return ring_rig(params, (45.0, 0.0, -45.0), size, focal, names=("left", "center", "right"),
                    finger_to_rig=placement, tip_left=True, pose=pose, distance=distance)


def cfpose_rig(params: FingerParams, rng: np.random.Generator, size: tuple[int, int] = (1024, 1280),
               focal: float | None = None, count: int = 10, max_roll: float = 45.0,
               max_pitch: float = 15.0, max_yaw: float = 8.0, distance: float = CAMERA_DISTANCE_MM) -> list[RigView]:
    """CFPose-like: one fixed camera, the finger (tip up) rolled, pitched and turned at random.

    The first pose is frontal; the others spread roll over ``[-max_roll, max_roll]`` (stratified,
    so a finger gets both sides) with random pitch and in-plane yaw.
    """
    focal = default_focal(size, distance) if focal is None else float(focal)
    pivot = _target(params)
    # Stage frame = finger frame at rest; the camera looks at the pad with the tip up in the image.
    stage_to_cam = look_at(pivot + [0.0, 0.0, -distance], pivot, [1.0, 0.0, 0.0])
    light_stage = np.array([0.3, 0.35, -1.0])
    rolls = np.concatenate([[0.0], np.linspace(-max_roll, max_roll, count - 1) if count > 1 else []])
    if count > 2:
        rolls[1:] += rng.uniform(-0.5, 0.5, count - 1) * (2 * max_roll / (count - 2))
    rolls = np.clip(rolls, -max_roll, max_roll)
    views = []
    for index, roll in enumerate(rolls):
        pitch = 0.0 if index == 0 else rng.uniform(-max_pitch, max_pitch)
        yaw = 0.0 if index == 0 else rng.uniform(-max_yaw, max_yaw)
        # Finger pose in the stage frame: roll about its own axis, pitch about y, yaw in the image plane.
        rotation = rotation_about([0, 0, 1], yaw) @ rotation_about([0, 1, 0], pitch) @ rotation_about([1, 0, 0], roll)
        finger_to_stage = np.eye(4)
        finger_to_stage[:3, :3] = rotation
        finger_to_stage[:3, 3] = pivot - rotation @ pivot
        camera = Camera.from_focal(focal, size[0], size[1], stage_to_cam @ finger_to_stage)
        light_world = rotation.T @ light_stage
        views.append(RigView(f"p{index + 1}", camera, light_world,
                             {"roll_deg": float(roll), "pitch_deg": float(pitch), "yaw_deg": float(yaw)}))
    return views
