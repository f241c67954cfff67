"""A stack of frames with a prior the batched kernels do not have (reg="dncnn") runs frame by
frame, with each frame's own prior (it ran ADMM-TV on the whole stack before, recorded as
dncnn)."""

from __future__ import annotations

import warnings

import numpy as np

import clfza


def test_stack_with_dncnn_prior_is_the_frames_one_at_a_time():
    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.055, z1=20.0, z2=3.0, R=None)
    rng = np.random.default_rng(0)
    ys = np.stack([clfza.simulate(rng.random((16, 16)), cam,
                                  noise=clfza.Noise(gaussian_var=1e-4, seed=k)).y
                   for k in range(2)])
    kw = dict(reg="dncnn", tau=0.01, iters=3, stop="none", model="tf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stack = clfza.reconstruct(ys, cam, "admm", **kw)
        alone = [clfza.reconstruct(y, cam, "admm", **kw) for y in ys]
        tv = clfza.reconstruct(ys[0], cam, "admm", **{**kw, "reg": "tv"})
    images = np.asarray(stack.image)
    for k in range(2):
        np.testing.assert_allclose(images[k], alone[k].image, rtol=0, atol=1e-6)
    assert not np.allclose(images[0], tv.image, atol=1e-4)  # the prior did something


def test_measured_psf_camera_without_its_psf_is_refused():
    """A measured-PSF camera has no zone plate: without psf= it was solved silently with a
    placeholder mask."""
    import pytest

    cam = clfza.Camera.measured_psf(0.01, (32, 32))
    with pytest.raises(clfza.ClfzaError, match="measured-PSF camera"):
        clfza.reconstruct(np.zeros((32, 32)), cam, "admm")
