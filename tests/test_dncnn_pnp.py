"""Plug-and-play ADMM with the DnCNN prior (issue 38: ``reg="dncnn"``, clfza.solvers._pnp).

The x-update is checked against the normal equations with the numpy operator, the z-update
against the reference network, the OpenCL solve against the numpy (float64) one, and the
record (variant, sigma, the note when sigma leaves the training range) and the option errors.
float32 against float64 after a few iterations: 1e-4 of the data scale, like the other
solvers' agreement tests (tests/test_api_solvers.py).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import clfza
from clfza.denoisers import dncnn_reference, load_dncnn
from clfza.errors import ClfzaError


@pytest.fixture(scope="module")
def scene():
    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.07, z1=20.0, z2=3.0, R=0.6)
    yy, xx = np.mgrid[:32, :32] / 32.0
    truth = np.clip(0.2 + 0.6 * ((xx - 0.5) ** 2 + (yy - 0.5) ** 2 < 0.08), 0, 1)
    y = clfza.NumpyOperator(cam, warn=False).forward(truth)
    y = y + 0.01 * np.random.default_rng(0).standard_normal(y.shape)
    return cam, y, truth


def _pnp(scene, backend, **kw):
    cam, y, _ = scene
    opts = dict(model="tf", reg="dncnn", tau=2e-4, rho=0.1, iters=3, stop="none")
    opts.update(kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return clfza.reconstruct(y, cam, "admm", backend=backend, **opts)


def _tv(scene, x0, tau=2e-4):
    """The TV pre-solve reg='dncnn' runs first: ADMM-TV at tau from x0."""
    from clfza.solvers._pnp import PNP_TV_ITERS

    cam, y, _ = scene
    return clfza.reconstruct(y, cam, "admm", backend="numpy", model="tf", tau=tau,
                             iters=PNP_TV_ITERS, x0=x0).image


def test_first_iteration_solves_the_normal_equations_and_denoises(scene):
    """From the TV pre-solve's image v of x0: x1 = (K^T K + rho)^-1 (K^T y + rho v); the
    record's sigma is sqrt(tau' / rho) / c, tau' = PNP_TAU_PER_TV tau, for the image's range
    [lo, lo + c] of v's percentiles."""
    from clfza.solvers._pnp import PNP_TAU_PER_TV

    cam, y, _ = scene
    x0 = np.random.default_rng(1).random((32, 32))
    r = _pnp(scene, "numpy", iters=1, x0=x0)
    v = _tv(scene, x0)
    assert r.info.stats["tv_presolve_iters"] >= 1
    op = clfza.NumpyOperator(cam, warn=False)
    rho = r.info.stats["rho"]
    resid = op.normal(r.image) + rho * r.image - (op.adjoint(y) + rho * v)
    assert np.abs(resid).max() < 1e-10 * max(1.0, np.abs(op.adjoint(y)).max())
    lo, hi = np.percentile(v, (0.1, 99.9))
    tau_p = PNP_TAU_PER_TV * 2e-4
    assert r.info.stats["pnp_tau"] == pytest.approx(tau_p)
    assert r.info.stats["image_offset"] == pytest.approx(lo)
    assert r.info.stats["image_scale"] == pytest.approx(hi - lo)
    assert r.info.stats["sigma"] == pytest.approx(math.sqrt(tau_p / rho) / (hi - lo))
    assert r.info.stats["denoiser"] == "6N" and r.info.stats["denoiser_calls"] == 1


