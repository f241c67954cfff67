"""The default route (issue 33): ``clfza.reconstruct(y, cam)`` without a method runs ADMM with
``tau="auto"``, and ``model="auto"`` weighs the frame's noise against the transfer-function
model's error where the camera's sampling alone would choose the exact model.

On the simulation preset cropped to 128^2 (no aperture, far from critical sampling): a
noise-free frame keeps the exact model, the paper's Fig. 7 noise (variance 0.01) takes Eq. 17,
and there the default beats the exact route it replaced; a camera with an aperture keeps the
exact model whatever the noise (Eq. 17 cannot express its open disc).
"""

from __future__ import annotations

import numpy as np
import pytest

import clfza
from clfza.metrics import compare
from clfza.solvers import estimate_noise, method_model, resolve_method, route_model
from clfza.solvers._route import energies

N = 128


@pytest.fixture(scope="module")
def cam():
    return clfza.Camera.preset("simulation").with_shape((N, N))


def _frame(cam, var: float):
    scene = np.zeros((N, N))
    scene[32:96, 40:88] = 1.0
    scene[50:70, 20:110] = 0.5
    return clfza.simulate(scene, cam, object_width=N * cam.pitch,
                          noise=clfza.Noise(gaussian_var=var, seed=3))


def test_noise_estimate_is_the_known_noise(cam):
    m = _frame(cam, 0.01)
    sigma = estimate_noise(m.y, cam)[0]
    assert sigma == pytest.approx(0.1, rel=0.1)
    noise, err = energies(m.y, cam)
    assert noise == pytest.approx(m.y.size * sigma**2) and err > 0


def test_clean_frame_keeps_the_exact_model_noisy_frame_takes_eq17(cam):
    clean, noisy = _frame(cam, 0.0), _frame(cam, 0.01)
    assert method_model(cam, "auto", "admm")[0] == "exact"  # the sampling alone
    assert route_model(clean.y, cam)[0] == "exact"
    kind, why = route_model(noisy.y, cam)
    assert kind == "tf" and "noise swamps" in why
    assert method_model(cam, "auto", "admm", y=noisy.y)[0] == "tf"
    assert method_model(cam, "exact", "admm", y=noisy.y)[0] == "exact"  # asked for
    assert method_model(cam, "auto", "fista", y=clean.y)[0] == "tf"  # not ADMM's choice


def test_an_aperture_keeps_the_exact_model_under_noise():
    exp = clfza.Camera.preset("experiment")
    y = np.random.default_rng(0).normal(size=exp.shape)
    assert method_model(exp, "auto", "admm", y=y)[0] == "exact"


def test_default_reconstruct_is_the_default_route(cam):
    m = _frame(cam, 0.01)
    rec = clfza.reconstruct(m.y, cam)
    info = rec.info
    assert info.method == "admm" and info.params["model"] == "tf"
    assert info.params["method_asked"] == "auto" and "tau_auto" in info.stats
    assert info.notes[0].startswith("method: auto, the default route")
    assert info.notes[1].startswith("model: tf")
    # Eq. 17 at a tenth of the exact model's cost per iteration, and no worse than it: the
    # exact model with its own tau="auto" (before issue 33's rule for it, 3 dB and more below)
    exact = clfza.reconstruct(m.y, cam, "admm", model="exact", tau="auto")
    new_db, exact_db = (compare(rec.image, m.truth)["psnr"],
                        compare(exact.image, m.truth)["psnr"])
    assert new_db >= exact_db - 0.5, (new_db, exact_db)
    # a tau given keeps the route's method and model choice, not its tau
    fixed = clfza.reconstruct(m.y, cam, tau=0.02, iters=20)
    assert fixed.info.method == "admm" and fixed.info.params["tau"] == 0.02
    assert resolve_method("auto", {"weight": 0.01})[1] == {"weight": 0.01}


def test_tau_search_time_leaves_out_the_final_solves_checkpoints():
    """The parts of ``timings`` add up to no more than the whole: ``tau_search`` is what the
    final solve did not spend, and the final solve's checkpoints (here a callback that sleeps
    at each, so that a count in two places would show) are in ``checkpoint_overhead`` alone."""
    import time

    cam = clfza.Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0)
    m = clfza.simulate(np.random.default_rng(0).random((32, 32)), cam,
                       noise=clfza.Noise(gaussian_var=1e-2, seed=1))
    calls = []

    def slow(record):
        calls.append(record["iteration"])
        time.sleep(0.1)

    t = clfza.reconstruct(m.y, cam, "admm", backend="numpy", model="tf", tau="auto", iters=50,
                          checkpoints=10, callback=slow).info.timings
    assert len(calls) >= 3 and t["checkpoint_overhead"] >= 0.1 * len(calls)
    assert t["tau_search"] + t["solve"] + t["checkpoint_overhead"] <= t["total"], t
