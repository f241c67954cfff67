"""The paper's numbers: resolution (Eqs. 5-6), geometry (Eqs. 2-3), CIR (Eqs. 4/13)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import j1

from clfza import Camera
from clfza.camera import _optics as optics
from clfza.errors import ClfzaError


@pytest.mark.parametrize("r1, expected", [(0.56, 0.042), (0.32, 0.014)])
def test_resolution_matches_paper_fig4(r1, expected):
    # Eq. 5 with R = 4.56 mm; the paper quotes 0.042 mm and 0.014 mm (two significant digits).
    assert optics.resolution(r1, 4.56) == pytest.approx(expected, abs=5e-4)


@pytest.mark.parametrize("r1", [0.8, 0.5, 0.3])
def test_fig3_resolution_is_1p22_outermost_zone(r1):
    # Eq. 6: r_c = 1.22 dr; dr ~ r1 / (2 sqrt(n)) is an approximation, good to ~1 % here.
    R = 5.12
    rc = optics.resolution(r1, R)
    dr = optics.outermost_zone_width(r1, R)
    assert rc == pytest.approx(1.22 * dr, rel=0.01)
    assert rc == pytest.approx(0.61 * r1**2 / R, rel=0.001)


def test_cir_first_zero_is_resolution():
    # The Bessel factor of Eq. 4 vanishes first at r_c (Eq. 5).
    r1, R = 0.32, 4.56
    rc = optics.resolution(r1, R)
    r = np.linspace(1e-6, 2 * rc, 20001)
    amp = (R / r) * j1(2 * np.pi * r * R / r1**2)
    first_zero = r[np.argmax(amp <= 0)]
    assert first_zero == pytest.approx(rc, rel=1e-3)
    cir = optics.coherent_impulse_response(np.array([0.0]), r1, R)
    assert cir[0].real == pytest.approx(np.pi * R**2 / r1**2)


def test_geometry_eqs_2_3_and_shadow_scaling():
    assert optics.magnification(300, 3) == pytest.approx(0.01)
    assert optics.image_size(200, 300, 3) == pytest.approx(2.0)
    assert optics.field_of_view(6.0, 3.0) == pytest.approx(math.pi / 4)
    assert optics.shadow_r1(0.32, 300, 3) == pytest.approx(0.3232)
    cam = Camera(pitch=0.0038, shape=(2048, 2048), r1=0.32, z1=300, z2=3, R=4.56)
    assert cam.r1p == pytest.approx(0.3232)
    assert cam.resolution_object == pytest.approx(cam.resolution_sensor / 0.01)
    # Paper: r1 = 0.32 mm resolves 1.5 mm in the object plane; theory 1.4 mm (Eq. 5 / M).
    assert optics.object_resolution(0.32, 4.56, 300, 3) == pytest.approx(1.37, abs=0.02)


def test_sampling_regimes():
    p, n = 0.01, 512
    rc = optics.critical_r1p(p, n)
    assert optics.sampling_regime(rc, p, n).name == "critical"
    assert optics.sampling_regime(rc * 1.3, p, n).name == "undersampled-frequency"
    assert optics.sampling_regime(rc * 0.7, p, n).name == "undersampled-space"
    # The paper's simulation sits at r1'^2 / (N p^2) = 1.37 (docs/design.md s.1 says ~1.3x).
    cam = Camera.preset("simulation")
    assert cam.regime.ratio == pytest.approx(0.2645**2 / 0.0512, rel=1e-6)
    assert cam.regime.name == "undersampled-frequency"


def test_band_limit_and_bin_factor():
    # Experiment preset: rho_c = R'/r1'^2 = 43.6 cyc/mm against a pixel Nyquist of 133: bin 3.
    cam = Camera.preset("experiment")
    assert cam.band_limit == pytest.approx(4.56 * 1.01 / (math.pi / 29.75), rel=1e-6)
    assert cam.suggested_bin == 3
    assert Camera.preset("simulation").suggested_bin == 1


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "x", None])
def test_optics_rejects_bad_parameters(bad):
    with pytest.raises(ClfzaError, match="r1"):
        optics.resolution(bad, 4.56)