def test_z_update_is_the_reference_denoiser_on_the_clipped_scaled_image(scene):
    """Two iterations from x0 with the first z computed by hand: half-quadratic splitting's
    second x-update solves (K^T K + rho2) x2 = K^T y + rho2 z1 with
    z1 = lo + c D(clip((x1 - lo) / c), sigma1) and rho2 = tau / (c sigma2)^2."""
    from clfza.solvers._pnp import PNP_SIGMA_MIN

    cam, y, _ = scene
    x0 = np.random.default_rng(2).random((32, 32))
    # rho 0.01: the first sigma (about 0.03) above PNP_SIGMA_MIN, so the schedule decreases
    r1 = _pnp(scene, "numpy", iters=1, x0=x0, rho=0.01)
    r2 = _pnp(scene, "numpy", iters=2, x0=x0, rho=0.01)
    assert r1.info.stats["sigma"] > PNP_SIGMA_MIN
    st = r1.info.stats
    lo, c, s = st["image_offset"], st["image_scale"], st["sigma"]
    x1 = r1.image
    t = np.clip((x1 - lo) / c, 0, 1)
    z1 = lo + c * dncnn_reference(t, load_dncnn("6N"), sigma=s)
    op = clfza.NumpyOperator(cam, warn=False)
    rho2, s2 = r2.info.stats["rho"], r2.info.stats["sigma"]
    assert s2 < s and rho2 == pytest.approx(st["pnp_tau"] / (c * s2) ** 2)
    rhs = op.adjoint(y) + rho2 * z1
    resid = op.normal(r2.image) + rho2 * r2.image - rhs
    assert np.abs(resid).max() < 1e-9 * max(1.0, np.abs(rhs).max())


@pytest.mark.agreement
def test_opencl_pnp_matches_the_numpy_reference(rt, scene):
    ref = _pnp(scene, "numpy")
    got = _pnp(scene, "opencl", device=rt.info.index)
    scale = np.abs(ref.image).max()
    assert np.abs(got.image - ref.image).max() < 1e-4 * scale
    assert got.info.stats["denoiser"] == ref.info.stats["denoiser"]
    assert got.info.stats["sigma"] == pytest.approx(ref.info.stats["sigma"], rel=1e-5)


@pytest.mark.agreement
def test_colour_joint_and_independent_pnp(rt, scene):
    cam, y, _ = scene
    rgb = np.stack([y, 0.5 * y, y], -1)
    outs = {}
    for colour in ("independent", "joint"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = clfza.reconstruct(rgb, cam, "admm", model="tf", reg="dncnn", tau=2e-4, rho=0.1,
                                  iters=2, stop="none", colour=colour, x0=np.zeros(rgb.shape),
                                  device=rt.info.index)
        assert r.image.shape == rgb.shape and np.all(np.isfinite(r.image))
        # the record names the variant: per channel (independent), once for the joint call
        per = r.info.stats["channels"] if colour == "independent" else [r.info.stats]
        assert len(per) == (3 if colour == "independent" else 1)
        assert all(c["denoiser"] == "6N" and c["denoiser_calls"] == 2 for c in per)
        outs[colour] = r.image
    # channels 0 and 2 hold the same data: denoised channel by channel, they agree
    np.testing.assert_allclose(outs["joint"][..., 0], outs["joint"][..., 2], atol=1e-5)


def test_sigma_outside_the_training_range_is_recorded(scene):
    r = _pnp(scene, "numpy", tau=5.0, iters=1)
    assert any("above the training range" in n for n in r.info.notes), r.info.notes
    assert any(n.startswith("prior: DnCNN 6N") for n in r.info.notes)


def test_a_named_variant_outside_its_band_is_recorded_with_the_one_covering_it(scene):
    """6L (blind, trained at 0.06) from sigma PNP_SIGMA_MAX: the record says which sigmas
    leave its band and names the variants that cover them."""
    r = _pnp(scene, "numpy", rho=None, denoiser="6L", iters=10)
    notes = [n for n in r.info.notes if "outside the band" in n]
    assert len(notes) == 1 and "of 6L" in notes[0], r.info.notes
    assert "6N (sigma input) or 6M (blind) covers it" in notes[0]
    assert r.info.stats["denoiser"] == "6L"


def test_blind_denoiser_follows_the_band_of_each_sigma(scene, monkeypatch):
    """denoiser='blind': each iteration's network is the blind variant whose band holds that
    iteration's sigma (select_variant), switching along the decreasing schedule (6M, then
    6L); the record lists the variant of every iteration, and no range note is needed."""
    from clfza.denoisers import select_variant
    from clfza.solvers import _pnp as pnp

    calls = []
    ref = pnp.dncnn_reference

    def spy(t, weights, sigma):
        calls.append((weights.variant, sigma))
        return ref(t, weights, sigma=sigma)

    monkeypatch.setattr(pnp, "dncnn_reference", spy)
    r = _pnp(scene, "numpy", rho=None, denoiser="blind", iters=pnp.PNP_ITERS)
    assert len(calls) == pnp.PNP_ITERS
    assert [v for v, _ in calls] == [select_variant(s, "blind").variant for _, s in calls]
    assert calls[0][0] == "6M" and calls[-1][0] == "6L"
    assert r.info.stats["denoiser_variants"] == [v for v, _ in calls]
    assert r.info.stats["denoiser"] == "6M+6L"
    assert not any("outside the band" in n for n in r.info.notes), r.info.notes
    assert any(n.startswith("prior: DnCNN 6M then 6L") for n in r.info.notes)


def test_the_solve_stays_bounded_and_reports_its_data_term(scene):
    """The denoiser's input is clipped to its training range: without it the split diverges
    (DnCNN amplifies values above 1); the objective reported is 1/2 ||y - K x||^2."""
    cam, y, truth = scene
    r = _pnp(scene, "numpy", iters=15)
    assert np.all(np.isfinite(r.image)) and np.abs(r.image).max() < 10 * np.abs(truth).max()
    op = clfza.NumpyOperator(cam, warn=False)
    assert r.info.objective[-1] == pytest.approx(
        0.5 * np.sum((y - op.forward(r.image)) ** 2), rel=1e-6)


def test_the_sigma_schedule_is_geometric_and_ends_the_solve(scene):
    """Without rho: sigma from PNP_SIGMA_MAX down to PNP_SIGMA_MIN over min(iters, PNP_ITERS)
    iterations (one denoiser call each), after which the solve ends."""
    from clfza.solvers._pnp import PNP_ITERS, PNP_SIGMA_MAX, PNP_SIGMA_MIN

    r = _pnp(scene, "numpy", rho=None, iters=PNP_ITERS + 5)
    st = r.info.stats
    assert r.info.iterations == PNP_ITERS and st["denoiser_calls"] == PNP_ITERS
    assert st["sigma_first"] == pytest.approx(PNP_SIGMA_MAX)
    assert st["sigma"] == pytest.approx(PNP_SIGMA_MIN)
    assert st["rho"] == pytest.approx(st["pnp_tau"] / (st["image_scale"] * PNP_SIGMA_MIN) ** 2)
    r3 = _pnp(scene, "numpy", rho=None, iters=3)
    assert r3.info.iterations == 3 and r3.info.stats["sigma"] == pytest.approx(PNP_SIGMA_MIN)


@pytest.fixture(scope="module")
def natural():
    """scikit-image's camera at 32^2 (a natural scene: the disc above is piecewise constant,
    where TV wins) with Gaussian noise of std 0.05 on y."""
    from skimage import data, transform

    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.07, z1=20.0, z2=3.0, R=0.6)
    truth = transform.resize(data.camera().astype(float) / 255, (32, 32), anti_aliasing=True)
    y = clfza.NumpyOperator(cam, warn=False).forward(truth)
    y = y + 0.05 * np.random.default_rng(0).standard_normal(y.shape)
    return cam, y, truth


