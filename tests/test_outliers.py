"""Outlier rows (pincal.fit.outliers): robust scores of positions and of orientations, each with a physical floor."""

import numpy as np

from pincal.fit.outliers import OUTLIER_FLOOR_M, OUTLIER_FLOOR_RAD, OUTLIER_THRESHOLD, find_outliers, find_row_outliers


def test_a_gross_row_is_flagged_by_file_line():
    rng = np.random.default_rng(4)
    errors = np.abs(rng.normal(0.0, 1e-4, size=(40, 1)))  # 0.1 mm noise [m]
    errors[17] = 5e-3  # a 5 mm blunder: ~50 robust sigmas
    lines = np.arange(40) + 2
    assert [line for line, _ in find_outliers(errors, lines)] == [19]


def test_rounding_noise_is_never_an_outlier():
    """Noise-free data leaves residuals at rounding level (~1e-16 m): a row 5 robust
    sigmas above them is still far below any sensor's resolution."""
    rng = np.random.default_rng(5)
    errors = np.abs(rng.normal(0.0, 1e-16, size=(40, 1)))
    errors[3] = 1e-13
    assert find_outliers(errors, np.arange(40)) == []
    errors[3] = 10 * OUTLIER_FLOOR_M  # a real 10 µm excess on the same rows is reported
    assert [line for line, _ in find_outliers(errors, np.arange(40))] == [3]


def test_an_orientation_alone_far_off_is_flagged_by_it_and_a_position_by_its_own():
    """The two errors are scored apart: a row 20 robust sigmas off in orientation only, with a position
    like the others', is flagged by its orientation; a position blunder keeps ``position``; the worst first."""
    rng = np.random.default_rng(6)
    positions = np.abs(rng.normal(0.0, 1e-4, size=(40, 2)))  # 0.1 mm noise [m], two points
    angles = np.abs(rng.normal(0.0, 1e-3, size=40))  # 1 mrad noise [rad]
    angles[11] = 0.035  # a 2° blunder, its position as the others'
    positions[25] = 5e-3  # a 5 mm blunder, its orientation as the others'
    lines = np.arange(40) + 2
    found = find_row_outliers(positions, lines, angles)
    assert [(o.row, o.by) for o in found] == [(27, "position"), (13, "orientation")]
    assert found[0].score > found[1].score > OUTLIER_THRESHOLD
    # without the orientations only the position blunder is seen, as find_outliers reports it
    assert [o.row for o in find_row_outliers(positions, lines)] == [line for line, _ in find_outliers(positions, lines)]
    assert [line for line, _ in find_outliers(positions, lines)] == [27]


def test_orientation_rounding_and_missing_orientations_are_never_outliers():
    """An orientation excess below the floor (rounding on noise-free 6D rows) is no outlier; a row that measures
    no orientation (NaN) is neither flagged nor part of the median."""
    rng = np.random.default_rng(7)
    positions = np.abs(rng.normal(0.0, 1e-16, size=(40, 1)))
    angles = np.abs(rng.normal(0.0, 1e-16, size=40))
    angles[5] = 1e-12
    assert find_row_outliers(positions, np.arange(40), angles) == []
    angles[5] = 10 * OUTLIER_FLOOR_RAD  # a real 100 µrad excess on the same rows is reported
    angles[[0, 1, 2]] = np.nan
    assert [(o.row, o.by) for o in find_row_outliers(positions, np.arange(40), angles)] == [(5, "orientation")]
