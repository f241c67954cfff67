"""The exact model's data term through a box high-pass (clfza.models._highpass): the filter against
a direct convolution, the filtered model = the filtered simulator on the sensor's interior, the
default width, the solver with it (shape, backends, convergence) and its bad inputs."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from skimage import data

import clfza
from clfza import Camera
from clfza.errors import ClfzaError
from clfza.models._exact import ExactModel
from clfza.models._highpass import (
    default_halfwidth,
    highpass_frame,
    highpass_kernel,
    highpass_model,
    noise_gain,
)
from clfza.simulation import simulate

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def _g(k: int) -> np.ndarray:
    w = 2 * k + 1
    g = -np.ones((w, w)) / w**2
    g[k, k] += 1.0
    return g


@pytest.mark.parametrize("k", [1, 3])
def test_frame_and_kernel_filters_are_the_convolution_with_g(rng, k):
    y = rng.standard_normal((2, 31, 44)) + 5.0
    ref = np.stack([scipy.signal.convolve2d(c, _g(k), mode="valid") for c in y])
    assert np.allclose(highpass_frame(y, k), ref, atol=1e-12)
    ker = rng.standard_normal((9, 12))
    assert np.allclose(highpass_kernel(ker, k), scipy.signal.convolve2d(ker, _g(k)),
                       atol=1e-12)
    assert noise_gain(k) == pytest.approx(np.linalg.norm(_g(k)), rel=1e-12)


@pytest.fixture(scope="module")
def aperture_shot():
    """The experiment preset binned 12x (200^2, binary FZA, R = 4.56 mm)."""
    cam0 = Camera.preset("experiment")
    cam = cam0.with_shape((200, 200), cam0.pitch * 12)
    return cam, simulate(data.camera(), cam, object_width=200.0)


@pytest.mark.parametrize("margin", [0, 5])
def test_filtered_model_is_the_filtered_frame_on_the_interior(aperture_shot, rng, margin):
    """``P C' (g * h) * x = P C' g * (P C h * x)`` to rounding: the high-passed problem is
    the same camera seen through G, nothing approximated."""
    cam, _ = aperture_shot
    K = ExactModel.from_camera(cam, margin)
    k = 4
    M = highpass_model(K, k)
    assert M.sensor == (200 - 2 * k, 200 - 2 * k) and M.image_geom.sensor == (200, 200)
    x = rng.random((200 + 2 * margin,) * 2)
    grid_x = np.zeros(K.shape)
    (oy, ox), m = K.geom.offset, margin
    grid_x[oy - m:oy + 200 + m, ox - m:ox + 200 + m] = x
    y = K.forward(grid_x)
    grid_x2 = np.zeros(M.shape)
    (oy, ox) = M.image_geom.offset
    grid_x2[oy - m:oy + 200 + m, ox - m:ox + 200 + m] = x
    want = ExactModel.remove_mean(highpass_frame(y, k))
    assert np.linalg.norm(M.forward(grid_x2) - want) <= 1e-12 * np.linalg.norm(want)
    # the adjoint identity holds on the filtered model too
    r = rng.standard_normal(M.sensor)
    assert np.isclose(np.vdot(M.forward(grid_x2), r), np.vdot(grid_x2, M.adjoint(r)),
                      rtol=1e-10)


def test_default_halfwidth_follows_r1_and_spares_measured_psfs(aperture_shot):
    cam, _ = aperture_shot
    k = default_halfwidth(cam, None)
    r1_px = cam.r1p / cam.pitch
    assert abs((2 * k + 1) - clfza.models._highpass.HIGHPASS_R1 * r1_px) <= 2.0
    assert default_halfwidth(cam, ExactModel.from_camera(cam)) == k  # a mask's model
    assert default_halfwidth(cam, np.ones((5, 5))) == 0  # a measured PSF: off
    tiny = cam.with_shape((2 * k + 10, 2 * k + 10))
    assert default_halfwidth(tiny, None) == 0  # too little interior left
    coarse = cam.with_shape((96, 96), cam.pitch * 200 / 96)  # r1' = 3.5 pixels
    assert coarse.r1p / coarse.pitch < clfza.models._highpass.MIN_R1_PIXELS
    assert default_halfwidth(coarse, None) == 0  # the box would reach into the zone band


def test_admm_with_highpass_keeps_the_sensor_shape_and_agrees_across_backends(aperture_shot):
    cam, meas = aperture_shot
    kw = {"iters": 15, "stop": "none", "highpass": 5, "tau": 0.005}  # a fixed tau
    ref, rinfo = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", **kw)
    img, info = clfza.reconstruct(meas.clean_y, cam, "admm", **kw)
    assert img.shape == ref.shape == cam.shape
    assert info.params["highpass"] == 5 and any("high-pass" in n for n in info.notes)
    assert np.abs(img - ref).max() <= 1e-3 * np.abs(ref).max()
    assert info.stats["mu1_final"] == rinfo.stats["mu1_final"]


def test_highpass_converges_far_faster_on_the_aperture_camera(aperture_shot):
    """The reason for the default: the disc's low frequencies leave the problem, and ADMM's
    iterate reaches the truth far sooner (same iterations, same tau)."""
    cam, meas = aperture_shot
    kw = {"iters": 150, "tau": 1e-3}
    off = clfza.reconstruct(meas.clean_y, cam, "admm", highpass=0, **kw)
    on = clfza.reconstruct(meas.clean_y, cam, "admm", **kw)
    assert on.info.params["highpass"] > 0 and off.info.params["highpass"] == 0
    p_off = clfza.metrics.compare(off.image, meas.truth)["psnr"]
    p_on = clfza.metrics.compare(on.image, meas.truth)["psnr"]
    assert p_on > p_off + 10.0


def test_start_point_and_truth_are_on_the_sensor(aperture_shot):
    cam, meas = aperture_shot
    recs = []
    img, info = clfza.reconstruct(meas.clean_y, cam, "admm", iters=4, stop="none",
                                  x0=np.full(cam.shape, 0.5), truth=meas.truth,
                                  checkpoints=[2, 4], callback=recs.append)
    assert img.shape == cam.shape and len(info.checkpoints) == 2
    assert all(np.isfinite(c["psnr"]) for c in info.checkpoints)


@pytest.mark.parametrize("bad, match", [(-1, "integer"), (2.5, "integer"), ("4", "integer"),
                                        (99, "leaves")])
def test_bad_highpass_is_one_clear_error(aperture_shot, bad, match):
    cam, meas = aperture_shot
    with pytest.raises(ClfzaError, match=match):
        clfza.reconstruct(meas.clean_y, cam, "admm", iters=2, highpass=bad)


def test_highpass_is_an_exact_model_option():
    cam = Camera.preset("simulation").with_shape((64, 64))
    y = np.zeros((64, 64))
    y[3, 4] = 1.0
    with pytest.raises(ClfzaError, match="exact model"):
        clfza.reconstruct(y, cam, "admm", model="tf", highpass=3)


def test_tau_auto_reads_the_noise_off_the_models_residual(aperture_shot):
    """The pilot passes' noise is the frame's noise where there is noise, and falls far below
    the frame's own (signal-holding) Haar estimate where there is none."""
    cam, meas = aperture_shot
    sigma = 0.03
    noisy = simulate(data.camera(), cam, object_width=200.0,
                     noise=clfza.Noise(gaussian_var=sigma**2, seed=3))
    rec = clfza.reconstruct(noisy.y, cam, "admm", tau="auto")
    a = rec.info.stats["tau_auto"]
    k = rec.info.params["highpass"]
    seen = sigma * np.sqrt(1.0 - 1.0 / (2 * k + 1) ** 2)  # G keeps this much white noise
    assert a["criterion"] == "residual_noise" and 0.8 * seen <= a["sigma"] <= 1.1 * seen
    assert a["rule"] == "noise" and a["residual_white"]
    clean = clfza.reconstruct(meas.clean_y, cam, "admm", tau="auto").info.stats["tau_auto"]
    assert clean["sigma"] < 0.2 * clean["sigma_frame"] and clean["tau"] < 0.1 * a["tau"]
    # no noise: the last pass's residual still holds signal (not white), tau at the
    # noise-free rule, well below what the residual's sigma would give
    assert clean["rule"] == "noise_free" and not clean["residual_white"]
    assert clean["stages"][-1][2] > clean["white_max"]
    assert clean["tau"] < 0.1 * tau_rule_of(clean, cam, k)


