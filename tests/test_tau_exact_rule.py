"""``tau="auto"`` on the exact model (issue 33, item 2): the noise it reads against the known
noise of the frame, and the ``tau`` it picks against the hindsight-best ``tau`` of a grid.

The former rule without the high-pass read the frame's Haar estimate as an upper bound that holds
signal and scaled it by a noise-free constant: on a noisy frame it chose a ``tau`` ~100x below
the best (clfza.solvers._tau_exact, docs/measurements.md)."""

from __future__ import annotations

import numpy as np
import pytest

import clfza
from clfza.metrics import compare
from clfza.models import noise_gain

SIGMA_TOL = 0.15   # relative: the Haar MAD of a 64^2 residual (1024 coefficients) and the
#                    signal a 100-iteration pilot leaves in it
TAU_FACTOR = 3.0   # the chosen tau within this factor of the grid's best (grid: 2 per decade)


def _frame(cam, var: float, seed: int = 3):
    from clfza.benchmarks import _scenes as scenes

    obj = scenes.natural()[::16, ::16]  # 32^2
    m = clfza.simulate(obj, cam, noise=clfza.Noise(gaussian_var=var, seed=seed))
    return m, float(np.std(m.y - m.clean_y))


def test_exact_auto_reads_the_noise_and_picks_a_tau_near_the_best():
    # no aperture: the exact model without the high-pass (the simulation preset's case)
    cam = clfza.Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0)
    m, sigma = _frame(cam, 1e-2)
    kw = dict(backend="numpy", model="exact", iters=100)
    rec = clfza.reconstruct(m.y, cam, "admm", tau="auto", **kw)
    a = rec.info.stats["tau_auto"]
    assert rec.info.params["highpass"] == 0
    assert a["sigma"] == pytest.approx(sigma, rel=SIGMA_TOL), (a["sigma"], sigma)
    assert a["rule"] == "noise"  # never the noise-free rule (or the floor) on a noisy frame
    taus = [float(t) for t in 10 ** np.arange(-3.0, 1.01, 0.5)]
    psnr = [compare(clfza.reconstruct(m.y, cam, "admm", tau=t, **kw).image, m.truth)["psnr"]
            for t in taus]
    best = taus[int(np.argmax(psnr))]
    assert 0 < np.argmax(psnr) < len(taus) - 1, psnr  # the grid brackets the best
    assert best / TAU_FACTOR <= a["tau"] <= best * TAU_FACTOR, (a["tau"], best, psnr)


@pytest.mark.parametrize("var", [1e-3, 1e-2])
def test_exact_auto_noise_estimate_with_the_highpass(var):
    # finite aperture: the data term's box high-pass scales white noise by noise_gain(k); the
    # pilot's residual estimate is of that noise
    cam = clfza.Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0, R=0.6)
    m, sigma = _frame(cam, var)
    rec = clfza.reconstruct(m.y, cam, "admm", backend="numpy", model="exact", tau="auto",
                            iters=100)
    a = rec.info.stats["tau_auto"]
    k = rec.info.params["highpass"]
    assert k > 0 and a["criterion"] == "residual_noise" and a["rule"] == "noise"
    assert a["sigma"] == pytest.approx(sigma * noise_gain(k), rel=SIGMA_TOL), (a, sigma)


