"""The host work of a batch (issue 37): each frame's noise estimate and Wiener ``lam`` computed
for the whole stack at once (one FFT per plane for both, the frames' Brent searches in
lockstep, the frames over threads) must give every frame, bit for bit, what the one-frame path
gives it, so that a batch's starts, and hence its images, equal one frame at a time."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.fft
import scipy.optimize

import clfza
from clfza.backends import get_backend
from clfza.errors import ClfzaError
from clfza.solvers._context import SolveContext
from clfza.solvers._noise import estimate_noise, noise_from_power
from clfza.solvers._tau import channel_group, frame_starts
from clfza.solvers._wiener import brentq_steps, wiener_lam, wiener_lams

N = 48


@pytest.fixture(scope="module")
def cam():
    return clfza.Camera.preset("simulation").with_shape((N, N))


def _run(gen, f):
    x = next(gen)
    try:
        while True:
            x = gen.send(f(x))
    except StopIteration as e:
        return e.value


def test_brent_steps_are_scipys_brentq():
    """The generator takes scipy.optimize.brentq's steps: the same root, bit for bit, on
    functions that exercise its interpolation, extrapolation and bisection branches."""
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(400):
        a, b = rng.uniform(-20, -1), rng.uniform(1, 20)
        c, p = rng.uniform(-0.9, 0.9) * min(-a, b), rng.uniform(0.3, 3)

        def f(u, c=c, p=p):
            return math.copysign(abs(u - c) ** p, u - c) + 0.1 * math.sin(3 * u)

        if f(a) * f(b) >= 0:
            continue
        xtol = 10 ** rng.uniform(-12, -1)
        assert _run(brentq_steps(a, b, xtol), f) == scipy.optimize.brentq(f, a, b, xtol=xtol)
        checked += 1
    assert checked > 100
    with pytest.raises(ClfzaError, match="different signs"):
        _run(brentq_steps(1.0, 2.0, 1e-6), lambda u: u)


@pytest.mark.parametrize("backend", ["numpy", "opencl"])
def test_wiener_lams_equal_each_frame_alone(cam, backend):
    B = get_backend(backend, cam)
    rng = np.random.default_rng(1)
    ys = rng.standard_normal((5, N, N)) * rng.uniform(0.01, 3, (5, 1, 1))
    sig = [0.0, 1e-3, 0.05, 0.5, 5.0]  # lam at its floor, inside and at its ceiling
    Y2 = np.abs(scipy.fft.rfft2(ys - ys.mean(axis=(1, 2), keepdims=True))) ** 2
    assert wiener_lams(B, Y2, sig) == [wiener_lam(B, y, s) for y, s in zip(ys, sig,
                                                                          strict=True)]


def test_noise_from_power_equals_estimate_noise(cam):
    rng = np.random.default_rng(2)
    ys = rng.standard_normal((4, N, N)) * rng.uniform(0.01, 3, (4, 1, 1))
    p = np.abs(scipy.fft.rfft2(ys - ys.mean(axis=(1, 2), keepdims=True))) ** 2
    assert noise_from_power(p, ys, cam) == [estimate_noise(y, cam) for y in ys]
    # the Haar fallback (no out-of-band share large enough)
    assert noise_from_power(p, ys, cam, min_fraction=1.0) == [
        estimate_noise(y, cam, min_fraction=1.0) for y in ys]


@pytest.mark.parametrize("nc", [1, 3])
@pytest.mark.parametrize("workers", [1, 2])
def test_frame_starts_equal_each_frame_alone(cam, nc, workers):
    B = get_backend("opencl", cam, nc=nc)
    ctx = SolveContext(cam, B.data_scale ** 2, False)
    rng = np.random.default_rng(3)
    F = 3
    planes = rng.standard_normal((F * nc, N, N)) * rng.uniform(0.01, 2, (F * nc, 1, 1))
    groups, lams = frame_starts(B, ctx, planes, nc, workers=workers)
    assert len(groups) == len(lams) == F
    for f in range(F):
        g = channel_group(B, ctx, planes[f * nc:(f + 1) * nc])
        assert (groups[f].sigma, groups[f].sigma_method) == (g.sigma, g.sigma_method)
        np.testing.assert_array_equal(groups[f].y, g.y)
        assert lams[f] == wiener_lam(B, g.y, g.sigma)[0]
