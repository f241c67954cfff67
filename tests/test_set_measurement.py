"""The OpenCL backend's set_measurement (issue 37, a batched call's host work): the upload in one
conversion pass, ``b = K^T y`` from a zero spectrum filled on the device instead of the FFT of a
zero image, and ``||y||^2`` per frame without a stack-sized float64 temporary
(:func:`clfza.backends._opencl.frame_norms2`). Each is held to the path it replaced, bit for
bit: ``from_host`` + the forward FFT, ``resid_grad`` at ``x = 0``, and the float64 squares
summed; and ``b`` to the float64 reference ``F^-1[H F(y)]``."""

from __future__ import annotations

import numpy as np
import pytest

from clfza import Camera
from clfza.backends import get_backend
from clfza.backends._opencl import frame_norms2

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def _cam(shape):
    return Camera(pitch=0.01, shape=shape, r1=0.05, z1=100.0, z2=3.0, mask="gzp")


def _old_norms(y, frames):
    y2 = np.asarray(y, np.float64) ** 2
    return float(np.sum(y2)) if frames == 1 else y2.reshape(frames, -1).sum(axis=1)


@pytest.mark.parametrize("frames,nc,shape", [(1, 1, (12, 30)), (3, 1, (9, 29)),
                                             (2, 3, (16, 16)), (1, 3, (5, 18))])
@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int16])
@pytest.mark.parametrize("fft", ["host", "device"])  # device: the GPUs' path
def test_set_measurement_equals_the_replaced_path(frames, nc, shape, dtype, fft):
    B = get_backend("opencl", _cam(shape), nc=nc, frames=frames, fft=fft)
    rng = np.random.default_rng(3)
    y = (rng.standard_normal((frames * nc,) + shape) * 1000).astype(dtype)
    B.set_measurement(y)
    Y, b = B.Y.get(), B.b.get()
    # the replaced path: from_host, the forward FFT, then resid_grad at a zero image
    yd = B.from_host(y)
    B.fft.rfft2(yd, B.Y)
    g = B.empty()
    B.resid_grad(B.zeros(), g)
    assert np.array_equal(B.Y.get(), Y)
    assert np.array_equal(g.get(), b)
    want = _old_norms(y, frames)
    assert np.array_equal(np.asarray(B.ynorm2), np.asarray(want))
    assert type(B.ynorm2) is type(want)
    # and b against the float64 reference F^-1[H F(y)] (mean-free y: H is 0 at DC)
    H = B.op.H.get().astype(np.float64)
    yy = np.asarray(y, np.float64).reshape(B.b.shape)
    ref = np.fft.irfft2(H * np.fft.rfft2(yy), s=shape)
    assert np.max(np.abs(b - ref)) <= 1e-5 * max(1.0, float(np.max(np.abs(ref))))


@pytest.mark.parametrize("shape,frames", [((4, 7, 9), 4), ((3, 64, 64), 3), ((3, 64, 64), 1),
                                          ((2, 1, 513, 257), 2), ((1, 70000), 1)])
def test_frame_norms2_bit_for_bit(shape, frames):
    rng = np.random.default_rng(5)
    for dt in (np.float64, np.float32):
        y = rng.standard_normal(shape).astype(dt) * 1e3
        got, want = frame_norms2(y, frames), _old_norms(y, frames)
        assert np.array_equal(np.asarray(got), np.asarray(want))
    # not C-contiguous, integers: the float64 expression itself
    y = rng.standard_normal((3, 16, 16))[:, ::2]
    assert np.array_equal(frame_norms2(y, 3), _old_norms(y, 3))
    assert frame_norms2(np.arange(6), 1) == 55.0
