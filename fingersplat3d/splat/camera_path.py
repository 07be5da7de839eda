"""Novel-view camera paths: the arc from the leftmost to the rightmost input camera.

The paper renders 12 views "at equal intervals between the left, front and right viewpoints". A
capture rig turns about one axis (the finger's, in a UWA-like rig; in a CFPose-like capture it is
the finger that rolls, which is the same relative geometry), so the path is defined by:

* the rig axis: the common direction of the relative rotations between the input cameras, i.e.
  the top eigenvector of ``sum r r^T`` over the rotation vectors ``r`` of every camera pair (the
  pair with the largest rotation dominates; for a perfect ring it is exact);
* its sign, so "left" and "right" do not depend on the input order: the axis points along the
  cameras' mean image-right direction (image-up when the axis is closer to vertical in the
  images); angles are right-handed about it. With the synthetic ``ring``/``uwa`` rigs this is the
  finger axis and the angles are the rig's own (``left`` = -45, ``right`` = +45);
* the pivot: the least-squares intersection of the optical axes (the point the cameras look at);
* each camera's angle: the twist of its orientation about the axis, relative to the others,
  unwrapped on the circle from the largest gap, so the span is below 360 degrees.

Arc camera ``k`` sits at angle ``lo + k (hi - lo) / (count - 1)``. Between the two input cameras
that bracket it, its orientation is their slerp and its centre the blend of their centres rotated
about the axis (through the pivot) to that angle; the ends are the input end cameras exactly.
All inputs share the image size, except that a camera stored portrait among landscape ones (or
the other way round: the same camera, its image turned by 90 degrees, as UWA stores one now and
then) is first turned back about its optical axis, by whichever quarter turn brings it closest
to the others; ``K`` is interpolated the same way (all equal in practice).

Degenerate input raises ``ValueError``: fewer than 2 cameras, cameras with the same orientation
(no axis to turn about), or parallel optical axes (no pivot). numpy, with
``scipy.spatial.transform.Rotation`` / ``Slerp`` for the rotation algebra.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ..eval.poses import rotation_angle_deg
from ..scene import Camera

__all__ = ["middle_camera", "RigGeometry", "rig_geometry", "arc_cameras", "cameras_at_angles"]

_MIN_ROTATION_RAD = 1e-6


class RigGeometry(NamedTuple):
    """How the input cameras sit around their common rotation axis."""

    axis: np.ndarray  # [3] unit, world; angles are right-handed about it
    pivot: np.ndarray  # [3] world point on the axis (least-squares intersection of the optical axes)
    angles_deg: np.ndarray  # [N] each input camera's angle about the axis (same order as the input)
    order: np.ndarray  # [N] input indices sorted from the leftmost (smallest angle) to the rightmost


def rig_geometry(cameras: Sequence[Camera]) -> RigGeometry:
    """The rig axis, pivot and per-camera angles of ``cameras`` (at least 2, not all alike)."""
    cameras = list(cameras)
    if len(cameras) < 2:
        raise ValueError(f"a camera arc needs at least 2 cameras, got {len(cameras)}")
    cam_to_world = np.stack([camera.rotation.T for camera in cameras])  # [N, 3, 3]
    axis = _common_axis(cam_to_world)
    pivot = _optical_axes_intersection(cameras)
    relative = (Rotation.from_matrix(cam_to_world) * Rotation.from_matrix(cam_to_world[0]).inv()).as_quat()  # xyzw, i rel. to 0
    twist = 2.0 * np.arctan2(relative[:, :3] @ axis, relative[:, 3])  # [N] in (-2pi, 2pi]
    angles = _unwrap_from_largest_gap(twist)
    return RigGeometry(axis, pivot, np.rad2deg(angles), np.argsort(angles, kind="stable"))


def arc_cameras(cameras: Sequence[Camera], count: int = 12) -> list[Camera]:
    """``count`` cameras at equal angles from the leftmost to the rightmost input camera (inclusive)."""
    cameras = _upright(list(cameras))
    if count < 2:
        raise ValueError(f"an arc needs at least 2 cameras, got count={count}")
    _check_sizes(cameras)
    rig = rig_geometry(cameras)
    ordered = [cameras[i] for i in rig.order]
    angles = np.deg2rad(rig.angles_deg[rig.order])  # [N] ascending
    targets = np.linspace(angles[0], angles[-1], count)
    result = []
    for k, angle in enumerate(targets):
        if k == 0 or k == count - 1:  # the ends are the input end cameras, exactly
            end = ordered[0] if k == 0 else ordered[-1]
            result.append(Camera(end.K.copy(), end.world_to_cam.copy(), end.width, end.height))
            continue
        right = int(np.clip(np.searchsorted(angles, angle, side="right"), 1, len(angles) - 1))
        left = right - 1
        span = angles[right] - angles[left]
        t = 0.0 if span <= 0 else float(np.clip((angle - angles[left]) / span, 0.0, 1.0))
        a, b = ordered[left], ordered[right]
        rotation = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([a.rotation.T, b.rotation.T])))(t).as_matrix()
        center = ((1 - t) * _turn(a.center, rig, angle - angles[left])
                  + t * _turn(b.center, rig, angle - angles[right]))
        K = (1 - t) * a.K + t * b.K
        result.append(_camera(K, rotation, center, a.width, a.height))
    return result


def cameras_at_angles(cameras: Sequence[Camera], angles_deg: Sequence[float],
                      reference: int | Camera | None = None) -> list[Camera]:
    """The reference camera turned about the rig axis (through the pivot) by each of ``angles_deg``.

    ``reference``: an index into ``cameras``, a camera, or None for the middle input camera (the
    one whose angle is nearest the middle of the span; with two cameras, the leftmost).
    """
    cameras = _upright(list(cameras))
    rig = rig_geometry(cameras)
    if reference is None:
        reference = cameras[_middle(rig)]
    elif not isinstance(reference, Camera):
        reference = cameras[int(reference)]
    result = []
    for angle in np.deg2rad(np.asarray(angles_deg, np.float64).reshape(-1)):
        turn = Rotation.from_rotvec(angle * rig.axis).as_matrix()
        result.append(_camera(reference.K.copy(), turn @ reference.rotation.T, _turn(reference.center, rig, angle),
                              reference.width, reference.height))
    return result


def middle_camera(cameras: Sequence[Camera]) -> int:
    """Index of the middle camera about the rig axis: the one whose angle is nearest the middle of
    the span (with two cameras, the leftmost). Cameras stored portrait against the others count as
    turned back upright."""
    return _middle(rig_geometry(_upright(list(cameras))))


def _middle(rig: RigGeometry) -> int:
    middle = 0.5 * (rig.angles_deg.min() + rig.angles_deg.max())
    return int(rig.order[int(np.argmin(np.abs(rig.angles_deg[rig.order] - middle)))])


# --- helpers -----------------------------------------------------------------------------------

def _quarter_turn(camera: Camera, sign: int) -> Camera:
    """The same camera with its image turned by a quarter turn (``sign`` +1 or -1) about the optical axis."""
    width, height = camera.height, camera.width
    turn = np.array([[0.0, -sign, 0.0], [sign, 0.0, 0.0], [0.0, 0.0, 1.0]])  # new camera frame from the old
    K = np.array([[camera.K[1, 1], 0.0, (width - 1) / 2.0], [0.0, camera.K[0, 0], (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    pose = camera.world_to_cam.copy()
    pose[:3, :3] = turn @ pose[:3, :3]
    pose[:3, 3] = turn @ pose[:3, 3]
    return Camera(K, pose, width, height)


def _upright(cameras: list[Camera]) -> list[Camera]:
    """Cameras stored with the image turned by 90 degrees against the majority, turned back."""
    sizes = [camera.size for camera in cameras]
    majority = max(set(sizes), key=sizes.count)
    upright = [camera for camera in cameras if camera.size == majority]
    result = []
    for camera in cameras:
        if camera.size == majority or camera.size != majority[::-1] or not upright:
            result.append(camera)
            continue
        candidates = [_quarter_turn(camera, sign) for sign in (1, -1)]
        result.append(min(candidates, key=lambda c: min(rotation_angle_deg(c.rotation, u.rotation) for u in upright)))
    return result


def _check_sizes(cameras: list[Camera]) -> None:
    sizes = {camera.size for camera in cameras}
    if len(sizes) > 1:
        raise ValueError(f"arc cameras need input cameras of one image size, got {sorted(sizes)}")


def _camera(K: np.ndarray, cam_to_world_rotation: np.ndarray, center: np.ndarray, width: int, height: int) -> Camera:
    world_to_cam = np.eye(4)
    rotation = cam_to_world_rotation.T
    u, _, vt = np.linalg.svd(rotation)  # re-orthonormalise against float drift
    rotation = u @ vt
    world_to_cam[:3, :3] = rotation
    world_to_cam[:3, 3] = -rotation @ center
    return Camera(K, world_to_cam, width, height)


def _turn(point: np.ndarray, rig: RigGeometry, angle: float) -> np.ndarray:
    """``point`` rotated by ``angle`` (radians) about the rig axis through the pivot."""
    return rig.pivot + Rotation.from_rotvec(angle * rig.axis).as_matrix() @ (point - rig.pivot)


def _common_axis(cam_to_world: np.ndarray) -> np.ndarray:
    """Unit axis shared by the relative rotations, oriented along the cameras' mean image right."""
    vectors = []
    for i in range(len(cam_to_world)):
        for j in range(i + 1, len(cam_to_world)):
            vectors.append(Rotation.from_matrix(cam_to_world[j] @ cam_to_world[i].T).as_rotvec())  # i -> j, world frame
    vectors = np.array(vectors)  # [pairs, 3]
    if np.max(np.linalg.norm(vectors, axis=1)) < _MIN_ROTATION_RAD:
        raise ValueError("the cameras all have the same orientation; there is no rig axis to turn about")
    _, eigenvectors = np.linalg.eigh(vectors.T @ vectors)
    axis = eigenvectors[:, -1]
    right = cam_to_world[:, :, 0].sum(axis=0)  # image +x in the world
    up = -cam_to_world[:, :, 1].sum(axis=0)  # image -y in the world
    sign_source = right if abs(axis @ right) >= abs(axis @ up) else up
    return axis if axis @ sign_source >= 0 else -axis


