"""The incident point is not refined where the bright core is cut by the image border."""

import numpy as np
import pytest
from translucent.fitting.profile import refine_incident_point

#: A symmetric blob sampled at pixel centres: the thresholded centroid of an uncut core is
#: unbiased up to the pixel sampling of the threshold contour (a few hundredths of a pixel).
CENTRE_ACCURACY_PX = 0.05


def blob(shape, centre, sigma):
    ys, xs = np.mgrid[0:shape[0], 0:shape[1]] + 0.5
    return np.exp(-((xs - centre[0]) ** 2 + (ys - centre[1]) ** 2) / (2 * sigma**2))


@pytest.mark.parametrize("centre", [(0.0, 24.0), (0.5, 24.0), (0.0, 0.0), (48.0, 47.5)])
def test_a_core_cut_by_the_border_keeps_the_given_point(centre):
    # the centroid of the visible part lies 0.5 px and more inside the image
    found = refine_incident_point(blob((48, 48), centre, 2.0), centre)
    assert found == centre


def test_a_core_clear_of_the_border_is_still_refined():
    centre = (6.3, 24.2)  # core radius ~3.6 px: clear of the border by ~2 px
    found = refine_incident_point(blob((48, 48), centre, 2.0), (7.0, 25.0))
    assert np.hypot(found[0] - centre[0], found[1] - centre[1]) < CENTRE_ACCURACY_PX
