"""A captured PSF stack goes through the scale search's scorer and confidence rule
(clfza.focus.select_psf_depth, issue 34): the right depth, confident, on simulated captures;
no preference for small or large PSFs on a frame without structure."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from skimage import data

from clfza.errors import ClfzaError
from clfza.focus import PSFDepthWarning, score_psf_stack, select_psf_depth
from clfza.focus._psf_scale import judge_candidates, null_noise
from clfza.models import load_psf, load_psf_stack, scale_psf
from clfza.simulation import simulate_psf_capture

DEPTHS = (20.0, 25.0, 32.0, 40.0, 55.0, 80.0, 130.0, 250.0)  # mm: point sources captured
N = 488


@pytest.fixture(scope="module")
def captured():
    """A PSF captured at each depth (8-bit, aperture, noise) and a scene frame at 80 mm."""
    caps = [simulate_psf_capture(data.coffee(), shape=(N, N), psf_z1=d, scene_z1=80.0)
            for d in DEPTHS]
    stack = load_psf_stack([c.psf for c in caps], DEPTHS, center="centroid")
    return stack, caps[0].y


def test_stack_search_finds_the_scene_depth_confidently(captured):
    stack, y = captured
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = select_psf_depth(y, stack, full=True)
    assert res.depth == 80.0 and res.index == DEPTHS.index(80.0)
    assert res.confident, res.evidence["reason"]
    k, scores = select_psf_depth(y, stack)  # the pair, as before
    assert k == res.index
    np.testing.assert_allclose(scores, res.scores)
    # the stack's order does not matter (the curve is ordered by depth)
    perm = [3, 0, 7, 5, 1, 6, 2, 4]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r2 = select_psf_depth(y, stack.arrays[perm], [DEPTHS[i] for i in perm], full=True)
    assert r2.depth == 80.0 and r2.confident
    assert r2.evidence["prominence"] == pytest.approx(res.evidence["prominence"])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_noise_frame_is_not_confident(captured, seed):
    stack, _ = captured
    nz = np.random.default_rng(seed).standard_normal((N, N))
    with pytest.warns(PSFDepthWarning):
        res = select_psf_depth(nz, stack, full=True)
    assert not res.confident


def test_no_scale_bias_one_psf_at_many_scales(captured):
    """The issue's case: one PSF loaded at scales 1.0-2.0. On frames without structure the
    raw sharpness falls with the PSF's size; the normalised score does not."""
    stack, _ = captured
    p = load_psf(stack.arrays[-1])
    kernels = [scale_psf(p, s, max_shape=(2 * N - 1, 2 * N - 1)).array
               for s in np.linspace(1.0, 2.0, 9)]
    slopes_raw, slopes, wins = [], [], []
    for seed in range(4):
        nz = np.random.default_rng(10 + seed).standard_normal((N, N))
        raw = score_psf_stack(nz, kernels, nulls=0)
        s = score_psf_stack(nz, kernels)
        x = np.log(np.linspace(1.0, 2.0, 9))
        slopes_raw.append(np.polyfit(x, raw, 1)[0])
        slopes.append(np.polyfit(x, s, 1)[0])
        wins.append(int(np.argmax(s)))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            assert not select_psf_depth(nz, kernels, full=True).confident
    # the raw scores have a consistent trend with scale; the normalised ones a much smaller one
    assert abs(np.mean(slopes)) < 0.25 * abs(np.mean(slopes_raw)), (slopes, slopes_raw)
    assert len(set(wins)) > 1  # not always the same end


def test_judge_candidates_rules():
    xs = np.arange(7.0)
    peak = np.array([0.0, 0.01, 0.0, 1.0, 0.02, 0.0, 0.01])
    ev = judge_candidates(xs, peak, noise=0.01)
    assert ev["confident"] and not ev["at_edge"]
    assert not judge_candidates(xs, peak, noise=0.5)["confident"]  # below the noise
    edge = np.array([1.0, 0.0, 0.01, 0.0, 0.02, 0.0, 0.01])
    assert judge_candidates(xs, edge, noise=0.01)["at_edge"]
    two = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.98, 0.0])
    ev = judge_candidates(xs, two, noise=0.01)
    assert not ev["confident"] and ev["ambiguity"] > 0.9
    assert not judge_candidates(xs[:2], peak[:2], noise=0.01)["confident"]


def test_null_noise_is_the_nulls_spread():
    rng = np.random.default_rng(3)
    raw = np.column_stack([rng.standard_normal(4000) * 0.1 + 5.0,
                           rng.standard_normal((4000, 3)) * 0.1 + np.arange(3)])
    assert null_noise(raw) == pytest.approx(0.1 * np.sqrt(1 + 1 / 3), rel=0.05)
    assert np.isnan(null_noise(raw[:, :2]))


def test_bad_stacks():
    y = np.random.default_rng(0).standard_normal((64, 64))
    with pytest.raises(ClfzaError, match="empty"):
        select_psf_depth(y, [])
    with pytest.raises(ClfzaError, match="distinct"):
        select_psf_depth(y, [np.ones((9, 9))] * 2, [10.0, 10.0])
    with pytest.warns(DeprecationWarning, match="no longer used"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PSFDepthWarning)
            select_psf_depth(y, [np.eye(9) + 0.1, np.eye(9)[::-1] + 0.1], envelope_sigma=8.0)
    with pytest.raises(ClfzaError, match="no detail"):
        select_psf_depth(y, [np.ones((9, 9)), np.eye(9)])
