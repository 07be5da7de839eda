"""Open3D adapters: ground-truth depth back-projected to clouds that lie on the ground-truth mesh."""
import numpy as np
import pytest

from fingersplat3d.geometry import capture_point_cloud, cloud_arrays, points_to_cloud, view_point_cloud
from fingersplat3d.scene import Camera, View
from fingersplat3d.synth import SynthConfig, synthesize


@pytest.fixture(scope="module")
def small():
    return synthesize(4, SynthConfig(size=(160, 128)))


def test_view_cloud_lies_on_mesh_with_camera_facing_normals(small):
    import open3d as o3d

    view = small.capture["center"]
    cloud = view_point_cloud(view)
    points, colors, normals = cloud_arrays(cloud)
    assert len(points) == view.mask.sum()
    np.testing.assert_allclose(colors[:, 0], view.image[view.mask], atol=1e-6)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(small.surface.to_open3d()))
    distance = scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()
    assert np.percentile(distance, 99) < 2e-3
    to_camera = view.camera.center - points
    assert np.mean((normals * to_camera).sum(1) > 0) > 0.99


def test_capture_cloud_fuses_views_and_downsamples(small):
    full = capture_point_cloud(small.capture)
    sparse = capture_point_cloud(small.capture, voxel_mm=0.5)
    assert len(full.points) == sum(v.mask.sum() for v in small.capture.views)
    assert 0 < len(sparse.points) < len(full.points)


def test_view_without_camera_or_depth_is_refused():
    view = View("v", np.zeros((4, 4), np.float32))
    with pytest.raises(ValueError, match="no camera"):
        view_point_cloud(view)
    with pytest.raises(ValueError, match="no depth"):
        view_point_cloud(view.with_(camera=Camera.from_focal(10, 4, 4)))


def test_points_to_cloud_gray_colours_become_rgb():
    cloud = points_to_cloud(np.zeros((5, 3)), np.linspace(0, 1, 5))
    _, colors, normals = cloud_arrays(cloud)
    assert colors.shape == (5, 3) and normals is None


def test_open3d_loads_without_its_web_viewer_in_an_fs3d_process():
    """The entry points' skip: Open3D works, Dash and IPython are not loaded, the viewer says why it is missing."""
    import subprocess
    import sys

    script = (
        "import sys\n"
        "from fingersplat3d.geometry import skip_open3d_web_viewer, points_to_cloud\n"
        "skip_open3d_web_viewer()\n"
        "import open3d as o3d\n"
        "cloud = points_to_cloud([[0, 0, 0], [1, 0, 0], [0, 1, 0]])\n"
        "assert len(cloud.voxel_down_sample(0.1).points) == 3\n"
        "assert 'dash' not in sys.modules and 'IPython' not in sys.modules\n"
        "try:\n"
        "    o3d.visualization.draw_plotly([cloud])\n"
        "except RuntimeError as error:\n"
        "    assert 'Plotly viewer' in str(error)\n"
        "else:\n"
        "    raise AssertionError('the viewer ran')\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_the_web_viewer_skip_leaves_a_loaded_open3d_alone():
    import sys

    import open3d  # noqa: F401  (loaded whole, as in a user's session)

    from fingersplat3d.geometry import skip_open3d_web_viewer

    before = sys.modules.get("open3d.visualization.draw_plotly")
    skip_open3d_web_viewer()
    assert sys.modules.get("open3d.visualization.draw_plotly") is before
