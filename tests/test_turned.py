"""Photos turned in their own plane (experiments/turned.py, degrade_photos --kind quarter|roll): the turned photo is the
rolled camera's."""
import numpy as np

from fingersplat3d.experiments.turned import quarter_turned, roll_rotation, rolled_in_plane
from fingersplat3d.scene import Camera


def _dot(shape, at):
    image = np.full(shape, 10, np.uint8)
    y, x = np.mgrid[:shape[0], :shape[1]]
    image[(x - at[0]) ** 2 + (y - at[1]) ** 2 <= 4] = 250
    return image


def _centroid(image):
    y, x = np.nonzero(image > 128)
    return np.array([x.mean(), y.mean()])


def test_a_turned_photo_is_the_photo_of_its_camera_rolled_about_the_optical_axis():
    width, height = 160, 120
    camera = Camera.from_focal(200.0, width, height, np.eye(4))
    point = np.array([[9.0, -6.0, 100.0]])
    seen = camera.project(point)[0][0]
    for degrees in (25.0, -15.0, 90.0):
        turned = rolled_in_plane(_dot((height, width), seen), degrees)
        rolled_pose = np.eye(4)
        rolled_pose[:3, :3] = roll_rotation(degrees) @ camera.world_to_cam[:3, :3]
        rolled = Camera(camera.K, rolled_pose, width, height)
        assert np.linalg.norm(_centroid(turned) - rolled.project(point)[0][0]) < 0.3
        assert np.allclose(roll_rotation(degrees) @ roll_rotation(degrees).T, np.eye(3))
    # What comes in at the corners is the background, not a copy of the finger: the border's median.
    corner = rolled_in_plane(_dot((height, width), seen), 45.0)[0, 0]
    assert corner == 10


def test_a_colour_photo_keeps_its_channels_and_a_quarter_turn_is_clockwise():
    image = np.zeros((4, 6, 3), np.uint8)
    image[..., 2] = 200  # red background
    image[0, 0] = (0, 255, 0)
    turned = quarter_turned(image)
    assert turned.shape == (6, 4, 3) and tuple(turned[0, -1]) == (0, 255, 0)  # top-left -> top-right
    large = np.zeros((40, 60, 3), np.uint8)
    large[...] = (0, 0, 200)
    large[15:25, 20:40] = (0, 255, 0)
    rolled = rolled_in_plane(large, 45.0)
    assert rolled.shape == large.shape and tuple(rolled[-1, 0]) == (0, 0, 200)  # brought in: the background's colour
