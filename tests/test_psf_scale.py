"""Measured PSFs at another depth (issue 34): the simulated captures, the PSF's
magnification, the scale search and its confidence, measured-PSF cameras."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from skimage import data

from clfza import Camera
from clfza.errors import ClfzaError
from clfza.focus import find_psf_scale
from clfza.models import load_psf, magnify, scale_psf
from clfza.simulation import shadow_pattern, simulate_psf_capture


@pytest.fixture(scope="module")
def capture():
    return simulate_psf_capture(data.coffee(), shape=(160, 160), scene_z1=40.0)


def test_magnify_keeps_sum_and_centre():
    a = np.zeros((9, 11))
    a[4, 5] = 1.0
    for s in (0.6, 1.0, 1.37, 2.0):
        b = magnify(a, s)
        assert b.shape == (round(9 * s), round(11 * s))
        assert b.sum() == pytest.approx(1.0, abs=1e-12)
        assert b.min() >= 0
        cy, cx = (np.indices(b.shape) * b).reshape(2, -1).sum(axis=1)
        assert (cy, cx) == pytest.approx((b.shape[0] // 2, b.shape[1] // 2), abs=1e-9)


def test_capture_psf_magnified_is_the_scene_shadow(capture):
    """The captured PSF magnified by the true scale is the exact shadow at the scene's depth
    (noise aside): the simulation's geometry and magnify agree."""
    cam = capture.mask_camera.at_depth(40.0)
    true = shadow_pattern(cam, (201, 201))
    psf = load_psf(capture.psf, center="none").array.mean(axis=2)
    got = magnify(psf, capture.true_scale, (201, 201))
    assert np.corrcoef(got[50:150, 50:150].ravel(), true[50:150, 50:150].ravel())[0, 1] > 0.95
    wrong = magnify(psf, 1.0, (201, 201))
    assert np.corrcoef(wrong[50:150, 50:150].ravel(), true[50:150, 50:150].ravel())[0, 1] < 0.5
    assert capture.frame.max() <= 255 and np.all(capture.frame == np.round(capture.frame))


def test_scale_psf_records_and_cuts():
    p = load_psf(np.outer(np.hanning(41), np.hanning(41)))
    q = scale_psf(p, 2.0, max_shape=(41, 41))
    assert q.shape == (41, 41) and q.info["scale"] == 2.0
    assert q.array.sum() == pytest.approx(1.0)
    assert 0 < q.info["scale_cut_fraction"] < 0.6


def test_scale_search_finds_the_scale(capture):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = find_psf_scale(capture.y, load_psf(capture.psf, center="centroid"),
                             camera=capture.camera)
    assert res.scale == pytest.approx(capture.true_scale, rel=0.02)
    assert res.depth == pytest.approx(40.0, rel=0.15)
    assert len(res.coarse_scores) == len(res.coarse_scales) and res.levels


def test_scale_search_on_noise_is_not_confident(capture):
    """A frame of noise (no scene) never gets a confident scale."""
    rng = np.random.default_rng(3)
    y = rng.standard_normal((160, 160))
    with pytest.warns(UserWarning, match="not reliable"):
        res = find_psf_scale(y, load_psf(capture.psf, center="centroid"))
    assert not res.confident


def test_scale_search_bad_range(capture):
    with pytest.raises(ClfzaError, match="scale_range"):
        find_psf_scale(capture.y, capture.psf, (2.0, 1.0))


def test_measured_psf_camera_needs_pitch_and_shape_only():
    cam = Camera.from_dict({"camera": {"pitch": 0.0066, "shape": [64, 48]}})
    assert cam.kind == "psf" and not cam.knows_depth
    s = cam.summary()
    assert not {"r1_mm", "z1_mm", "band_limit_cyc_per_mm", "R_mm"} & set(s)
    cam = Camera.from_dict({"pitch": 0.0066, "shape": [64, 64], "z2": 8.0, "psf_z1": 400.0})
    assert cam.depth_of_scale(1.0) == pytest.approx(400.0)
    assert cam.depth_of_scale(cam.scale_of_depth(40.0)) == pytest.approx(40.0)
    assert Camera.from_dict(cam.to_dict()) == cam
    with pytest.raises(ClfzaError, match="together"):
        Camera.from_dict({"pitch": 0.0066, "shape": [64, 64], "z2": 8.0})
    with pytest.raises(ClfzaError, match="r1"):  # an FZA file without r1 is still an error
        Camera.from_dict({"pitch": 0.0066, "shape": [64, 64], "z1": 20.0, "z2": 3.0})


def test_reconstruct_records_the_scale(capture):
    from clfza.reconstruction import reconstruct

    img, info = reconstruct(capture.y[..., 1], capture.camera, "admm", iters=5,
                            psf=load_psf(capture.psf[..., 1], center="centroid"),
                            psf_scale=1.25, backend="numpy")
    assert info.params["psf_scale"] == 1.25 and img.shape == (160, 160)
    with pytest.raises(ClfzaError, match="psf_scale"):
        reconstruct(capture.y[..., 1], capture.camera, "admm", iters=2, psf_scale="big",
                    psf=capture.psf[..., 1], backend="numpy")


def test_default_range_from_camera_depths(capture):
    """A camera that knows its depths searches only physical scales: from just below a scene
    at infinity's scale (no scene lies beyond it)."""
    from clfza.focus._psf_scale import DEPTH_MARGIN, default_scale_range

    lo, hi = default_scale_range(capture.camera)
    assert lo == pytest.approx(capture.camera.scale_of_depth(float("inf")) * (1 - DEPTH_MARGIN))
    assert hi == 2.0 and default_scale_range(None) == (0.5, 2.0)


def test_search_carries_candidates_and_judges_the_winner(capture):
    """The coarse level's distinct peaks are refined and the best at the finest level wins;
    the evidence names them, and the ambiguity is the runner-up's height relative to it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = find_psf_scale(capture.y, load_psf(capture.psf, center="centroid"), (0.5, 2.0))
    ev = res.evidence
    assert 1 <= len(ev["candidates"]) <= 3
    assert ev["candidates"][0]["scale"] == res.scale
    peaks = [c["peak"] for c in ev["candidates"]]
    assert peaks == sorted(peaks, reverse=True)
    assert 0 <= ev["ambiguity"] <= 1 or len(peaks) == 1
    assert res.scale == pytest.approx(capture.true_scale, rel=0.02)


def test_peaks_are_distinct_local_maxima():
    from clfza.focus._psf_scale import _peaks

    s = np.array([0.0, 1.0, 0.5, 0.2, 0.9, 0.3, 0.1, 0.0, 0.8])
    assert _peaks(s, 2, 3) == [1, 4, 8]
    assert _peaks(s, 4, 3) == [1, 8]  # 4 is within 4 points of 1


def test_claim_refuses_disagreeing_levels_and_ambiguity():
    from clfza.focus._psf_scale import MAX_AMBIGUITY, claim

    ok = {"confident": True, "reason": "clear peak", "levels_agree": True, "ambiguity": 0.2}
    assert claim(ok) == (True, "clear peak")
    assert not claim({**ok, "levels_agree": False})[0]
    bad, why = claim({**ok, "ambiguity": MAX_AMBIGUITY + 0.05}, 0.61)
    assert not bad and "0.61" in why
    assert not claim({**ok, "confident": False, "reason": "at the lower end"})[0]
