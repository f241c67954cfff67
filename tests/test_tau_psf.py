"""``tau="auto"`` with a measured PSF (issue 33, item 2): the noise it reads against the sensor
model's known noise, and the ``tau`` it picks against the hindsight-best ``tau`` of a grid, on a
small :func:`clfza.simulation.simulate_psf_capture` frame.

The rule before read the exact model's ``PLAIN_TAU_FACTOR (p / r1') sigma`` with the placeholder
``r1'`` of a measured-PSF camera (no zone plate) and chose a ``tau`` 30-100x above the best
(bench/bench_tau_psf.py, docs/measurements.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import clfza
from clfza.metrics import compare
from clfza.models import load_psf
from clfza.simulation import Noise, simulate_psf_capture

SIGMA_TOL = 0.15   # relative: the Haar MAD of a 96^2 residual (2304 coefficients), the signal a
#                    pilot pass leaves in it, and the per-pixel photon noise averaged
TAU_FACTOR = 3.0   # the chosen tau within this factor of the grid's best (4 per decade)
PHOTONS, READ, EXPOSURE = 2000.0, 2.0, 0.9


def _capture(n: int = 96, scene=None):
    from skimage import data

    noise = Noise(photons=PHOTONS, read_noise=READ, bit_depth=8, exposure=EXPOSURE, seed=1)
    cap = simulate_psf_capture(data.camera() if scene is None else scene, shape=(n, n),
                               scene_z1=400.0, psf_z1=400.0, noise=noise)
    psf = load_psf(cap.psf, background="border", center="centroid")
    # the sensor model's noise (photon + read + 8-bit quantisation, DN), in the solver's
    # scale-free units: the frame divided by the RMS of y
    fw = PHOTONS / EXPOSURE
    var = float(np.mean(cap.frame)) * 255.0 / fw + (READ * 255.0 / fw) ** 2 + 1.0 / 12.0
    return cap, psf, math.sqrt(var) / float(np.sqrt(np.mean(cap.y ** 2)))


@pytest.mark.parametrize("scene", ["camera", "text"])
def test_psf_auto_reads_the_noise_and_picks_a_tau_near_the_best(scene):
    # a natural scene and a sparse high-contrast one (text: its best tau is ~40x lower, which
    # the rule reads from the pilot estimate's energy support: psf_sparse_factor)
    from clfza.benchmarks import _scenes as scenes

    cap, psf, sigma = _capture(scene=None if scene == "camera" else scenes.text())
    kw = dict(psf=psf, iters=200)
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", tau="auto", **kw)
    a = rec.info.stats["tau_auto"]
    assert a["sigma"] == pytest.approx(sigma, rel=SIGMA_TOL), (a["sigma"], sigma)
    assert a["rule"] == "noise"
    # quarter decades: the grid's best is quantised to 10^0.25 = 1.78x, well inside
    # TAU_FACTOR (a half-decade grid's 3.16x steps left a flat top's best at either end of it)
    taus = [float(t) for t in 10 ** np.arange(-6.0, -1.49, 0.25)]
    psnr = [compare(clfza.reconstruct(cap.y, cap.camera, "admm", tau=t, **kw).image,
                    cap.truth)["psnr"] for t in taus]
    best = taus[int(np.argmax(psnr))]
    assert best not in (taus[0], taus[-1]), psnr  # the grid brackets the best
    chosen = rec.info.params["tau"]
    assert best / TAU_FACTOR <= chosen <= best * TAU_FACTOR, (chosen, best, psnr)
    assert a["kernel"] == "measured_psf"  # the record says which rule it read
    # ... and the note states the rule applied: PSF_TAU_FACTOR x sigma, no r1' (a measured-PSF
    # camera's is a placeholder), times the sparse multiple where the scene is sparse
    assert a["factor"] * a["sigma"] * a["w"] == pytest.approx(a["tau"], rel=1e-9)
    note = next(n for n in rec.info.notes if n.startswith("tau=auto:"))
    assert "r1'" not in note and f"{a['factor']:g} x sigma" in note, note
    assert (f"x {a['w']:g}: the pilot estimate's energy" in note) == (a["w"] != 1.0), note
    assert (a["w"] != 1.0) == (scene == "text"), a  # the sparse scene, and only it


def test_psf_admm_default_is_auto():
    # ADMM's tau is "auto" unless given, with a measured PSF as on the FZA models
    cap, psf, _ = _capture(64)
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, iters=50)
    assert "tau_auto" in rec.info.stats
    assert rec.info.params["tau"] == pytest.approx(rec.info.stats["tau_auto"]["tau"])
    given = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, iters=50, tau=1e-3)
    assert "tau_auto" not in given.info.stats and given.info.params["tau"] == 1e-3


def test_psf_sparse_factor():
    # measured PSF: a pilot estimate whose energy lies in few pixels gets PSF_SPARSE_FACTOR (< 1:
    # sparse high-contrast scenes want a lower tau), every other one (NaN included) x1
    from clfza.solvers._tau_exact import PSF_SPARSE_FACTOR, PSF_SPARSE_SUPPORT, psf_sparse_factor

    assert 0 < PSF_SPARSE_FACTOR < 1
    assert psf_sparse_factor(PSF_SPARSE_SUPPORT / 2) == PSF_SPARSE_FACTOR
    assert psf_sparse_factor(PSF_SPARSE_SUPPORT * 2) == 1.0
    assert psf_sparse_factor(math.nan) == 1.0


def _colour_capture(channels):
    from skimage.transform import resize

    from clfza.benchmarks import _scenes as scenes

    n = 96
    pick = {"camera": lambda: __import__("skimage").data.camera() / 255.0,
            "text": lambda: np.asarray(scenes.text(), float)}
    scene = np.stack([resize(pick[c](), (n, n)) for c in channels], axis=-1)
    noise = Noise(photons=PHOTONS, read_noise=READ, bit_depth=8, exposure=EXPOSURE, seed=1)
    cap = simulate_psf_capture(scene, shape=(n, n), scene_z1=400.0, psf_z1=400.0, noise=noise)
    return cap, load_psf(cap.psf, background="border", center="centroid")


def test_colour_psf_channels_share_the_sparse_scene_decision():
    # a colour PSF's channels are solved one by one; whether the scene is sparse is decided on
    # their mean energy support, and a channel that decided otherwise alone (here the text
    # channel of a frame whose other two are natural) is solved again with the frame's decision
    from clfza.solvers._tau_exact import scene_factor

    cap, psf = _colour_capture(("camera", "camera", "text"))
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, iters=200)
    chans = [c["tau_auto"] for c in rec.info.stats["channels"]]
    joint = rec.info.stats["colour_energy_support"]
    mean = float(np.mean([c["energy_support"] for c in chans]))
    assert joint["mean"] == pytest.approx(mean)
    assert joint["solved_again"] == [2]  # the text channel alone is sparse
    assert scene_factor(chans[2]["energy_support"], True) != scene_factor(mean, True)
    assert [c["w"] for c in chans] == [scene_factor(mean, True)] * 3  # one decision
    assert chans[2]["frame_energy_support"] == pytest.approx(mean)
    assert chans[0]["frame_energy_support"] is None  # decided alone, in agreement
    assert any("mean energy support" in n for n in rec.info.notes), rec.info.notes


def test_frame_energy_support_decides_a_solve_and_is_recorded():
    # the override the colour path uses: a natural frame solved under a sparse frame's support
    # takes the sparse multiple, and its record keeps its own support beside the frame's
    from clfza.solvers import frame_energy_support
    from clfza.solvers._tau_exact import PSF_SPARSE_FACTOR, PSF_SPARSE_SUPPORT

    cap, psf, _ = _capture(64)
    alone = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, iters=50).info.stats
    with frame_energy_support(PSF_SPARSE_SUPPORT / 4):
        told = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, iters=50).info.stats
    a, b = alone["tau_auto"], told["tau_auto"]
    assert a["energy_support"] > PSF_SPARSE_SUPPORT and a["w"] == 1.0
    assert a["frame_energy_support"] is None
    assert b["w"] == PSF_SPARSE_FACTOR and b["frame_energy_support"] == PSF_SPARSE_SUPPORT / 4
    assert b["tau"] == pytest.approx(a["tau"] * PSF_SPARSE_FACTOR, rel=1e-6)


def test_psf_noise_free_frame_gets_the_floor():
    """A noise-free measured-PSF frame: the passes find no noise and ``tau`` is the floor
    ``EXACT_FLOOR rms(y)`` (the mask's noise-free rule ``NOISE_FREE_TAU rms(y)``, 100x higher,
    left these frames 2-11 dB lower; docs/measurements.md), the note names it, and the image
    is better than at the mask rule's tau from the same pilot passes."""
    from unittest import mock

    from skimage import data

    from clfza.solvers import _tau_exact as te

    cap = simulate_psf_capture(data.camera(), shape=(192, 192), scene_z1=400.0, psf_z1=400.0,
                               noise=None)
    psf = load_psf(cap.psf, background="border", center="centroid")
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)
    a = rec.info.stats["tau_auto"]
    assert a["rule"] == "noise_free" and a["kernel"] == "measured_psf"
    rms_solver = math.sqrt(a["y_energy"] / a["operator_norm"] ** 2 / cap.y.size)
    assert a["tau"] == pytest.approx(te.EXACT_FLOOR * rms_solver * a["operator_norm"] ** 2)
    assert "the floor 7e-07 x rms(y), a measured PSF's: no noise found" in " ".join(
        rec.info.notes)
    mask_tau = te.NOISE_FREE_TAU / te.EXACT_FLOOR  # the mask rule's tau, as a multiple
    after = []  # the pilot passes done: the final solve's tau is the next set_tau
    run_passes, set_tau = te._residual_noise, te.set_tau

    def passes(*args, **kw):
        out = run_passes(*args, **kw)
        after.append(True)
        return out

    with mock.patch.object(te, "_residual_noise", passes), mock.patch.object(
            te, "set_tau", lambda opts, tau: set_tau(opts, tau * mask_tau if after else tau)):
        mask = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)
    assert after
    truth = cap.truth
    assert compare(rec.image, truth)["psnr"] > compare(mask.image, truth)["psnr"] + 1.0