def test_exact_auto_noise_free_without_highpass_reads_the_pilot_sigma():
    # without the high-pass a noise-free frame's tau is NOISE_FREE_PLAIN_SHARE times the noise
    # rule's tau on the pilot's last sigma (rms(y), the rule with the high-pass, holds the
    # aperture's bright disc there), at least the floor; and it stays below a noisy frame's
    from clfza.benchmarks import _scenes as scenes
    from clfza.solvers._tau_exact import NOISE_FREE_PLAIN_SHARE, PLAIN_TAU_FACTOR

    cam = clfza.Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0, R=0.6)
    kw = dict(backend="numpy", model="exact", tau="auto", iters=100, highpass=0)
    clean = clfza.simulate(scenes.natural()[::16, ::16], cam)
    a = clfza.reconstruct(clean.y, cam, "admm", **kw).info.stats["tau_auto"]
    assert a["rule"] == "noise_free" and not a["highpass"], a
    rule = NOISE_FREE_PLAIN_SHARE * PLAIN_TAU_FACTOR * cam.pitch / cam.r1p * a["sigma"]
    assert a["tau"] == pytest.approx(rule, rel=1e-6), (a["tau"], rule)
    m, _ = _frame(cam, 1e-3)
    noisy = clfza.reconstruct(m.y, cam, "admm", **kw).info.stats["tau_auto"]
    assert noisy["rule"] == "noise" and a["tau"] < noisy["tau"], (a["tau"], noisy["tau"])


@pytest.mark.parametrize("pitch", [0.005, 0.01])
def test_the_highpass_rule_caps_the_pitch_at_the_fit_cameras(pitch):
    """``tau = HIGHPASS_TAU_FACTOR min(p / r1', HIGHPASS_PITCH_CAP) sigma`` (times the
    sparse-scene factor ``w``): the best ``tau / sigma`` stops growing with the pitch at the
    camera the factor was fitted on; the record and the note say when the cap applies."""
    from clfza.solvers._tau_exact import HIGHPASS_PITCH_CAP, HIGHPASS_TAU_FACTOR

    cam = clfza.Camera(pitch=pitch, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0, R=0.6)
    m, _ = _frame(cam, 1e-2)
    rec = clfza.reconstruct(m.y, cam, "admm", backend="numpy", model="exact", tau="auto",
                            iters=100)
    a = rec.info.stats["tau_auto"]
    ratio = cam.pitch / cam.r1p
    capped = ratio > HIGHPASS_PITCH_CAP
    assert capped is (pitch == 0.01) and a["highpass"] and a["rule"] == "noise"
    assert a["pixel_r1_capped"] is capped
    assert a["pixel_r1"] == min(ratio, HIGHPASS_PITCH_CAP)
    rule = HIGHPASS_TAU_FACTOR * min(ratio, HIGHPASS_PITCH_CAP) * a["sigma"] * a["w"]
    assert a["tau"] == pytest.approx(rule, rel=1e-6), (a["tau"], rule)
    note = next(n for n in rec.info.notes if n.startswith("tau=auto"))
    assert ("capped at" in note) is capped


def test_the_noise_free_verdict_reads_the_pass_that_gave_sigma(monkeypatch):
    """A last pass that did not converge at its lower tau can leave a structured residual above
    an earlier white one; sigma is the earlier pass's, and so is the verdict: noise, not the
    noise-free rule (seen on the 60 um experiment camera at variance 1e-4)."""
    from clfza.solvers import _tau_exact

    cam = clfza.Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0, R=0.6)
    m, sigma = _frame(cam, 1e-3)
    real = _tau_exact._residual_noise
    seen = {}

    def passes(cls, B, opts, x, ctx, factor=_tau_exact.HIGHPASS_TAU_FACTOR):
        x, found, stages, total, state = real(cls, B, opts, x, ctx, factor)
        low = found * 0.1  # far below the frame's own estimate, as on that camera
        # a white pass that set sigma, then a structured one above it
        stages = [(1.0, 4 * low, 1.6), (0.5, low, 1.0), (0.1, 1.5 * low, 1.5)]
        seen["frame"] = ctx.group.sigma
        return x, low, stages, total, None

    monkeypatch.setattr(_tau_exact, "_residual_noise", passes)
    a = clfza.reconstruct(m.y, cam, "admm", backend="numpy", model="exact", tau="auto",
                          iters=100).info.stats["tau_auto"]
    assert a["sigma"] <= _tau_exact.NOISE_FREE_FALL * seen["frame"]  # it fell far enough
    assert not _tau_exact.is_white(a["stages"][-1][2])  # and the last pass is structured
    assert a["rule"] == "noise", a["rule"]
