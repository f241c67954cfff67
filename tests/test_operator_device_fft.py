"""The OpenCL operator K on the device FFT ("opencl-stockham") matches the numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from clfza import Camera, NumpyOperator
from clfza.models._device_operator import OpenCLOperator

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_operator_device_fft_matches_numpy(rt, rng, dtype):
    if np.dtype(dtype) == np.float64 and not rt.has_fp64:
        pytest.skip("device has no float64")
    cam = Camera.preset("simulation")
    ref = NumpyOperator(cam, warn=False)
    op = OpenCLOperator(cam, rt, dtype=dtype, fft="device", warn=False)
    assert op.fft.name == "opencl-stockham"
    x = rng.random(cam.shape)
    # float32: FFT pair error ~ 2 * eps * log2(512) plus the rounding of H and x
    tol = 2e-5 if np.dtype(dtype) == np.float32 else 1e-12
    for mine, theirs in ((op.forward_host, ref.forward), (op.normal_host, ref.normal)):
        y = mine(x)
        y_ref = theirs(x)
        assert np.linalg.norm(y - y_ref) / np.linalg.norm(y_ref) < tol


def test_operator_device_and_host_fft_agree(rt, rng):
    cam = Camera.preset("simulation")
    x = rng.random(cam.shape).astype(np.float32)
    a = OpenCLOperator(cam, rt, fft="device", warn=False).forward_host(x)
    b = OpenCLOperator(cam, rt, fft="host", warn=False).forward_host(x)
    assert np.linalg.norm(a - b) / np.linalg.norm(b) < 1e-5
