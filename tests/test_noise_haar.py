"""haar_mad_sigma: Donoho's estimate on the finest diagonal Haar band, equal to the median of
|HH| from the full Haar level (the definition) and right on white noise."""

from __future__ import annotations

import numpy as np
import pytest

from clfza.solvers._noise import _MAD_GAUSS, _haar_level, haar_mad_sigma


@pytest.mark.parametrize("shape", [(64, 64), (63, 65), (2, 2), (5, 3)])
def test_haar_mad_sigma_is_the_definition(shape):
    y = np.random.default_rng(sum(shape)).standard_normal(shape) * 3.0
    hh, _ = _haar_level(y)
    assert haar_mad_sigma(y) == float(np.median(np.abs(hh)) / _MAD_GAUSS)


def test_haar_mad_sigma_white_noise():
    y = np.random.default_rng(0).normal(scale=0.25, size=(256, 256))
    assert haar_mad_sigma(y) == pytest.approx(0.25, rel=0.03)  # 16384 values: ~1 % spread


def test_haar_mad_sigma_does_not_modify_input():
    y = np.random.default_rng(1).standard_normal((32, 32))
    before = y.copy()
    haar_mad_sigma(y)
    np.testing.assert_array_equal(y, before)
