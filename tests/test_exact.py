"""The exact finite-aperture model: simulator = operator, adjoints, grids, model choice, and the
solvers on it (numpy float64 reference against OpenCL float32)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.fft
from skimage import data

import clfza
from clfza import Camera
from clfza.errors import ClfzaError
from clfza.models._exact import ExactModel, choose_model, model_grid, place_kernel
from clfza.simulation import simulate

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def _camera(n=96, ratio=1.0, mask="gzp", R=None, center=(0.0, 0.0), wavelength=None):
    p, z1, z2 = 0.01, 300.0, 3.0
    r1p = np.sqrt(ratio * n * p * p)
    return Camera(pitch=p, shape=(n, n + 8), r1=r1p / (1 + z2 / z1), z1=z1, z2=z2, R=R,
                  mask=mask, mask_center=center, wavelength=wavelength)


@pytest.mark.parametrize("mask", ["fza", "gzp"])
@pytest.mark.parametrize("R", [None, 0.3])
@pytest.mark.parametrize("ratio", [0.6, 1.0, 1.4])
def test_operator_equals_simulator(mask, R, ratio):
    """y = K_exact truth to rounding in every mask/aperture/sampling regime."""
    cam = _camera(ratio=ratio, mask=mask, R=R)
    meas = simulate(data.camera(), cam, object_width=0.4 * 104 * 0.01 / cam.magnification)
    K = ExactModel.from_camera(cam)
    ky = K.forward(K.geom.embed(meas.truth))
    assert np.linalg.norm(ky - meas.clean_y) <= 1e-12 * np.linalg.norm(meas.clean_y)


@pytest.mark.parametrize("extra", [dict(center=(3.0, -2.5)), dict(wavelength=5.5e-4)])
def test_operator_equals_simulator_offset_and_diffraction(extra):
    cam = _camera(mask="fza", R=0.35, **extra)
    diffraction = "wavelength" in extra
    meas = simulate(data.camera(), cam, object_width=0.3 * 104 * 0.01 / cam.magnification,
                    diffraction=diffraction)
    K = ExactModel.from_camera(cam, diffraction=diffraction)
    ky = K.forward(K.geom.embed(meas.truth))
    assert np.linalg.norm(ky - meas.clean_y) <= 1e-12 * np.linalg.norm(meas.clean_y)


def test_grid_is_fast_and_smaller_than_twice_the_sensor_with_an_aperture():
    cam = _camera(n=128, R=0.3)  # aperture radius 30 px: the grid needs ~N + 31, not 2N
    K = ExactModel.from_camera(cam)
    for g, s in zip(K.shape, cam.shape, strict=True):
        assert g == scipy.fft.next_fast_len(g, real=True)
        assert s + 30 <= g < 2 * s - 1
    unbounded = ExactModel.from_camera(_camera(n=128))
    assert all(g >= 2 * s - 1 for g, s in zip(unbounded.shape, cam.shape, strict=True))


def test_grid_holds_margin_and_kernel():
    g = model_grid((50, 60), (41, 21), margin=7)
    assert g.offset == (7, 7)
    assert g.grid[0] >= 50 + 7 + 20 and g.grid[1] >= 60 + 14
    k = np.arange(9.0).reshape(3, 3)
    placed = place_kernel(k, (8, 8), (5, 5))
    assert placed[0, 0] == 4 and placed[-1, -1] == 0 and placed[1, 1] == 8


def test_adjoint_identity_numpy(rng):
    K = ExactModel.from_camera(_camera(mask="fza", R=0.3, center=(1.5, -2.0)), margin=4)
    x = rng.standard_normal(K.shape)
    y = rng.standard_normal(K.sensor)
    lhs, rhs = np.vdot(K.forward(x), y), np.vdot(x, K.adjoint(y))
    assert abs(lhs - rhs) <= 1e-12 * abs(lhs)


def test_opencl_data_term_matches_numpy(rng):
    """resid_grad (gradient and residual norm) of the OpenCL exact backend against float64."""
    from clfza.backends import get_backend

    cam = _camera(mask="fza", R=0.3, center=(2.0, 1.0))
    nb = get_backend("numpy", cam, model="exact")
    cb = get_backend("opencl", cam, model="exact")
    y = rng.standard_normal(cam.shape)
    nb.set_measurement(y[None])
    cb.set_measurement(y[None])
    x = rng.standard_normal((1,) + nb.shape)
    gn, gc = nb.empty(), cb.empty()
    dn = nb.resid_grad(x, gn).get()[0]
    dc = cb.resid_grad(cb.from_host(x), gc).get()[0]
    gc = cb.to_host(gc)
    # float32: a few ulps per FFT pass, relative to the largest value
    assert abs(dc - dn) <= 1e-5 * dn
    assert np.abs(gc - gn).max() <= 2e-5 * np.abs(gn).max()
    assert np.abs(cb.to_host(cb.b) - nb.b).max() <= 2e-5 * np.abs(nb.b).max()
    # the unit gradient step x + K^T (y - K x) (FISTA's), on both
    ws, wc = nb.empty(), cb.empty()
    assert nb.resid_grad(x, ws, step=True).get()[0] == dn
    np.testing.assert_allclose(ws, gn + x, rtol=0, atol=1e-12 * np.abs(gn + x).max())
    cb.resid_grad(cb.from_host(x), wc, step=True)
    assert np.abs(cb.to_host(wc) - ws).max() <= 2e-5 * np.abs(ws).max()
    # the data term alone (no gradient) is the same number
    assert nb.data_term(x) == pytest.approx(dn, rel=1e-12)
    assert abs(cb.data_term(cb.from_host(x)) - dn) <= 1e-5 * dn


def test_choose_model():
    assert choose_model(_camera(R=0.3), "auto", method="admm")[0] == "exact"
    assert choose_model(_camera(ratio=1.0), "auto", method="admm")[0] == "tf"
    assert choose_model(_camera(ratio=1.6), "auto", method="admm")[0] == "exact"
    assert choose_model(_camera(ratio=1.6), "auto", method="fista")[0] == "tf"
    assert choose_model(_camera(ratio=1.6, R=0.3), "auto", method="fista")[0] == "exact"
    assert choose_model(_camera(center=(1.0, 0.0)), "auto", method="fista")[0] == "exact"
    assert choose_model(_camera(R=0.3), "auto", method="bp")[0] == "tf"
    assert choose_model(_camera(R=0.3), "auto", method="twist", mode="paper")[0] == "tf"
    assert choose_model(_camera(), "tf", psf=False)[0] == "tf"
    assert choose_model(_camera(), "auto", psf=True)[0] == "exact"
    with pytest.raises(ClfzaError, match="measured PSF"):
        choose_model(_camera(), "tf", psf=True)
    with pytest.raises(ClfzaError, match="model must be one of"):
        choose_model(_camera(), "wrong")


@pytest.fixture(scope="module")
def aperture_shot():
    """The experiment preset binned 12x (200^2, binary FZA, R = 4.56 mm): its frame is
    dominated by the aperture's open disc."""
    cam0 = Camera.preset("experiment")
    cam = cam0.with_shape((200, 200), cam0.pitch * 12)
    return cam, simulate(data.camera(), cam, object_width=200.0)