def test_pnp_improves_on_its_tv_start(natural):
    """On a natural scene at its best TV tau of a small grid, the defaults (TV pre-solve,
    then the denoiser's schedule) come closer to the truth than the TV pre-solve alone."""
    from clfza.metrics import compare

    cam, y, truth = natural
    taus = (3e-3, 1e-2, 3e-2, 0.1)
    tvs = [compare(_tv(natural, None, t), truth)["psnr"] for t in taus]
    tau = taus[int(np.argmax(tvs))]
    r = _pnp(natural, "numpy", rho=None, tau=tau, iters=20)
    assert np.all(np.isfinite(r.image))
    assert compare(r.image, truth)["psnr"] > max(tvs), (compare(r.image, truth)["psnr"], tvs)


@pytest.mark.parametrize("kw, match", [
    (dict(reg="tv", denoiser="6N"), "denoiser is an option of reg='dncnn'"),
    (dict(denoiser="9Q"), "denoiser must be one of"),
    (dict(reg="l1"), "use fista or twist for l1"),
    (dict(denoiser="17N", rho=-1.0), "rho"),
    (dict(tau="auto"), "numeric tau"),
    (dict(tau=None), "numeric tau"),
])
def test_bad_pnp_options_are_clear_errors(scene, kw, match):
    cam, y, _ = scene
    opts = dict(model="tf", reg="dncnn", tau=2e-4, iters=1)
    opts.update(kw)
    with pytest.raises(ClfzaError, match=match):
        clfza.reconstruct(y, cam, "admm", backend="numpy", **opts)


