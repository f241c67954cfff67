"""The crop-split ADMM's defaults with a measured PSF (issue 34): its TV penalty
``rho = PSF_RHO_PER_WEIGHT w`` and ``PSF_ITERS`` iterations, while a mask's shadow keeps
``RHO_PER_WEIGHT w`` and 400, ``tau="auto"``'s pilot passes run at ``RHO_PER_WEIGHT w`` (the
penalty its rule was fitted on) and options given are kept."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import clfza
import clfza.solvers._admm_crop as crop
from clfza.solvers import default_iters
from clfza.solvers._admm import RHO_PER_WEIGHT


@pytest.fixture(scope="module")
def capture():
    from skimage import data

    from clfza.models import load_psf
    from clfza.simulation import Noise, simulate_psf_capture

    noise = Noise(photons=5000.0, read_noise=2.0, bit_depth=8, exposure=0.9, seed=3)
    cap = simulate_psf_capture(data.camera(), shape=(48, 48), scene_z1=400.0, psf_z1=400.0,
                               noise=noise)
    return cap.y, cap.camera, load_psf(cap.psf, background="border", center="centroid")


def _solve(y, cam, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return clfza.reconstruct(y, cam, "admm", backend="numpy", **kw)


def test_measured_psf_defaults(capture):
    y, cam, psf = capture
    r = _solve(y, cam, psf=psf, tau=1e-3, stop="none")
    st = r.info.stats
    assert crop.PSF_RHO_PER_WEIGHT != RHO_PER_WEIGHT and crop.PSF_ITERS != 400
    assert r.info.params["iters"] == crop.PSF_ITERS == r.info.iterations
    assert st["rho"] == pytest.approx(crop.PSF_RHO_PER_WEIGHT * st["weight"], rel=1e-12)
    assert default_iters("admm", "exact", psf=True) == crop.PSF_ITERS


def test_options_given_are_kept(capture):
    y, cam, psf = capture
    r = _solve(y, cam, psf=psf, tau=1e-3, iters=30, rho=0.5, stop="none")
    assert r.info.params["iters"] == 30 == r.info.iterations
    assert r.info.stats["rho"] == 0.5
    # asked for explicitly, the former default is what runs
    r = _solve(y, cam, psf=psf, tau=1e-3, iters=400, stop="none")
    assert r.info.iterations == 400


def test_mask_shadow_keeps_its_defaults():
    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.07, z1=20.0, z2=3.0, R=0.3)
    m = clfza.simulate(np.random.default_rng(1).random((16, 16)), cam)
    r = _solve(m.y, cam, model="exact", tau=1e-3, iters=None, stop="none")
    st = r.info.stats
    assert r.info.params["iters"] == 400 == r.info.iterations == default_iters("admm", "exact")
    assert st["rho"] == pytest.approx(RHO_PER_WEIGHT * st["weight"], rel=1e-12)


def test_tau_auto_pilots_at_the_fitted_penalty_then_solves_at_the_psf_one(capture,
                                                                          monkeypatch):
    y, cam, psf = capture
    seen = []
    setup = crop.AdmmCropSolver.setup

    def spy(self, x0):
        setup(self, x0)
        seen.append((self.rho / self.opts.weight, self.opts.iters))

    monkeypatch.setattr(crop.AdmmCropSolver, "setup", spy)
    r = _solve(y, cam, psf=psf)
    passes = r.info.stats["tau_auto"]["stages"]
    assert len(seen) == len(passes) + 1 and passes
    for rho_w, _ in seen[:-1]:
        assert rho_w == pytest.approx(RHO_PER_WEIGHT)
    assert seen[-1] == (pytest.approx(crop.PSF_RHO_PER_WEIGHT), crop.PSF_ITERS)
    assert r.info.params["rho"] is None  # the options are left as given
