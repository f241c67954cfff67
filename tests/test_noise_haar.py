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


def _arrays(rng):
    """1-D float64 arrays for median_flat: noise (even and odd sizes), sorted, periodic with
    the sample's stride, few distinct values, constant, with inf, with NaN, too small."""
    n = 65536
    yield np.abs(rng.standard_normal(n))
    yield rng.standard_normal(n + 1)
    yield np.sort(rng.exponential(size=n))[::-1].copy()
    yield np.tile(rng.standard_normal(32), n // 32)
    yield np.round(rng.standard_normal(n) * 2)
    yield np.full(n, 0.5)
    v = rng.standard_normal(n)
    v[::7] = np.inf
    yield v
    v = rng.standard_normal(n)
    v[123] = np.nan
    yield v
    yield rng.standard_normal(1001)


def test_median_flat_is_np_median_bit_for_bit():
    from clfza.solvers._noise import median_flat

    rng = np.random.default_rng(9)
    for v in _arrays(rng):
        before = v.copy()
        got, want = median_flat(v), np.median(v)
        assert type(got) is type(want)
        assert got == want or (np.isnan(got) and np.isnan(want))
        np.testing.assert_array_equal(v, before)


def test_median_flat_selects_from_the_window_on_noise(monkeypatch):
    """On noise the sample's window holds the middle: no full np.median."""
    import clfza.solvers._noise as noise

    v = np.abs(np.random.default_rng(10).standard_normal(256 * 256))
    want = np.median(v)

    def refuse(*a, **k):
        raise AssertionError("np.median called")

    monkeypatch.setattr(noise.np, "median", refuse)
    assert noise.median_flat(v) == want
