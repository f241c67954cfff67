"""Masks (Eqs. 1, 7, 9): reference functions and the OpenCL synthesis kernel."""

from __future__ import annotations

import numpy as np
import pytest

from clfza.camera._masks import fza_fourier_orders, zone_plate
from clfza.errors import ClfzaError
from clfza.models._device_operator import device_zone_plate


def test_gzp_and_fza_values():
    t = zone_plate((65, 65), 0.01, 0.1, kind="gzp")
    assert t[32, 32] == pytest.approx(1.0)  # centre: cos(0) = 1
    assert 0.0 <= t.min() and t.max() <= 1.0
    b = zone_plate((65, 65), 0.01, 0.1, kind="fza")
    assert set(np.unique(b)) <= {0.0, 0.5, 1.0}
    # Binary is the sign of the sinusoid (Eq. 1 vs Eq. 9).
    assert np.all((b == 1.0) == (t > 0.5 + 1e-12)) or np.all((b >= 0.5) == (t >= 0.5))


def test_first_zone_boundary_at_r1_over_sqrt2():
    # cos(pi r^2 / r1^2) = 0 at r = r1 / sqrt(2): the first dark zone starts there.
    r1, p = 0.2, 0.001
    t = zone_plate((3, 801), p, r1, kind="fza")[1]  # the row through the centre
    x = (np.arange(801) - 400) * p
    edge = x[400:][np.argmax(t[400:] < 0.5)]
    assert edge == pytest.approx(r1 / np.sqrt(2), abs=p)


def test_aperture_and_phase():
    t = zone_plate((101, 101), 0.01, 0.1, kind="gzp", R=0.3)
    yy, xx = np.mgrid[-50:51, -50:51] * 0.01
    assert np.all(t[(xx**2 + yy**2) > 0.3**2 + 1e-12] == 0)
    shifted = zone_plate((101, 101), 0.01, 0.1, kind="gzp", phase=np.pi)
    plain = zone_plate((101, 101), 0.01, 0.1, kind="gzp")
    np.testing.assert_allclose(shifted + plain, 1.0, atol=1e-12)


def test_binary_fza_is_sum_of_gzps_eq7():
    # Eq. 7: the Fourier series converges to the binary profile away from zone edges.
    r1 = 1.0
    r = np.linspace(0.05, 2.0, 4000)
    c = np.cos(np.pi * r**2 / r1**2)
    mask = np.abs(c) > 0.3  # away from discontinuities
    series = fza_fourier_orders(r, r1, 401)
    binary = 0.5 + 0.5 * np.sign(c)
    assert np.max(np.abs(series - binary)[mask]) < 0.02


@pytest.mark.parametrize("kind", ["gzp", "fza"])
@pytest.mark.parametrize("shape", [(128, 128), (97, 130)])
@pytest.mark.parametrize("R", [None, 0.4])
def test_mask_kernel_matches_reference(rt, kind, shape, R):
    ref = zone_plate(shape, 0.01, 0.12, kind=kind, R=R, phase=0.3)
    got = device_zone_plate(rt, shape, 0.01, 0.12, kind=kind, R=R, phase=0.3).get()
    if kind == "gzp":
        # float32: phase reduced mod 2 in float64 on the host, sum < 4 -> |dphi| <= 4 ulp(4)
        # = 1.9e-6 rad; cospi error a few ulp; so |dT| <= 0.5 * (2e-6 + 4 * 6e-8) < 2e-6.
        np.testing.assert_allclose(got, ref, atol=2e-6, rtol=0)
    else:
        # Binary: exact except where cos is within float32 rounding of 0 (zone edges).
        c = np.abs(np.cos(np.pi * ((np.arange(shape[0]) - shape[0] // 2)[:, None] ** 2
                                   + (np.arange(shape[1]) - shape[1] // 2)[None, :] ** 2)
                          * 0.01**2 / 0.12**2 + 0.3))
        near_edge = c < 1e-5
        assert np.array_equal(got[~near_edge], ref[~near_edge])


@pytest.mark.parametrize("kw", [dict(pitch=0), dict(r1=-1), dict(kind="zebra"),
                                dict(R=-2.0), dict(phase=float("nan"))])
def test_mask_bad_input(kw):
    args = dict(shape=(8, 8), pitch=0.01, r1=0.1, kind="gzp")
    args.update(kw)
    with pytest.raises(ClfzaError):
        zone_plate(**args)
