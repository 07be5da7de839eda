"""experiments/arc_cover.py: holes in a rendered finger are counted, its outline and the background are not."""
import numpy as np

from fingersplat3d.experiments.arc_cover import cover_gaps


def test_holes_and_thin_skin_inside_the_finger_are_counted_and_the_outline_is_not():
    alpha = np.zeros((60, 80))
    alpha[10:50, 10:70] = 1.0
    alpha[10, 10:70] = 0.6  # an antialiased outline row: inside the finger, taken off by the inset
    alpha[25:29, 30:34] = 0.0  # a hole: 16 px
    alpha[35:37, 50:55] = 0.7  # thin skin: 10 px
    finger, holes, thin = cover_gaps(alpha, inset_px=3)
    assert finger == (40 - 6) * (60 - 6)
    assert holes == 16 and thin == 26
    assert cover_gaps(np.zeros((20, 20))) == (0, 0, 0)
    assert cover_gaps(np.full((20, 20), np.nan))[0] == 0  # NaN is no cover
