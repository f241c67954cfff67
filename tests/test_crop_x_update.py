"""The crop-split ADMM's x-update (clfza.solvers._admm_crop_ops.CropFourierSolve) on OpenCL against
its float64 reference, with both spectral kernels: ``crop_x_spec`` (one frequency per
work-item) and, on CPU devices in float32, ``crop_x_spec8`` (eight, the last work-item taking
the spectrum's ``n % 8`` left over)."""

from __future__ import annotations

import numpy as np
import pytest

from clfza import Camera
from clfza.backends import get_backend
from clfza.solvers._admm_crop_ops import CropFourierSolve

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def _camera(shape):
    return Camera(pitch=0.01, shape=shape, r1=0.16, z1=100.0, z2=3.0, R=0.12, mask="fza")


@pytest.mark.parametrize("nc", [1, 3])
@pytest.mark.parametrize("lanes", [1, 8])
@pytest.mark.parametrize("shape, tail", [((24, 28), 0), ((30, 22), 1), ((26, 30), 3)])
def test_x_update_matches_the_reference(rng, shape, tail, lanes, nc):
    """x and H x of one x-update, OpenCL against float64, on model grids whose half spectrum
    leaves ``tail`` = ``n % 8`` frequencies to the last work-item."""
    cam = _camera(shape)
    nb = get_backend("numpy", cam, model="exact", nc=nc)
    cb = get_backend("opencl", cam, model="exact", nc=nc)
    ny, nx = cb.shape
    assert (ny * (nx // 2 + 1)) % 8 == tail  # the grid the case is for
    ns, cs = CropFourierSolve.for_backend(nb), CropFourierSolve.for_backend(cb)
    if lanes == 8 and cs.lanes == 1:
        pytest.skip("crop_x_spec8 runs on CPU devices in float32 only")
    cs.lanes = lanes
    mu1, rho, mu3 = 0.3, 0.05, 0.02
    ns.setup(mu1, rho, mu3)
    cs.setup(mu1, rho, mu3)
    e, q1, q2, w, s = (rng.standard_normal((nc,) + nb.shape) for _ in range(5))
    xn, hn = nb.empty(), nb.empty()
    ns.solve(xn, hn, e, q1, q2, w, s, rho, mu3, mu1)
    xc, hc = cb.empty(), cb.empty()
    dev = [cb.from_host(a) for a in (e, q1, q2, w, s)]
    cs.solve(xc, hc, *dev, rho, mu3, mu1)
    # float32: a few ulps per FFT pass and per spectral product, relative to the largest value
    for got, want in ((cb.to_host(xc), xn), (cb.to_host(hc), hn)):
        got = got.reshape(want.shape)
        assert np.abs(got - want).max() <= 2e-5 * np.abs(want).max()
