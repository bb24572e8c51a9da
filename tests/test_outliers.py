"""Outlier rows (pincal.fit.outliers): robust scores with a physical floor."""

import numpy as np

from pincal.fit.outliers import OUTLIER_FLOOR_M, find_outliers


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