def _footprint_psnr(img, truth):
    rows, cols = np.where(truth.any(1))[0], np.where(truth.any(0))[0]
    fp = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    return clfza.metrics.compare(img[fp], truth[fp])["psnr"]


def test_admm_crop_recovers_the_aperture_camera(aperture_shot):
    """The TF model returns a blob on this camera; the exact model's ADMM recovers it."""
    cam, meas = aperture_shot
    tf, _ = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", model="tf",
                              iters=60)
    ex, info = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", iters=60)
    assert info.params["model"] == "exact"
    assert "finite aperture" in info.notes[0]
    p_tf, p_ex = _footprint_psnr(tf, meas.truth), _footprint_psnr(ex, meas.truth)
    assert p_ex > 25.0 and p_ex > p_tf + 10.0
    assert ex.min() >= 0  # non-negativity is on by default on the exact model


@pytest.mark.parametrize("method", ["admm", "fista", "bp"])
def test_opencl_solvers_match_numpy_on_the_exact_model(aperture_shot, method):
    cam, meas = aperture_shot
    # a fixed tau (ADMM's default is "auto", whose choice differs by float32 rounding)
    kw = {"model": "exact"} if method == "bp" else {"iters": 15, "stop": "none",
                                                     "tau": 0.005}
    ref, rinfo = clfza.reconstruct(meas.clean_y, cam, method, backend="numpy", **kw)
    img, info = clfza.reconstruct(meas.clean_y, cam, method, **kw)
    assert info.params["model"] == "exact" and img.shape == cam.shape
    # float32 against float64 after 15 iterations (ADMM: mu1 adapted identically)
    assert np.abs(img - ref).max() <= 1e-3 * np.abs(ref).max()
    if method == "admm":
        assert info.stats["mu1_final"] == rinfo.stats["mu1_final"]


