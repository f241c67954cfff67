"""``tau="auto"`` with the data term's high-pass on continuous-tone scenes (issue 33, item 2):
the best ``tau`` of photographs lies below that of graphics of a few grey levels, more so at
low noise, so the rule's ``tau`` is multiplied by :func:`tone_factor` where the pilot estimate
is continuous-tone (clfza.solvers._tau_exact; the measurements: docs/measurements.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import clfza
from clfza.solvers._tau_exact import (
    HIGHPASS_PITCH_CAP,
    HIGHPASS_TAU_FACTOR,
    TONE_FACTOR,
    TONE_MID,
    TONE_NOISE_MIN,
    TONE_NOISE_REF,
    mid_tone_share,
    tone_factor,
)

# a 64^2 camera with a finite aperture: the exact model with the high-pass
CAM = clfza.Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0, R=0.6)
KW = dict(backend="numpy", model="exact", tau="auto", iters=100)


def _scene(name: str) -> np.ndarray:
    from skimage import color, data

    from clfza.benchmarks import _scenes as scenes

    return {"camera": lambda: data.camera() / 255.0,
            "astronaut": lambda: color.rgb2gray(data.astronaut()),
            "coins": lambda: data.coins() / 255.0,
            "text": lambda: scenes.scene_image("text"),
            "usaf": lambda: scenes.scene_image("usaf"),
            "horse": lambda: 1.0 - data.horse().astype(float),
            "checker": lambda: data.checkerboard() / 255.0}[name]()


@pytest.mark.parametrize("name", ["camera", "astronaut", "coins"])
def test_photographs_are_continuous_tone(name):
    assert mid_tone_share(_scene(name)) >= 2 * TONE_MID


@pytest.mark.parametrize("name", ["text", "usaf", "horse", "checker"])
def test_graphics_of_two_levels_are_not(name):
    assert mid_tone_share(_scene(name)) < TONE_MID / 2


def test_mid_tone_share_is_the_mean_over_channels_and_nan_when_flat():
    ramp = np.linspace(0.0, 1.0, 400).reshape(20, 20)
    two = (ramp > 0.5).astype(float)
    assert mid_tone_share(np.stack([ramp, two])) == pytest.approx(
        (mid_tone_share(ramp) + mid_tone_share(two)) / 2)
    assert math.isnan(mid_tone_share(np.ones((8, 8))))


def test_tone_factor_law():
    mid = 2 * TONE_MID
    assert tone_factor(mid, TONE_NOISE_REF) == pytest.approx(TONE_FACTOR)
    rs = [TONE_NOISE_MIN, 0.01, 0.1, 0.5]
    fs = [tone_factor(mid, r) for r in rs]
    assert all(a < b for a, b in zip(fs, fs[1:], strict=False)), fs  # lower tau at lower noise
    # not extrapolated below the fit's lowest noise fraction; never above the rule's tau
    assert tone_factor(mid, TONE_NOISE_MIN / 100) == tone_factor(mid, TONE_NOISE_MIN)
    assert tone_factor(mid, 1e6) == 1.0
    # graphics, and an estimate without a tonal range, keep the rule's tau
    assert tone_factor(TONE_MID * 0.99, 0.01) == 1.0
    assert tone_factor(math.nan, 0.01) == 1.0


def _frame(obj, var: float, cam=CAM):
    return clfza.simulate(obj, cam, noise=clfza.Noise(gaussian_var=var, seed=3))


def test_the_route_lowers_tau_on_a_noisy_photograph_and_says_so():
    from clfza.benchmarks import _scenes as scenes

    m = _frame(scenes.natural()[::16, ::16], 1e-4)
    rec = clfza.reconstruct(m.y, CAM, "admm", **KW)
    a = rec.info.stats["tau_auto"]
    assert a["rule"] == "noise" and a["highpass"]
    assert a["mid_tone_share"] >= TONE_MID
    assert a["tone_factor"] == pytest.approx(tone_factor(a["mid_tone_share"],
                                                         a["noise_fraction"]))
    assert a["tone_factor"] < 0.5 and a["w"] == a["tone_factor"]
    ratio = min(CAM.pitch / CAM.r1p, HIGHPASS_PITCH_CAP)
    rule = HIGHPASS_TAU_FACTOR * ratio * a["sigma"] * a["tone_factor"]
    assert a["tau"] == pytest.approx(rule, rel=1e-6)
    note = next(n for n in rec.info.notes if n.startswith("tau=auto"))
    assert "continuous-tone" in note


def test_the_route_keeps_the_rule_on_graphics_and_without_the_highpass():
    from clfza.benchmarks import _scenes as scenes

    text = _frame(scenes.scene_image("text")[::16, ::16], 1e-4)
    a = clfza.reconstruct(text.y, CAM, "admm", **KW).info.stats["tau_auto"]
    assert a["rule"] == "noise" and a["mid_tone_share"] < TONE_MID
    assert a["tone_factor"] == 1.0
    natural = _frame(scenes.natural()[::16, ::16], 1e-4)
    plain = clfza.reconstruct(natural.y, CAM, "admm", highpass=0, **KW).info.stats["tau_auto"]
    assert not plain["highpass"] and plain["tone_factor"] == 1.0
    assert plain["mid_tone_share"] is None


def test_a_photograph_lower_tau_is_the_better_image():
    # the reason for the factor, on the frame above: PSNR at the chosen tau against the rule's
    from clfza.benchmarks import _scenes as scenes
    from clfza.metrics import compare

    m = _frame(scenes.natural()[::16, ::16], 1e-4)
    rec = clfza.reconstruct(m.y, CAM, "admm", **KW)
    a = rec.info.stats["tau_auto"]
    fixed = {k: v for k, v in KW.items() if k != "tau"}
    rule = clfza.reconstruct(m.y, CAM, "admm", tau=a["tau"] / a["tone_factor"], **fixed)
    chosen = clfza.reconstruct(m.y, CAM, "admm", tau=a["tau"], **fixed)
    assert compare(chosen.image, m.truth)["psnr"] > compare(rule.image, m.truth)["psnr"]
