"""The exact model's accelerated proximal gradient with restart (clfza.solvers._apg_exact):
its point kernel against the float64 reference, the support trick inside the FGP prox, the
solver's agreement across backends, its objective against the crop-split ADMM's, and its
errors."""

from __future__ import annotations

import numpy as np
import pytest
from skimage import data

import clfza
from clfza import Camera
from clfza.backends import ProxState, get_backend
from clfza.errors import ClfzaError
from clfza.simulation import simulate
from clfza.solvers._apg_exact import ApgExactOps, off_value

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


@pytest.fixture(scope="module")
def shot():
    """The simulation preset at 64^2 (no aperture; the exact model's grid 128^2) and a small
    aperture camera (the experiment preset binned to 96^2, so the object region has a
    margin)."""
    cam = Camera.preset("simulation").with_shape((64, 64), 0.08)
    meas = simulate(data.camera() / 255.0, cam, object_width=20.0)
    cam0 = Camera.preset("experiment")
    acam = cam0.with_shape((96, 96), cam0.pitch * 25)
    ameas = simulate(data.camera() / 255.0, acam, object_width=200.0)
    return (cam, meas), (acam, ameas)


def _backends(cam, y):
    out = []
    for kind in ("numpy", "opencl"):
        B = get_backend(kind, cam, model="exact")
        B.set_measurement(y[None])
        out.append(B)
    return out


def test_apg_point_matches_the_reference(shot, rng):
    """b = x + K^T (y - K x) inside the object region, the off value outside (and no
    off value without the support), float32 against float64."""
    for cam, meas in shot:
        nb, cb = _backends(cam, meas.clean_y)
        x = rng.random(nb.shape)[None] * nb.region
        for support in (True, False):
            refs = []
            for B in (nb, cb):
                ops = ApgExactOps.for_backend(B)
                xd, hx, b = B.from_host(x), B.empty(), B.empty()
                ops.forward(xd, hx)
                ops.grad_point(b, xd, hx, -3.5, support)
                refs.append(B.to_host(b).astype(np.float64))
            ref, got = refs
            if support:
                assert np.all(ref[0][nb.region == 0] == -3.5)
            else:
                assert not np.any(ref == -3.5)
            # float32: the adjoint's two FFT pairs of O(1) values, relative to the point's scale
            assert np.abs(got - ref).max() <= 1e-4 * np.abs(ref).max()


def test_the_off_value_makes_the_fgp_prox_the_prox_with_the_support(shot, rng):
    """The FGP prox with non-negativity of a point set to ``off_value(w)`` off the region is
    zero there, and it is the prox of ``w TV + i_C`` restricted to the region: it equals the
    prox computed on the region padded by one zero row and column (the circular TV of a
    point that is zero off the region), run to convergence."""
    from clfza import regularizers as R

    (acam, ameas) = shot[1]
    B = get_backend("numpy", acam, model="exact")
    region = B.region
    rows, cols = np.where(region.any(1))[0], np.where(region.any(0))[0]
    v = rng.standard_normal(B.shape) * 0.3 + 0.2
    w = 0.05
    b = np.where(region > 0, v, off_value(w))[None]
    z = np.empty_like(b)
    B.fgp_prox("tv", z, b, w, 3000, ProxState(warm=False), True)
    assert np.all(z[0][region == 0] == 0.0) and z.min() >= 0.0
    sub = np.zeros((rows.size + 1, cols.size + 1))
    sub[:-1, :-1] = v[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    mask = np.zeros_like(sub)
    mask[:-1, :-1] = 1.0
    ref, _ = R.fgp(np.where(mask > 0, sub, off_value(w)), w, 3000, None, nonneg=True)
    got = z[0][rows[0]:rows[-1] + 2, cols[0]:cols[-1] + 2]
    assert np.abs(got - ref).max() <= 1e-6


@pytest.mark.parametrize("case", [0, 1])
def test_apg_matches_numpy_and_stays_feasible(shot, case):
    cam, meas = shot[case]
    kw = dict(model="exact", iters=15, stop="none", tau=0.005, algorithm="apg")
    ref, rinfo = clfza.reconstruct(meas.clean_y, cam, "admm", backend="numpy", **kw)
    img, info = clfza.reconstruct(meas.clean_y, cam, "admm", **kw)
    assert info.stats["algorithm"] == "apg" and rinfo.params["model"] == "exact"
    assert np.abs(img - ref).max() <= 1e-3 * np.abs(ref).max()
    assert ref.min() >= 0.0 and img.min() >= 0.0


@pytest.mark.parametrize("case", [0, 1])
def test_apg_objective_falls_and_reaches_the_split_admms(shot, case):
    """Same problem as the crop-split ADMM: after its restarts the APG's objective never
    ends above where it started, and with enough iterations it is at or below what the ADMM
    reaches in the same count (both solve ``F`` on the same normalised operator)."""
    cam, meas = shot[case]
    kw = dict(model="exact", iters=300, stop="none", tau=0.002, backend="numpy", highpass=0)
    _, ainfo = clfza.reconstruct(meas.clean_y, cam, "admm", algorithm="apg", **kw)
    _, sinfo = clfza.reconstruct(meas.clean_y, cam, "admm", **kw)
    fa = np.asarray(ainfo.objective)
    assert fa[-1] < fa[0] and np.minimum.accumulate(fa)[-1] == pytest.approx(fa[-1], rel=0.05)
    # the ADMM's returned objective is in the normalised units; the APG starts at x = 0,
    # where F = ||y~||^2 / 2 in those units: the ratio is the units' factor
    B = get_backend("numpy", cam, model="exact")
    B.set_measurement(meas.clean_y[None])
    f_split = min(sinfo.stats["objective_last"], sinfo.stats["objective_mean"])
    assert fa[-1] / fa[0] * (0.5 * B.ynorm2) <= 1.01 * f_split


def test_apg_options_are_checked(shot):
    cam, meas = shot[0]
    with pytest.raises(ClfzaError, match="algorithm must be one of"):
        clfza.reconstruct(meas.clean_y, cam, "admm", model="exact", algorithm="newton")
    with pytest.raises(ClfzaError, match="nonneg"):
        clfza.reconstruct(meas.clean_y, cam, "admm", model="exact", algorithm="apg",
                          nonneg=False, backend="numpy", iters=2)
    with pytest.raises(ClfzaError, match="does not take option"):
        clfza.reconstruct(meas.clean_y, cam, "admm", model="tf", algorithm="apg")