def _optical_axes_intersection(cameras: list[Camera]) -> np.ndarray:
    """The point nearest (least squares) to every camera's optical axis."""
    normal_matrix = np.zeros((3, 3))
    rhs = np.zeros(3)
    for camera in cameras:
        direction = camera.rotation[2]  # optical axis (camera +z) in the world
        projector = np.eye(3) - np.outer(direction, direction)
        normal_matrix += projector
        rhs += projector @ camera.center
    if np.linalg.cond(normal_matrix) > 1e10:
        raise ValueError("the cameras' optical axes are parallel; they look at no common point to turn about")
    return np.linalg.solve(normal_matrix, rhs)


def _unwrap_from_largest_gap(angles: np.ndarray) -> np.ndarray:
    """Angles on the circle -> real values spanning < 2 pi, cut at the largest empty gap."""
    wrapped = np.mod(angles, 2 * np.pi)
    order = np.argsort(wrapped, kind="stable")
    sorted_angles = wrapped[order]
    gaps = np.diff(np.concatenate([sorted_angles, sorted_angles[:1] + 2 * np.pi]))
    start = sorted_angles[(int(np.argmax(gaps)) + 1) % len(sorted_angles)]  # first angle after the gap
    unwrapped = np.mod(wrapped - start, 2 * np.pi)
    unwrapped[np.isclose(unwrapped, 2 * np.pi)] = 0.0
    return unwrapped - np.median(unwrapped)  # centred: the front camera of a symmetric rig is ~0
