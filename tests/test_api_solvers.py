"""The public API for the iterative solvers: info record, colour, checkpoints, bad input."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import clfza
from clfza import Camera, ClfzaError
from clfza.solvers import ClfzaWarning

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


@pytest.fixture(scope="module")
def setup():
    cam = Camera(pitch=0.01, shape=(64, 64), r1=0.08 / 1.015, z1=200.0, z2=3.0, mask="gzp")
    t = np.zeros((64, 64, 3))
    t[15:45, 20:40, 0] = 1.0
    t[25:55, 10:30, 1] = 0.7
    t[10:30, 30:60, 2] = 0.4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = clfza.simulate(t, cam, sensor_plane=True)
    return cam, m


def test_info_record(setup):
    cam, m = setup
    y = m.y[..., 0]
    image, info = clfza.reconstruct(y, cam, "twist", tau=0.01, iters=5)
    assert image.shape == y.shape and np.isfinite(image).all()
    assert info.method == "twist" and info.mode == "paper" and info.iterations == 6
    assert set(info.timings) >= {"compile", "plan", "solve", "total"}
    assert info.device and info.dtype == "float32" and info.stop_reason == "max_iters"
    assert len(info.objective) == 7 and info.evaluations >= 6 and info.ffts >= 6


@pytest.mark.parametrize("method", ["twist", "fista", "admm"])
@pytest.mark.parametrize("colour", ["independent", "joint"])
def test_colour(setup, method, colour):
    cam, m = setup
    r = clfza.reconstruct(m.y, cam, method, iters=8, colour=colour, truth=m.truth,
                          checkpoints=[4])
    assert r.image.shape == m.y.shape and np.isfinite(r.image).all()
    recs = r.info.checkpoints
    assert any(c["iteration"] == 4 for c in recs) and all("psnr" in c for c in recs)


def test_joint_numpy_matches_opencl(setup):
    cam, m = setup
    rn = clfza.reconstruct(m.y, cam, "fista", backend="numpy", iters=10, colour="joint")
    ro = clfza.reconstruct(m.y, cam, "fista", backend="opencl", iters=10, colour="joint")
    assert np.max(np.abs(rn.image - ro.image)) < 1e-3 * np.abs(rn.image).max()


@pytest.mark.parametrize("method,opts", [("twist", {"mode": "paper"}), ("fista", {}),
                                         ("admm", {})])
@pytest.mark.parametrize("shape", [(64, 64), (30, 34)])
def test_joint_colour_device_fft_matches_numpy(method, opts, shape):
    """Joint colour (C = 3) on the device FFT, the default on GPUs, against the float64
    reference: at 64^2 every channel plane is a sub-buffer of the (3, H, W) arrays, at 30x34
    the planes' byte offsets miss the base-address alignment and go through scratch copies.
    Float32 after 6 iterations: 1e-3 of the image scale, as for the host FFT above."""
    cam = Camera(pitch=0.01, shape=shape, r1=0.08 / 1.015, z1=200.0, z2=3.0, mask="gzp")
    t = np.random.default_rng(5).random(shape + (3,))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        y = clfza.simulate(t, cam, sensor_plane=True).y
    kw = dict(iters=6, min_iters=6, stop="none", colour="joint", **opts)
    a = clfza.reconstruct(y, cam, method, backend="opencl", fft="device", **kw).image
    b = clfza.reconstruct(y, cam, method, backend="numpy", **kw).image
    assert a.shape == b.shape == y.shape
    assert np.max(np.abs(a - b)) < 1e-3 * np.abs(b).max()


def test_checkpoint_callback_and_cost(setup):
    cam, m = setup
    seen = []
    r = clfza.reconstruct(m.y[..., 0], cam, "admm", iters=12, checkpoints=4,
                          truth=m.truth[..., 0], callback=seen.append)
    assert [c["iteration"] for c in seen] == [4, 8, 12]
    assert all(k in seen[0] for k in ("time", "objective", "mse", "psnr", "ssim"))
    assert r.info.timings["checkpoint_overhead"] > 0
    assert seen[-1]["time"] <= r.info.timings["solve"] + 1e-9


@pytest.mark.parametrize("bad", [{"tau": -1}, {"tau": float("nan")}, {"tau": float("inf")},
                                 {"iters": 0}, {"reg": "l2"}, {"mode": "fast"},
                                 {"colour": "rgb"}, {"bogus": 1}, {"stop": "never"}])
def test_bad_options(setup, bad):
    cam, m = setup
    with pytest.raises(ClfzaError):
        clfza.reconstruct(m.y[..., 0], cam, "twist", **bad)


def test_bad_measurements(setup):
    cam, m = setup
    y = m.y[..., 0].copy()
    with pytest.raises(ClfzaError):
        clfza.reconstruct(y[:32], cam, "twist")
    for v in (np.nan, np.inf):
        yb = y.copy()
        yb[3, 3] = v
        with pytest.raises(ClfzaError):
            clfza.reconstruct(yb, cam, "fista")
    with pytest.raises(ClfzaError):
        clfza.reconstruct(y, cam, "nope")


@pytest.mark.parametrize("value", [0.0, 2.5])
def test_constant_measurement_warns_and_returns_zeros(setup, value):
    cam, _ = setup
    with pytest.warns(ClfzaWarning):
        r = clfza.reconstruct(np.full((64, 64), value), cam, "twist")
    assert np.all(r.image == 0) and r.info.stop_reason == "constant_measurement"


@pytest.mark.parametrize("method", ["twist", "fista", "admm"])
def test_callback_true_stops_and_records_carry_the_data_term(setup, method):
    """callback(record) -> True stops with stop_reason "callback"; without checkpoints the
    callback sees every iteration, with ``data`` = 1/2 ||y - K x||^2 of that iterate."""
    from clfza.models._transfer import NumpyOperator

    cam, m = setup
    y = m.y[..., 0]
    seen = []

    def cb(rec):
        seen.append(rec)
        return rec["iteration"] >= 3

    r = clfza.reconstruct(y, cam, method, iters=50, callback=cb)
    assert r.info.stop_reason == "callback" and r.info.iterations == 3
    its = [c["iteration"] for c in seen]
    assert its[-3:] == [1, 2, 3] and its[0] in (0, 1)  # ADMM has no iteration-0 record
    last = seen[-1]
    assert all(k in last for k in ("iteration", "time", "objective", "data", "residual_norm2"))
    assert last["residual_norm2"] == pytest.approx(2 * last["data"])
    op = NumpyOperator(cam, "tf", warn=False)
    r2 = float(np.sum((y - op.forward(r.image)) ** 2))
    assert last["residual_norm2"] == pytest.approx(r2, rel=1e-3)
    # False / None continue
    r = clfza.reconstruct(y, cam, method, iters=5, callback=lambda rec: None)
    assert r.info.stop_reason != "callback"


def test_admm_nonneg_returns_the_projection(setup):
    cam, m = setup
    for backend in ("numpy", "opencl"):
        r = clfza.reconstruct(m.y[..., 0], cam, "admm", backend=backend, iters=15, nonneg=True)
        assert r.image.min() >= 0.0


def test_twist_tv_tol_options(setup):
    cam, m = setup
    y = m.y[..., 0]
    with pytest.raises(ClfzaError):  # paper mode is the reference: no adaptive inner stop
        clfza.reconstruct(y, cam, "twist", tv_tol=1e-2)
    rn = clfza.reconstruct(y, cam, "twist", backend="numpy", mode="efficient", iters=20,
                           tv_iters=6, tv_tol=0.05)
    ro = clfza.reconstruct(y, cam, "twist", backend="opencl", mode="efficient", iters=20,
                           tv_iters=6, tv_tol=0.05)
    assert rn.info.iterations == ro.info.iterations == 20
    inner = ro.info.stats["inner_tv_iterations"]
    assert inner < 6 * ro.info.evaluations  # the adaptive stop saved inner steps
    assert abs(inner - rn.info.stats["inner_tv_iterations"]) <= 0.1 * inner
    assert np.max(np.abs(ro.image - rn.image)) < 1e-3 * np.abs(rn.image).max()


def test_no_option_is_documented_as_unused():
    """Every option a method lists does something: ADMM has no inner TV iterations (its
    z-update is exact) and rejects tv_iters; the direct Wiener solve has one step."""
    from clfza.solvers import options_class

    for method in ("twist", "fista", "admm", "wiener"):
        for f in dataclasses.fields(options_class(method)):
            assert "unused" not in f.metadata.get("doc", ""), (method, f.name)
    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.055, z1=20.0, z2=3.0, R=None)
    y = clfza.simulate(np.ones((8, 8)), cam).y
    with pytest.raises(clfza.ClfzaError, match="tv_iters"):
        clfza.reconstruct(y, cam, "admm", tv_iters=3)
    with pytest.raises(clfza.ClfzaError, match="direct solve"):
        clfza.reconstruct(y, cam, "wiener", iters=5)
    assert clfza.reconstruct(y, cam, "wiener", iters=1, backend="numpy").info.iterations == 1
