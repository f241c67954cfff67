"""The objective rule's window (``stop_window``) and the final solve of ``tau="auto"`` on Eq. 17.

``stop_window=W`` makes every iterative method read the objective's change over ``W``
iterations, so no stop comes before iteration ``W + 1`` even with a tolerance every step
meets. The default route's final ADMM solve (after the discrepancy search) stops on the spread
of the objective over :data:`~clfza.solvers._tau.FINAL_STOP_WINDOW` iterations at
:data:`~clfza.solvers._tau.FINAL_TOL` unless the user gives ``tol``, ``stop`` or
``stop_window``; the record and the note say which rule ran, one frame or a batch.
"""

from __future__ import annotations

import numpy as np
import pytest

import clfza
from clfza.errors import ClfzaError
from clfza.solvers._tau import FINAL_STOP_WINDOW, FINAL_TOL

N = 64


@pytest.fixture(scope="module")
def cam():
    return clfza.Camera.preset("simulation").with_shape((N, N))


def _frame(cam, seed: int = 3, var: float = 0.01):
    scene = np.zeros((N, N))
    scene[16:48, 20:44] = 1.0
    scene[25:35, 10:55] = 0.5
    return clfza.simulate(scene, cam, object_width=N * cam.pitch,
                          noise=clfza.Noise(gaussian_var=var, seed=seed))


@pytest.mark.parametrize("method", ["admm", "fista", "twist"])
def test_the_window_holds_off_a_tolerance_every_step_meets(cam, method):
    # with tol 1e3 the relative change always passes: the one-step rule stops at the first
    # iteration that has a previous objective, the window only once it has W + 1 values
    y = _frame(cam).y
    one = clfza.reconstruct(y, cam, method, tau=0.01, tol=1e3, stop_window=1, min_iters=1,
                            backend="numpy", model="tf")
    win = clfza.reconstruct(y, cam, method, tau=0.01, tol=1e3, stop_window=7, min_iters=1,
                            backend="numpy", model="tf")
    assert one.info.iterations <= 2
    assert 7 <= win.info.iterations <= 8
    assert win.info.stop_reason == "objective_change"
    assert win.info.params["stop_window"] == 7


def test_the_window_on_the_exact_model_replaces_its_own(cam):
    y = _frame(cam, var=1e-4).y
    res = clfza.reconstruct(y, cam, "admm", model="exact", tau=0.01, tol=1e3, stop_window=3,
                            backend="numpy")
    assert 3 <= res.info.iterations <= 4  # its own window is 20


def test_a_window_below_one_is_refused(cam):
    with pytest.raises(ClfzaError, match="stop_window"):
        clfza.reconstruct(_frame(cam).y, cam, "admm", tau=0.01, stop_window=0)


def test_the_default_routes_final_solve_stops_on_the_window(cam):
    rec = clfza.reconstruct(_frame(cam).y, cam)
    assert rec.info.params["model"] == "tf"
    assert rec.info.params["stop_window"] == FINAL_STOP_WINDOW
    assert rec.info.params["tol"] == FINAL_TOL
    assert rec.info.stats["tau_auto"]["final_stop"] == {"stop_window": FINAL_STOP_WINDOW,
                                                        "tol": FINAL_TOL}
    assert f"spread over {FINAL_STOP_WINDOW} iterations" in " ".join(rec.info.notes)
    # never before the window is full
    assert rec.info.iterations > FINAL_STOP_WINDOW or rec.info.stop_reason == "max_iters"


@pytest.mark.parametrize("given", [{"tol": 1e-7}, {"stop": "step"}, {"stop_window": 1}])
def test_a_given_stopping_rule_is_kept(cam, given):
    rec = clfza.reconstruct(_frame(cam).y, cam, **given)
    assert rec.info.stats["tau_auto"]["final_stop"] is None
    assert rec.info.params["stop_window"] == given.get("stop_window")
    assert rec.info.params["tol"] == given.get("tol", 1e-6)
    assert "spread over" not in " ".join(rec.info.notes)


def test_a_batch_stops_its_frames_as_one_frame_is_stopped(cam):
    frames = [_frame(cam, seed=s) for s in (1, 2)]
    images, infos = clfza.reconstruct(np.stack([m.y for m in frames]), cam)
    for m, info, image in zip(frames, infos, images, strict=True):
        one = clfza.reconstruct(m.y, cam)
        assert info.stats["tau_auto"]["final_stop"] == one.info.stats["tau_auto"]["final_stop"]
        assert info.iterations == one.info.iterations
        np.testing.assert_allclose(image, one.image, atol=1e-4 * np.abs(one.image).max())
