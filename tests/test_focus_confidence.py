"""The focus searches' confidence rule (issue 34, item 3): clfza.focus.focus_confidence on
curves whose answer is known, and the FZA autofocus's verdicts on the cases the issue names.
The thresholds themselves are measured by bench/bench_focus_confidence.py."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from clfza import Camera, Noise, simulate
from clfza.errors import ClfzaError
from clfza.focus import autofocus, depth_resolution, focus_confidence

U = np.linspace(0.0, 1.0, 41)


def _peak(at: float, width: float = 0.02) -> np.ndarray:
    return np.exp(-(((U - at) / width) ** 2))


def test_a_narrow_interior_peak_is_confident():
    ev = focus_confidence(_peak(0.4), U)
    assert ev["confident"] and ev["best_index"] == 16 and ev["isolation"] == pytest.approx(1.0)


@pytest.mark.parametrize("curve", [U, U[::-1], _peak(0.0), _peak(1.0)])
def test_a_peak_at_an_end_is_not(curve):
    ev = focus_confidence(curve, U)
    assert not ev["confident"] and ev["at_edge"] and "end of the range" in ev["reason"]


def test_a_peak_within_its_width_of_an_end_is_not():
    ev = focus_confidence(_peak(0.05), U, resolution=0.06)
    assert ev["at_edge"] and not ev["confident"]


def test_two_equal_peaks_far_apart_are_not_isolated():
    ev = focus_confidence(_peak(0.3) + 0.95 * _peak(0.7), U)
    assert not ev["confident"] and ev["isolation"] < 0.1 and "isolated" in ev["reason"]


def test_a_broad_hump_is_not_isolated_but_a_wide_focus_window_says_why():
    hump = _peak(0.5, 0.3)
    assert not focus_confidence(hump, U)["confident"]
    ev = focus_confidence(_peak(0.5), U, resolution=0.2)  # focus 40% of the range wide
    assert not ev["confident"] and ev["resolution_fraction"] == pytest.approx(0.4)
    assert "as wide as the range" in ev["reason"]
    assert not focus_confidence(_peak(0.5), U, resolution=np.inf)["confident"]


def test_flat_or_broken_curves_and_bad_input():
    assert not focus_confidence(np.ones(41), U)["confident"]
    assert not focus_confidence(np.full(41, np.nan), U)["confident"]
    with pytest.raises(ClfzaError, match="positions"):
        focus_confidence(np.ones(5), U)


def _quiet_autofocus(y, cam, z_range):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return autofocus(y, cam, z_range, backend="numpy", warn=False)


def test_depth_of_focus_as_wide_as_the_range_is_refused():
    """The issue's camera (1024^2 of 5.5 um binned to 256^2 of 22 um) at 250 mm, searched
    over 100-1000 mm: the depth of focus there spans much of the range (the issue's search
    answered 553 mm "confident" with +/- 634 mm)."""
    cam = Camera(pitch=0.022, shape=(256, 256), r1=0.5, z1=250.0, z2=2.0, R=4.0, mask="fza")
    obj = np.random.default_rng(0).random((64, 64)) > 0.7
    y = simulate(obj.astype(float), cam, object_width=60.0).y
    fr = _quiet_autofocus(y, cam, (100.0, 1000.0))
    assert not fr.confident, fr.evidence["reason"]
    assert fr.evidence["resolution_fraction"] >= 0.25 or fr.evidence["at_edge"]


@pytest.fixture(scope="module")
def fig7():
    """The paper's Fig. 7 noise (variance 0.01 on y) on the simulation preset at 20 mm,
    binned 2x2 to 256^2 as the bench runs it."""
    from clfza.benchmarks._scenes import measurement

    cam = Camera.preset("simulation")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        y = measurement("natural", cam.at_depth(20.0),
                        noise=Noise(gaussian_var=0.01, seed=1)).measurement.y
    yb = y.reshape(256, 2, 256, 2).mean(axis=(1, 3))
    return yb, cam.with_shape((256, 256), 0.02)


def test_fig7_noise_finds_the_depth_with_confidence(fig7):
    yb, cam = fig7
    fr = _quiet_autofocus(yb, cam, (10.0, 1000.0))
    assert abs(fr.z1_best - 20.0) <= depth_resolution(cam, 20.0)
    assert fr.confident, fr.evidence["reason"]


def test_noise_alone_is_refused(fig7):
    _, cam = fig7
    rng = np.random.default_rng(11)
    for z_range in ((10.0, 60.0), (10.0, 1000.0), (5.0, 100.0)):
        fr = _quiet_autofocus(rng.normal(0.0, 0.1, cam.shape), cam, z_range)
        assert not fr.confident, (z_range, fr.z1_best, fr.evidence["reason"])
