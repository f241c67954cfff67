"""clfza.models.crop_to_support: a PSF cut to the box that holds its light (issue 34: the
padded grid sized by the PSF's energy support, not its array)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import fftconvolve

from clfza.errors import ClfzaError
from clfza.models import crop_to_support, load_psf


def disc_psf(shape=(61, 75), radius=9.0, centre_offset=(0, 0), tail=0.0, seed=0):
    h, w = shape
    yy, xx = np.indices(shape)
    cy, cx = h // 2 + centre_offset[0], w // 2 + centre_offset[1]
    r = np.hypot(yy - cy, xx - cx)
    a = (r <= radius) * (1.0 + 0.5 * np.cos(r))
    a = a + tail * np.random.default_rng(seed).random(shape)
    return a / a.sum()


def test_cut_to_the_lit_box_centre_kept():
    a = disc_psf()
    q = crop_to_support(a, cut=0.0)
    assert q.shape == (19, 19)  # the disc of radius 9 about (30, 37)
    c = q.info["support_cut"]
    assert c["from"] == [61, 75] and c["to"] == [19, 19] and c["light_cut"] == pytest.approx(0)
    # the centre pixel of the input is the centre pixel of the output
    assert q.array[9, 9] == pytest.approx(a[30, 37])
    assert q.array.sum() == pytest.approx(1.0)


def test_light_cut_bounded_and_model_agrees():
    """A faint tail: the box loses at most ``cut`` of the light, and the linear convolution
    with the cut PSF (cropped to the sensor the same way) differs from the full one by about
    the light cut."""
    a = disc_psf(tail=2e-5)
    for cut in (1e-4, 1e-3, 1e-2):
        q = crop_to_support(a, cut=cut)
        lost = 1.0 - a[_window(a.shape, q.shape)].sum() / a.sum()
        assert lost <= cut + 1e-12
        assert q.info["support_cut"]["light_cut"] == pytest.approx(lost, abs=1e-12)
        obj = np.random.default_rng(1).random((40, 40))
        full = _sensor(obj, a)
        part = _sensor(obj, q.array * (1.0 - lost))  # the kept light, unnormalised
        assert np.abs(full - part).max() <= 1.01 * lost * obj.max()
    assert crop_to_support(a, cut=1e-2).shape[0] < crop_to_support(a, cut=1e-4).shape[0]


def _window(shape, out):
    (h, w), (ho, wo) = shape, out
    y0, x0 = h // 2 - ho // 2, w // 2 - wo // 2
    return slice(y0, y0 + ho), slice(x0, x0 + wo)


def _sensor(obj, psf):
    c0, c1 = psf.shape[0] // 2, psf.shape[1] // 2
    return fftconvolve(obj, psf)[c0:c0 + obj.shape[0], c1:c1 + obj.shape[1]]


def test_rgb_channels_share_one_box_and_keep_their_sums():
    a = np.stack([disc_psf(radius=5.0), disc_psf(radius=9.0), disc_psf(radius=3.0)], -1)
    p = load_psf(a, normalise="sum")
    q = crop_to_support(p, cut=0.0)
    assert q.shape == (19, 19, 3)
    np.testing.assert_allclose(q.array.sum(axis=(0, 1)), 1.0)
    assert not q.array.flags.writeable


def test_off_centre_light_widens_the_box_both_ways():
    a = disc_psf(radius=4.0, centre_offset=(10, 0))  # light below the centre only
    q = crop_to_support(a, cut=0.0)
    assert q.shape[0] == 2 * 14 + 1  # symmetric about the centre: reaches row 30 + 14


def test_bad_cut_and_dark_psf():
    with pytest.raises(ClfzaError, match="cut must be"):
        crop_to_support(disc_psf(), cut=0.5)
    with pytest.raises(ClfzaError):
        crop_to_support(np.zeros((9, 9)))


def test_reconstruct_cuts_a_dark_tail_and_records_it():
    """An iterative solve with a measured PSF whose tail is dark runs on the PSF cut to its
    light (the same problem: the cut tail carried no light), and says so in its record."""
    import warnings

    import clfza
    from clfza.models import crop_to_support

    cam = clfza.Camera.measured_psf(0.01, (32, 32))
    rng = np.random.default_rng(3)
    psf = np.zeros((61, 61))
    psf[20:41, 20:41] = rng.random((21, 21))  # lit 21^2 box, dark 20-pixel margins
    y = rng.normal(size=(32, 32))
    kw = dict(tau=1e-3, iters=5, stop="none", backend="numpy")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = clfza.reconstruct(y, cam, "admm", psf=psf, **kw)
        cut = crop_to_support(clfza.models.PSF(array=psf, pitch=cam.pitch))
        ref = clfza.reconstruct(y, cam, "admm", psf=np.asarray(cut.array), **kw)
    assert got.info.stats["psf_support_cut"]["to"] == [21, 21]
    assert got.info.stats["psf_support_cut"]["from"] == [61, 61]
    assert any("cut to its light" in n for n in got.info.notes)
    np.testing.assert_allclose(got.image, ref.image, rtol=1e-12, atol=1e-12)
    assert "psf_support_cut" not in ref.info.stats  # nothing left to cut
