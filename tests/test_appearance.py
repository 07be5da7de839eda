"""Image statistics that compare synthetic and real photos: finite, in range, and they see the difference."""
import numpy as np

from fingersplat3d.eval.appearance import image_statistics
from fingersplat3d.synth import Appearance, SynthConfig, synthesize


def test_statistics_of_a_synthetic_view_are_plausible(uwa640):
    view = uwa640["center"]
    stats = image_statistics(view.image, view.mask)
    values = stats.as_dict()
    assert all(np.isfinite(v) for v in values.values()), values
    assert stats.background < 0.1 < stats.skin and 0 < stats.noise < 0.05
    assert 3 < stats.ridge_period_px < 40 and 0.2 < stats.width_fraction < 0.9 and 0 < stats.rim_shading < 1.2


def test_crisper_ridges_and_sharper_optics_are_measured_as_such():
    soft = synthesize(2, SynthConfig(size=(640, 512))).capture["center"]
    crisp = synthesize(2, SynthConfig(size=(640, 512), appearance=Appearance(ridge_contrast=0.35, blur_px=0.5))).capture["center"]
    a, b = image_statistics(soft.image, soft.mask), image_statistics(crisp.image, crisp.mask)
    assert b.ridge_contrast > 1.5 * a.ridge_contrast and b.edge_blur_px < a.edge_blur_px