@pytest.mark.parametrize("relax", [1.6, 1.9])
def test_over_relaxed_admm_matches_numpy_and_checks_its_factor(aperture_shot, relax):
    """``relax`` (over-relaxation of v = H x, folded into the dual) on both backends; it
    changes the path; the factor must lie in (0, 2) and belongs to the exact model."""
    cam, meas = aperture_shot
    kw = {"iters": 15, "stop": "none", "relax": relax}
    ref, rinfo = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", **kw)
    img, info = clfza.reconstruct(meas.clean_y, cam, "admm", **kw)
    assert info.params["relax"] == relax == rinfo.params["relax"]
    assert np.abs(img - ref).max() <= 1e-3 * np.abs(ref).max()
    plain, pinfo = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy",
                                     **{**kw, "relax": None})
    assert pinfo.params["relax"] == 1.0
    assert np.abs(plain - ref).max() > 1e-3 * np.abs(ref).max()
    for bad in (0.0, 2.0, -1.0, "fast"):
        with pytest.raises(ClfzaError, match="relax"):
            clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", relax=bad)
    with pytest.raises(ClfzaError, match="relax"):
        clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", model="tf", relax=1.5)


@pytest.mark.parametrize("mode", ["efficient", "paper"])
def test_twist_and_fista_objective_monotone_on_the_exact_model(aperture_shot, mode):
    cam, meas = aperture_shot
    _, info = clfza.reconstruct(meas.clean_y, cam, "twist", backend="numpy", model="exact",
                                mode=mode, iters=20, tau=1e-3)
    f = np.array(info.objective)
    assert np.all(np.diff(f) <= 1e-12 * f[0]) and f[-1] < f[0]
    _, info = clfza.reconstruct(meas.clean_y, cam, "fista", backend="numpy", iters=20)
    f = np.array(info.objective)
    assert np.all(np.diff(f) <= 1e-12 * f[0]) and f[-1] < f[0]


def test_measured_psf_is_scale_free_and_a_given_model_is_used_as_is(aperture_shot):
    """A PSF's and a frame's scales are arbitrary: scaling them scales the image and nothing
    else. A model passed as ``psf`` (here the camera's own) reproduces the camera-model
    solve exactly."""
    from clfza.models._exact import shadow_kernel

    cam, meas = aperture_shot
    psf = shadow_kernel(cam)
    a, info = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", iters=10, psf=psf)
    assert "measured PSF" in info.notes[0]
    b, _ = clfza.reconstruct(3.0 * meas.clean_y, cam, "admm", backend="numpy", iters=10,
                             psf=7.0 * psf)
    np.testing.assert_allclose(b, a * 3.0 / 7.0, rtol=0, atol=1e-9 * np.abs(a).max())
    c, _ = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", iters=10)
    d, _ = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", iters=10,
                             psf=ExactModel.from_camera(cam))
    np.testing.assert_allclose(c, d, rtol=0, atol=1e-9 * np.abs(c).max())
    with pytest.raises(ClfzaError, match="transfer-function"):
        clfza.reconstruct(meas.clean_y, cam, "bp", psf=psf, model="tf")
    with pytest.raises(ClfzaError, match="positive sum"):
        clfza.reconstruct(meas.clean_y, cam, "admm", psf=-psf)


def test_colour_psf_per_channel(aperture_shot):
    from clfza.models._exact import shadow_kernel

    cam, meas = aperture_shot
    psf = shadow_kernel(cam)
    y3 = np.stack([meas.clean_y, 0.5 * meas.clean_y, 0 * meas.clean_y + meas.clean_y], -1)
    img, info = clfza.reconstruct(y3, cam, "bp", backend="numpy", model="exact",
                                  psf=np.stack([psf] * 3, -1))
    assert img.shape == cam.shape + (3,)
    np.testing.assert_allclose(img[..., 1], 0.5 * img[..., 0], atol=1e-9 * np.abs(img).max())
    with pytest.raises(ClfzaError, match="colour PSF"):
        clfza.reconstruct(meas.clean_y, cam, "bp", psf=np.stack([psf] * 3, -1))


def test_bad_psf_is_one_clear_error(aperture_shot):
    cam, meas = aperture_shot
    for bad in (np.zeros((9, 9)), np.full((9, 9), np.nan)):
        with pytest.raises(ClfzaError, match="finite, non-zero"):
            clfza.reconstruct(meas.clean_y, cam, "bp", psf=bad)