def tau_rule_of(a: dict, cam, k: int) -> float:
    """The tau the noise rule would give for the pilot's sigma (user units)."""
    from clfza.solvers._tau_exact import HIGHPASS_TAU_FACTOR

    return HIGHPASS_TAU_FACTOR * cam.pitch / cam.r1p * a["sigma"]


def test_monitor_records_are_in_the_frames_units(aperture_shot):
    """The exact model solves the frame scaled to a fixed RMS; what a callback or a checkpoint
    reads (the planner's discrepancy stop compares it with N sigma^2 of the frame) is in the
    frame's units: ten times the frame (and tau) gives 100 times the residual."""
    cam, meas = aperture_shot
    recs = {}
    for f in (1.0, 10.0):
        got = []
        img, info = clfza.reconstruct(meas.y * f, cam, "admm", iters=5, stop="none",
                                      tau=0.01 * f, callback=got.append, checkpoints=[5])
        recs[f] = (got[-1], info.checkpoints[-1])
    for i in (0, 1):
        for key in ("residual_norm2", "objective"):
            assert recs[10.0][i][key] == pytest.approx(100.0 * recs[1.0][i][key], rel=1e-3)


@pytest.mark.parametrize("colour", ["independent", "joint"])
def test_colour_frames_on_the_exact_model(aperture_shot, colour):
    """Colour on the exact model (with its high-pass): one objective history per channel
    when the channels are solved one by one (the user-units rescaling used to fail on it)."""
    cam, _ = aperture_shot
    m = simulate(data.astronaut() / 255.0, cam, object_width=200.0)
    img, info = clfza.reconstruct(m.clean_y, cam, "admm", iters=5, stop="none", colour=colour)
    assert img.shape == cam.shape + (3,) and np.isfinite(img).all()
    hist = info.objective
    if colour == "independent":
        assert len(hist) == 3 and all(len(h) >= 5 for h in hist)
    else:
        assert all(isinstance(f, float) for f in hist)