@pytest.mark.parametrize("method", ["fista", "twist", "wiener", "fista-options"])
def test_methods_other_than_admm_refuse_dncnn_with_the_reason(scene, method):
    """reg='dncnn' is ADMM's (plug-and-play): FISTA (the denoiser as its prox did not
    converge, measured), TwIST and Wiener refuse it in one line that says so, points at the
    measurement and names what to run instead (not the generic list of regularisers)."""
    cam, y, _ = scene
    kw = dict(reg="dncnn", tau=0.01)
    m = method
    if method == "fista-options":
        m, kw = clfza.FISTA(**kw), {}
    with pytest.raises(ClfzaError) as e:
        clfza.reconstruct(y, cam, m, backend="numpy", model="tf", **kw)
    msg = str(e.value)
    assert "\n" not in msg and "must be one of" not in msg
    for part in ("prior for method 'admm'", "FISTA's prox", "docs/measurements.md",
                 "--method admm --opt reg=dncnn"):
        assert part in msg, msg


def test_float64_on_opencl_is_a_clear_error(rt, scene):
    if not rt.has_fp64:
        pytest.skip("no float64 on this device")
    with pytest.raises(ClfzaError, match="float32"):
        _pnp(scene, "opencl", dtype=np.float64, device=rt.info.index)



@pytest.fixture(scope="module")
def capture():
    """A measured-PSF capture at 32^2 (clfza.simulation.simulate_psf_capture): the exact
    model's reg='dncnn' (clfza.solvers._pnp.PnpExactSolver)."""
    from skimage import data

    from clfza.models import load_psf
    from clfza.simulation import Noise, simulate_psf_capture

    noise = Noise(photons=2000.0, read_noise=2.0, bit_depth=8, exposure=0.9, seed=1)
    cap = simulate_psf_capture(data.camera(), shape=(32, 32), scene_z1=400.0, psf_z1=400.0,
                               noise=noise)
    return cap, load_psf(cap.psf, background="border", center="centroid")


def _exact(capture, backend, **kw):
    cap, psf = capture
    opts = dict(psf=psf, reg="dncnn", tau=1e-3, rho=0.05, iters=3, stop="none")
    opts.update(kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return clfza.reconstruct(cap.y, cap.camera, "admm", backend=backend, **opts)


def test_exact_x_update_solves_the_normal_equations(capture):
    """The exact model's x-update: conjugate gradients on (K^T K + rho) x = K^T y + rho z,
    checked on the float64 operator's own normal equations (K^T K p = K^T y - K^T (y - K p))
    to the stopping tolerance, from a cold start."""
    from clfza.backends import get_backend
    from clfza.solvers._admm_crop import CropAdmmOptions
    from clfza.solvers._common import Monitor
    from clfza.solvers._pnp import PNP_CG_TOL, PnpExactSolver

    cap, psf = capture
    B = get_backend("numpy", cap.camera, model="exact", psf=psf)
    B.set_measurement(cap.y[None] / B.data_scale)
    opts = CropAdmmOptions.from_options({"reg": "dncnn", "tau": 1e-3}, method="admm",
                                        exact=True)
    s = PnpExactSolver(B, opts, Monitor(B))
    s._x_setup()
    rng = np.random.default_rng(2)
    s.rho = 0.05
    s.x, s.z = B.zeros(), B.from_host(rng.random(B.shape))
    s._x_update()
    assert s.cg_iters > 1

    def normal(x):  # (K^T K + rho) x
        g = B.empty()
        B.resid_grad(x, g)
        return B.b - g + s.rho * x

    rhs = B.b + s.rho * s.z
    res = np.linalg.norm(normal(s.x) - rhs) / np.linalg.norm(rhs - normal(B.zeros()))
    assert res <= PNP_CG_TOL * 1.01, res


def test_exact_pnp_runs_projects_and_records(capture):
    """On a measured PSF: the crop-split ADMM-TV pre-solve (its default iterations), the
    denoiser's iterations, an image on the sensor's grid that is non-negative (the exact
    model's default projection), and the record."""
    from clfza.solvers._admm import AdmmExactOptions

    r = _exact(capture, "numpy")
    st = r.info.stats
    assert r.image.shape == (32, 32) and np.all(np.isfinite(r.image))
    assert r.image.min() >= 0.0
    assert st["x_update"] == "cg" and st["cg_iters"] > 0 and st["denoiser_calls"] == 3
    assert st["tv_presolve_iters"] <= AdmmExactOptions().iters
    assert r.info.params["model"] == "exact"


@pytest.mark.agreement
def test_exact_opencl_pnp_matches_the_numpy_reference(rt, capture):
    ref = _exact(capture, "numpy")
    got = _exact(capture, "opencl", device=rt.info.index)
    scale = np.abs(ref.image).max()
    # float32 CG: its early stop may fall an iteration apart, within the CG's tolerance
    assert np.abs(got.image - ref.image).max() < 1e-3 * scale


def test_exact_pnp_refuses_a_mask_shadow():
    """reg='dncnn' on the exact model of a mask's shadow (not a measured PSF) is refused in one
    clear error before the TV pre-solve: its data weight is measured on PSFs only."""
    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.07, z1=20.0, z2=3.0, R=0.3)
    m = clfza.simulate(np.random.default_rng(0).random((16, 16)), cam)
    with pytest.raises(ClfzaError, match="measured PSF only") as e:
        clfza.reconstruct(m.y, cam, "admm", backend="numpy", model="exact", reg="dncnn",
                          tau=0.01)
    msg = str(e.value)
    assert "\n" not in msg
    for part in ("model='tf'", "--model tf", "bench/results/dncnn_quality_experiment",
                 "docs/measurements.md"):
        assert part in msg, msg


