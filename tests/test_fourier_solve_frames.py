"""ADMM's Fourier x-update on a batch of frames (clfza.solvers._admm_ops.OpenCLFourierSolve):
setup fills each frame's ``1 / (H^2 + rho |D|^2 + mu)`` on the device (spectrum.cl's
admm_inverse_fill, from the shared ``H^2``, ``|D|^2``'s two factors and the frame's ``(rho,
mu)``), the solve (admm_solve_spec, on CPUs admm_solve_spec8) divides by it; against the
float64 reference (``_inverse``) frame by frame, a batch's frame against the same frame alone,
a setup queued after a solve, and bad penalties refused."""

from __future__ import annotations

import numpy as np
import pytest

from clfza import Camera
from clfza.backends import get_backend
from clfza.errors import ClfzaError
from clfza.solvers._admm_ops import FourierSolve, _inverse

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def _cam(shape):
    return Camera(pitch=0.01, shape=shape, r1=0.05, z1=100.0, z2=3.0, mask="gzp")


def _reference(B, x, y, rho, mu):
    """float64: ``F^-1[F(x) / (H^2 + rho |D|^2 + mu)]`` with B's float32 H^2 (what the kernel
    reads) and the new x's data term ``||y - K x||^2``."""
    inv = _inverse(B.op.H2.get().astype(np.float64), B.shape, rho, mu)
    X = np.fft.rfft2(x) * inv
    H = B.op.H.get().astype(np.float64)
    r = np.fft.irfft2(np.fft.rfft2(y) - H * X, s=B.shape)
    return np.fft.irfft2(X, s=B.shape), float(np.sum(r * r))


# widths: 8-lane rows with a tail (29: odd; 30: the Nyquist column in a full vector; 18: a
# 1-lane tail), and a 2^k size
@pytest.mark.parametrize("shape", [(9, 29), (12, 30), (5, 18), (32, 32)])
def test_per_frame_penalties_against_the_float64_reference(shape):
    rho = np.array([0.7, 0.05, 3.0, 0.0])
    mu = np.array([0.1, 0.0, 0.2, 0.0])  # the last: rho = mu = 0, the bare 1 / H^2
    F = len(rho)
    B = get_backend("opencl", _cam(shape), frames=F)
    rng = np.random.default_rng(7)
    x, y = rng.standard_normal((2, F) + shape)
    B.set_measurement(y)
    fs = FourierSolve.for_backend(B)
    fs.setup(rho, mu)
    out = B.empty()
    data = fs.solve(B.from_host(x), out, True).get().reshape(F, -1)[:, 0]
    got = B.to_host(out)
    # the last frame divides by H^2 alone, which comes near 0 off the zones: its values are
    # large and float32's relative error of the inverse (a few ulp) is what scales
    for f in range(F):
        want, d = _reference(B, x[f], y[f], rho[f], mu[f])
        scale = max(1.0, float(np.max(np.abs(want))))
        assert np.max(np.abs(got[f] - want)) <= 1e-5 * scale, f
        assert data[f] == pytest.approx(d, rel=1e-4, abs=1e-5 * max(1.0, d))


def test_a_frame_of_a_batch_equals_the_frame_alone():
    """The same kernel, the same inputs: a batch's frame and that frame on a one-frame backend
    give the same bits; one shared penalty pair equals it given per frame."""
    shape = (16, 30)
    cam = _cam(shape)
    rng = np.random.default_rng(8)
    x, y = rng.standard_normal((2, 3) + shape)
    rho, mu = np.array([0.3, 0.9, 0.3]), np.array([0.02, 0.0, 0.02])
    B = get_backend("opencl", cam, frames=3)
    B.set_measurement(y)
    fs = FourierSolve.for_backend(B)
    fs.setup(rho, mu)
    ob = B.empty()
    fs.solve(B.from_host(x), ob, False)
    batch = B.to_host(ob)
    for f in (0, 1):
        A = get_backend("opencl", cam)
        A.set_measurement(y[f])
        fa = FourierSolve.for_backend(A)
        fa.setup(rho[f], mu[f])
        oa = A.empty()
        fa.solve(A.from_host(x[f][None]), oa, False)
        np.testing.assert_array_equal(A.to_host(oa)[0], batch[f])
    fs.setup(0.3, 0.02)  # one pair for every frame
    fs.solve(B.from_host(x), ob, False)
    np.testing.assert_array_equal(B.to_host(ob)[[0, 2]], batch[[0, 2]])


def test_setup_written_through_the_queue():
    """A solve queued before a new setup uses the penalties it was queued with (here one
    shared inverse, then one per frame: the setup makes the larger array)."""
    shape = (8, 18)
    B = get_backend("opencl", _cam(shape), frames=2)
    rng = np.random.default_rng(9)
    x = rng.standard_normal((2,) + shape)
    B.set_measurement(x)
    fs = FourierSolve.for_backend(B)
    o1, o2 = B.empty(), B.empty()
    xd = B.from_host(x)
    fs.setup(0.5, 0.3)
    fs.solve(xd, o1, False)
    fs.setup([2.0, 4.0], [1.0, 0.0])
    fs.solve(xd, o2, False)
    a, b = B.to_host(o1), B.to_host(o2)
    for f, (r1, m1, r2, m2) in enumerate(((0.5, 0.3, 2.0, 1.0), (0.5, 0.3, 4.0, 0.0))):
        for got, (r, m) in ((a, (r1, m1)), (b, (r2, m2))):
            want = _reference(B, x[f], x[f], r, m)[0]
            assert np.max(np.abs(got[f] - want)) <= 1e-5 * max(1.0, np.max(np.abs(want)))


@pytest.mark.parametrize("rho,mu,why", [
    ([0.1, 0.2], 0.0, "penalties for a batch of 3"),
    (np.ones((3, 1)), 0.0, "one value per frame"),
    ([0.1, np.nan, 0.2], 0.0, "finite"),
])
def test_bad_penalties_are_refused(rho, mu, why):
    B = get_backend("opencl", _cam((8, 18)), frames=3)
    with pytest.raises(ClfzaError, match=why):
        FourierSolve.for_backend(B).setup(rho, mu)