@pytest.mark.parametrize("sigma", [1e-6, 1.0, 300.0])
def test_haar_scale_ratio_of_white_noise_is_one(rng, sigma):
    """Orthonormal Haar levels: white noise of any variance has the same MAD at the first and
    second scale (256^2: 16384 and 4096 coefficients, the ratio's spread ~2 %)."""
    from clfza.solvers._noise import haar_scale_ratio

    r = haar_scale_ratio(sigma * rng.standard_normal((256, 256)))
    assert abs(r - 1.0) < 0.08


def test_haar_scale_ratio_sees_signal(rng):
    """A residual that still holds a smooth signal (a Gaussian blob's edges, a ramp's
    curvature) is not white: the ratio is well above ``WHITE_MAX``; odd shapes, zero and
    constant residuals are handled (NaN: no scale holds anything)."""
    from clfza.solvers._noise import haar_scale_ratio
    from clfza.solvers._tau_exact import WHITE_MAX, is_white

    yy, xx = np.mgrid[:255, :201] / 30.0
    smooth = np.sin(xx * yy) + 0.01 * rng.standard_normal(xx.shape)
    assert haar_scale_ratio(smooth) > 1.5 * WHITE_MAX and not is_white(haar_scale_ratio(smooth))
    assert is_white(haar_scale_ratio(rng.standard_normal((255, 201))))
    assert np.isnan(haar_scale_ratio(np.zeros((8, 8))))
    assert np.isnan(haar_scale_ratio(np.full((8, 8), 3.0))) and not is_white(float("nan"))