def test_camera_replace_keeps_model_cache_sound(aperture_shot):
    cam, meas = aperture_shot
    other = replace(cam, R=3.0)
    a, _ = clfza.reconstruct(meas.clean_y, cam, "bp", backend="numpy", model="exact")
    b, _ = clfza.reconstruct(meas.clean_y, other, "bp", backend="numpy", model="exact")
    assert not np.allclose(a, b)


def test_binned_model_matches_a_binned_frame():
    """Pixel binning of a full-resolution frame is modelled by the triangle-filtered kernel
    (clfza.models._exact.binned_kernel) far better than by the mask sampled at the coarse pitch."""
    from clfza.models._exact import binned_model, box_bin

    cam0 = Camera.preset("experiment")
    cam = cam0.with_shape((480, 480), cam0.pitch * 5)
    meas = simulate(data.camera(), cam, object_width=200.0)
    yb, tb = box_bin(meas.clean_y, 3), box_bin(meas.truth, 3)
    K = binned_model(cam, 3)
    err = np.linalg.norm(K.forward(K.geom.embed(tb)) - yb) / np.linalg.norm(yb)
    naive = ExactModel.from_camera(cam.with_shape((160, 160), cam.pitch * 3))
    err_naive = np.linalg.norm(naive.forward(naive.geom.embed(tb)) - yb) / np.linalg.norm(yb)
    assert err < 0.01 and err < err_naive / 4
    with pytest.raises(ClfzaError, match="does not divide"):
        binned_model(cam, 7)


@pytest.mark.parametrize("pitch", [0.02, 0.01])
def test_admm_exact_beats_the_transfer_function_far_from_critical(pitch):
    """No aperture, r1'^2/(N p^2) = 0.68 or 2.73: the sampled H_T aliases or wraps; the exact
    model (with the open mask's constant dropped, which P removes anyway) does not."""
    cam = Camera.preset("simulation").with_shape((256, 256), pitch)
    meas = simulate(data.camera(), cam)
    psnr = {}
    for model in ("tf", "exact"):
        img, _ = clfza.reconstruct(meas.y, cam, "admm", iters=100, model=model,
                                   backend="numpy")
        psnr[model] = clfza.metrics.compare(img, meas.truth)["psnr"]
    assert psnr["exact"] > 30.0 and psnr["exact"] > psnr["tf"] + 5.0


def test_wiener_warns_on_an_aperture_camera():
    from clfza.models._transfer import SamplingWarning

    with pytest.warns(SamplingWarning, match="finite aperture"):
        kind, _ = choose_model(_camera(R=0.3), "auto", method="wiener")
    assert kind == "tf"


def test_admm_average_returns_the_better_of_the_weighted_mean_and_the_last_iterate(
        aperture_shot):
    """``average=True`` keeps ``sum_j j x_j / sum_j j`` and returns it or the last iterate,
    whichever has the lower objective after the projection (recorded in the stats)."""
    cam, meas = aperture_shot
    kw = {"backend": "numpy", "stop": "none", "nonneg": False, "support": False}
    xs = [clfza.reconstruct(meas.clean_y, cam, "admm", iters=k, average=False, **kw).image
          for k in (1, 2, 3, 4)]
    out, info = clfza.reconstruct(meas.clean_y, cam, "admm", iters=4, **kw)
    assert info.params["model"] == "exact"
    st = info.stats
    assert st["returned"] in ("mean", "last")
    assert st["objective_" + st["returned"]] <= min(st["objective_mean"], st["objective_last"])
    mean = sum(j * x for j, x in enumerate(xs, start=1)) / 10.0
    want = mean if st["returned"] == "mean" else xs[-1]
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-12 * np.abs(want).max())
    with pytest.raises(ClfzaError, match="average"):
        clfza.reconstruct(meas.clean_y, cam, "admm", model="tf", average=True,
                          backend="numpy")


def test_spread_stop_rule_ignores_a_swing_and_fires_on_a_plateau():
    """The exact ADMM's objective swings: a rule comparing two values of a swing would stop on
    their coincidence; the spread over the window does not, and still fires on a plateau."""
    from clfza.solvers._common import Stopper

    def run(values, **kw):
        s = Stopper("objective", 1e-3, 1, 100, **kw)
        prev = None
        for it, f in enumerate(values, start=1):
            if s.check(it, f, prev, None):
                return it
            prev = f
        return None

    swing = [10.0, 5.0] * 20
    assert run(swing, window=2) == 3            # f_3 == f_1: taken for converged
    assert run(swing, window=2, spread=True) is None
    assert run(swing + [4.0] * 5, window=2, spread=True) == 43
