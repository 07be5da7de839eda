"""The robust standard deviation shared across the package (fingersplat3d/robust.py) against scipy's."""
import numpy as np
from scipy.stats import median_abs_deviation

from fingersplat3d.robust import robust_sigma


def test_robust_sigma_is_scipys_normal_scaled_mad_and_ignores_outliers():
    rng = np.random.default_rng(0)
    values = rng.normal(3.0, 2.0, 20000)
    # NORMAL_MAD is 1.4826, scipy's scale 1 / Phi^-1(3/4) = 1.482602...: the same to 2e-6 of the value
    assert abs(robust_sigma(values) / median_abs_deviation(values, scale="normal") - 1) < 2e-6
    assert abs(robust_sigma(values) - 2.0) < 0.05
    spoiled = np.concatenate([values, np.full(2000, 1e6)])  # a tenth of wild values barely moves it
    assert abs(robust_sigma(spoiled) - 2.0) < 0.3
    about_three = median_abs_deviation(values, center=lambda x, axis: 3.0, scale="normal")
    assert abs(robust_sigma(values, centre=3.0) / about_three - 1) < 2e-6
    assert robust_sigma([]) == 0.0 and robust_sigma(np.full(5, 7.0)) == 0.0