def test_auto_model_routes_dncnn_to_eq17_where_only_the_sampling_chose_the_exact_model():
    """model='auto' with reg='dncnn': a mask's shadow that the exact model was chosen for by
    its sampling alone (no aperture, centred mask) runs on Eq. 17, saying why; a finite
    aperture keeps the exact model (and its refusal), a measured PSF keeps the exact model,
    and reg='tv' keeps the sampling's choice."""
    from clfza.solvers import method_model

    sim = clfza.Camera.preset("simulation").with_shape((64, 64))
    kind, why = method_model(sim, "auto", "admm", {"reg": "dncnn"})
    assert kind == "tf" and "reg='dncnn'" in why and "sampling" in why, why
    assert method_model(sim, "auto", "admm", {"reg": "tv"})[0] == "exact"
    assert method_model(sim, "exact", "admm", {"reg": "dncnn"})[0] == "exact"  # asked for
    aperture = clfza.Camera.preset("experiment")
    assert method_model(aperture, "auto", "admm", {"reg": "dncnn"})[0] == "exact"
    assert method_model(sim, "auto", "admm", {"reg": "dncnn"}, psf=True)[0] == "exact"


def test_exact_pnp_on_a_colour_psf_capture(rt):
    """An RGB frame with its RGB measured PSF (exact model, PnpExactSolver): each channel with
    its own PSF channel, the denoiser's iterations run and are recorded, the image is
    finite, non-negative and in colour."""
    from skimage import data

    from clfza.models import load_psf
    from clfza.simulation import Noise, simulate_psf_capture

    noise = Noise(photons=2000.0, read_noise=2.0, bit_depth=8, exposure=0.9, seed=1)
    cap = simulate_psf_capture(data.astronaut(), shape=(32, 32), scene_z1=400.0,
                               psf_z1=400.0, noise=noise)
    psf = load_psf(cap.psf, background="border", center="centroid")
    assert cap.y.shape == (32, 32, 3) and psf.shape[-1] == 3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, reg="dncnn", tau=1e-3,
                              iters=3, device=rt.info.index)
    chans = r.info.stats["channels"]  # every channel's record, not only the first's
    assert r.image.shape == (32, 32, 3) and np.all(np.isfinite(r.image))
    assert r.image.min() >= 0.0 and r.info.params["model"] == "exact"
    assert len(chans) == 3 and len(r.info.objective) == 3
    for st in chans:
        assert st["x_update"] == "cg" and st["denoiser"] == "6N" and st["denoiser_calls"] == 3
    assert any(n.startswith("prior: DnCNN 6N") for n in r.info.notes)
    # the channels are not copies of one another (each has its own PSF and data)
    assert not np.allclose(r.image[..., 0], r.image[..., 2])
