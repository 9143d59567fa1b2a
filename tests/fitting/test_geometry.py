"""Exact disc-rectangle overlaps and the radial grid: analytic properties, by hypothesis."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from translucent.fitting.geometry import GRID_RATIO, disc_rectangle_area, radial_grid

#: Areas are sums of a few O(R^2) terms: agreement to 1e-9 of R^2 is round-off.
AREA_ROUND_OFF = 1e-9

finite = st.floats(-5.0, 5.0, allow_nan=False)
radius = st.floats(0.0, 8.0, allow_nan=False)


@given(radius=radius, x0=finite, y0=finite, width=st.floats(0.01, 4), height=st.floats(0.01, 4))
def test_area_between_zero_and_rectangle(radius, x0, y0, width, height):
    area = float(disc_rectangle_area(radius, x0, x0 + width, y0, y0 + height))
    scale = max(radius, 1.0) ** 2
    assert -AREA_ROUND_OFF * scale <= area <= width * height + AREA_ROUND_OFF * scale
    assert area <= np.pi * radius ** 2 + AREA_ROUND_OFF * scale


@given(radius=st.floats(0.1, 6.0), offset=st.floats(-0.5, 0.5), offset_y=st.floats(-0.5, 0.5))
def test_tiling_rectangles_sum_to_the_disc(radius, offset, offset_y):
    edges_x = np.arange(-8, 9) + offset
    edges_y = np.arange(-8, 9) + offset_y
    x0, y0 = np.meshgrid(edges_x[:-1], edges_y[:-1])
    total = disc_rectangle_area(radius, x0, x0 + 1, y0, y0 + 1).sum()
    assert abs(total - np.pi * radius ** 2) < AREA_ROUND_OFF * radius ** 2 * x0.size


@given(x0=finite, y0=finite, width=st.floats(0.01, 3), height=st.floats(0.01, 3))
def test_whole_rectangle_inside_a_large_disc(x0, y0, width, height):
    far = np.hypot(max(abs(x0), abs(x0 + width)), max(abs(y0), abs(y0 + height)))
    area = float(disc_rectangle_area(far * 1.0001 + 1e-9, x0, x0 + width, y0, y0 + height))
    assert abs(area - width * height) < AREA_ROUND_OFF * max(far, 1.0) ** 2


@given(r1=radius, r2=radius, x0=finite, y0=finite)
def test_monotone_in_radius_and_mirror_symmetric(r1, r2, x0, y0):
    small, large = sorted((r1, r2))
    a_small = disc_rectangle_area(small, x0, x0 + 1, y0, y0 + 1)
    a_large = disc_rectangle_area(large, x0, x0 + 1, y0, y0 + 1)
    assert a_small <= a_large + AREA_ROUND_OFF * max(large, 1) ** 2
    mirrored = disc_rectangle_area(large, -x0 - 1, -x0, y0, y0 + 1)
    assert abs(mirrored - a_large) < AREA_ROUND_OFF * max(large, 1) ** 2


def test_vectorised_area_and_nan_does_not_crash():
    radii = np.linspace(0, 3, 7)[:, None]
    area = disc_rectangle_area(radii, np.zeros(4), np.ones(4), np.zeros(4), np.ones(4))
    assert area.shape == (7, 4)
    quarter = radii[:, 0] <= 1.0  # a quarter disc inside the unit square
    np.testing.assert_allclose(area[quarter, 0], np.pi / 4 * radii[quarter, 0] ** 2,
                               atol=AREA_ROUND_OFF)
    assert np.isclose(area[-1, 0], 1.0)
    with np.errstate(invalid="ignore"):
        assert np.isnan(disc_rectangle_area(np.nan, 0, 1, 0, 1))


@settings(max_examples=30)
@given(r_max=st.floats(1.0, 100.0), resolution=st.floats(1e-4, 0.5),
       spacing=st.one_of(st.none(), st.floats(0.01, 2.0)))
def test_radial_grid_spacing(r_max, resolution, spacing):
    grid = radial_grid(r_max, resolution, spacing)
    nodes = grid.nodes
    steps = np.diff(nodes)
    assert nodes[0] == 0 and np.isclose(nodes[-1], r_max) and np.all(steps > 0)
    ratios = nodes[2:] / nodes[1:-1]
    assert np.all(ratios <= GRID_RATIO * (1 + 1e-9))
    if spacing is not None:
        assert np.all(steps[1:] <= max(spacing, resolution * (GRID_RATIO - 1)) * (1 + 1e-9))
