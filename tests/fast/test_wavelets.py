import numpy as np
import pytest
import pywt
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from translucent.errors import InputError
from translucent.fast.wavelets import (
    SpatialWavelet,
    balanced_split,
    haar2d_forward,
    haar2d_inverse,
    quadtree_layout,
)

#: float64 round-off of a few hundred additions of values of order 1.
ROUND_OFF = 1e-12
#: float32 round-off through the levels of a transform of values of order 1.
ROUND_OFF_32 = 1e-5
#: The CDF 9/7 lifting constants are known to 15 digits and PyWavelets' bior4.4 taps to
#: 16-17; through four lifting steps the two agree to ~1e-12 on values of order 1.
PYWT_AGREEMENT = 1e-10

side_power = st.integers(min_value=0, max_value=5)


@settings(max_examples=40, deadline=None)
@given(data=st.data(), power=side_power)
def test_haar_is_orthonormal_and_inverts(data, power):
    side = 2**power
    image = data.draw(arrays(np.float64, (2, side, side),
                             elements=st.floats(-1e3, 1e3, allow_nan=False)))
    coefficients = haar2d_forward(image)
    assert np.linalg.norm(coefficients) == pytest.approx(np.linalg.norm(image), rel=1e-12,
                                                         abs=1e-9)
    assert np.abs(haar2d_inverse(coefficients) - image).max() <= 1e-9 * max(
        1.0, np.abs(image).max())


def test_haar_of_a_constant_is_one_scaling_coefficient():
    coefficients = haar2d_forward(np.full((8, 8), 3.0))
    assert coefficients[0, 0] == pytest.approx(3.0 * 8)
    coefficients[0, 0] = 0
    assert np.abs(coefficients).max() < ROUND_OFF


def test_haar_of_a_two_by_two_block():
    # a b / c d = 1 2 / 3 4: average 5, horizontal -1, vertical -2, diagonal 0
    assert haar2d_forward(np.array([[1.0, 2.0], [3.0, 4.0]])) == pytest.approx(
        np.array([[5.0, -1.0], [-2.0, 0.0]]))


def test_haar_keeps_float32():
    assert haar2d_forward(np.ones((4, 4), dtype=np.float32)).dtype == np.float32
    assert haar2d_forward(np.ones((4, 4), dtype=np.int64)).dtype == np.float64


@pytest.mark.parametrize("shape", [(3, 3), (4, 8), (4,)])
def test_haar_needs_power_of_two_squares(shape):
    with pytest.raises(InputError, match="square whose side is a power of two"):
        haar2d_forward(np.zeros(shape))


def test_quadtree_layout_of_a_grid_puts_neighbours_side_by_side(rng):
    """Points on a regular grid come back as the grid (up to flips): neighbours 1 step apart."""
    level = 4
    side = 2**level
    cells = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1)
    points = cells.reshape(-1, 2).astype(float)
    shuffled = rng.permutation(len(points))
    layout = quadtree_layout(points[shuffled], level)
    placed = points[shuffled][layout]
    assert np.allclose(np.linalg.norm(np.diff(placed, axis=0), axis=-1), 1.0)
    assert np.allclose(np.linalg.norm(np.diff(placed, axis=1), axis=-1), 1.0)


def test_quadtree_layout_is_a_permutation(rng):
    points = rng.normal(size=(4**3, 3))
    layout = quadtree_layout(points, 3)
    assert sorted(layout.ravel()) == list(range(64))


def test_quadtree_layout_needs_four_to_the_level_points():
    with pytest.raises(InputError, match="needs 4\\*\\*level points; got 10"):
        quadtree_layout(np.zeros((10, 3)), 2)


def test_balanced_split_cuts_a_line_into_intervals(rng):
    points = np.stack([rng.permutation(12).astype(float), np.zeros(12)], axis=1)
    parts = balanced_split(points, 3)
    assert parts.shape == (3, 4)
    assert sorted(parts.ravel()) == list(range(12))
    ranges = sorted((points[p, 0].min(), points[p, 0].max()) for p in parts)
    assert all(high < next_low for (_, high), (next_low, _) in zip(ranges, ranges[1:],
                                                                  strict=False))


def test_balanced_split_needs_a_divisor():
    with pytest.raises(InputError, match="parts.*dividing the 10 points"):
        balanced_split(np.zeros((10, 3)), 3)


@settings(max_examples=25, deadline=None)
@given(rows=st.integers(2, 40), cols=st.integers(2, 40), channels=st.integers(1, 3),
       seed=st.integers(0, 2**16))
def test_cdf97_inverts_for_any_grid(rows, cols, channels, seed):
    values = np.random.default_rng(seed).normal(size=(rows * cols, channels))
    wavelet = SpatialWavelet((rows, cols))
    coefficients = wavelet.forward(values)
    assert coefficients.shape == values.shape
    assert np.abs(wavelet.inverse(coefficients) - values).max() < ROUND_OFF


def test_cdf97_equals_pywavelets_bior44_away_from_the_border(rng):
    values = rng.normal(size=(32, 32))
    one_level = SpatialWavelet((32, 32), min_side=17)
    coefficients = one_level.forward(values.reshape(-1)).reshape(32, 32)
    approximation, (horizontal, vertical, diagonal) = pywt.dwt2(values, "bior4.4",
                                                                mode="periodization")
    interior = (slice(4, -4), slice(4, -4))
    for ours, theirs in ((coefficients[:16, :16], approximation),
                         (coefficients[:16, 16:], vertical),
                         (coefficients[16:, :16], horizontal),
                         (coefficients[16:, 16:], diagonal)):
        assert np.abs(ours[interior] - theirs[interior]).max() < PYWT_AGREEMENT


def test_cdf97_annihilates_smooth_data_in_the_interior():
    """Four vanishing moments: the detail coefficients of a cubic vanish away from borders."""
    rows, cols = 33, 33
    y, x = np.meshgrid(np.linspace(0, 1, rows), np.linspace(0, 1, cols), indexing="ij")
    cubic = 1 + x - 2 * y + x * y + x**3 - y**2 * x
    coefficients = SpatialWavelet((rows, cols), min_side=20).forward(cubic.reshape(-1))
    grid = coefficients.reshape(rows, cols)
    assert np.abs(grid[:17, 17:][4:-4, 4:-4]).max() < ROUND_OFF
    assert np.abs(grid[17:, 17:][4:-4, 4:-4]).max() < ROUND_OFF


def test_cdf97_keeps_float32():
    wavelet = SpatialWavelet((9, 9))
    values = np.ones((81, 3), dtype=np.float32)
    assert wavelet.forward(values).dtype == np.float32
    assert np.abs(wavelet.inverse(wavelet.forward(values)) - values).max() < ROUND_OFF_32


def test_cdf97_rejects_bad_shapes():
    with pytest.raises(InputError, match="at least 2 x 2"):
        SpatialWavelet((1, 10))
    with pytest.raises(InputError, match="one row per vertex"):
        SpatialWavelet((4, 4)).forward(np.zeros(15))
