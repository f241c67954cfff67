"""The crop-split ADMM continued from where a run ended (:class:`CropAdmmState`), as
``tau="auto"`` runs its final solve from its last pilot pass: at the same ``tau`` the
continuation is the same run as one of the summed length (every split, dual and penalty carried
over), on the float64 reference and on OpenCL; at a new ``tau`` its duals are rescaled, and it
starts near the new minimiser where a start from the image alone first falls away from it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import clfza
from clfza.backends import get_backend
from clfza.solvers import _driver as driver
from clfza.solvers._admm_crop import AdmmCropSolver, CropAdmmOptions, CropAdmmState
from clfza.solvers._common import Monitor


@pytest.fixture(scope="module")
def frame():
    cam = clfza.Camera(pitch=0.01, shape=(40, 40), r1=0.07, z1=20.0, z2=3.0, R=0.25)
    scene = np.zeros((40, 40))
    scene[8:30, 10:18] = 1.0
    scene[14:22, 22:34] = 0.6
    return cam, clfza.simulate(scene, cam)


def _run(B, x0, tau: float, iters: int, **kw):
    opts = CropAdmmOptions.from_options({"tau": tau, "iters": iters, "stop": "none", **kw},
                                        method="admm", exact=True)
    solver = AdmmCropSolver(B, opts, Monitor(B))
    res = driver.run(solver, x0)
    return solver, res


def _backend(kind, frame):
    cam, meas = frame
    B = get_backend(kind, cam, model="exact",
                    dtype=np.float64 if kind == "numpy" else np.float32)
    B.set_measurement(meas.y[None] / B.data_scale)
    return B


@pytest.mark.parametrize("kind", ["numpy", "opencl"])
def test_continuing_at_the_same_tau_is_one_longer_run(frame, kind):
    B = _backend(kind, frame)
    # 20 iterations: a multiple of the mu1 balancing period, which counts from each start
    whole, r_whole = _run(B, B.zeros(), 1e-3, 50, average=False)
    first, _ = _run(B, B.zeros(), 1e-3, 20, average=False)
    state = first.end_state()
    assert isinstance(state, CropAdmmState)
    second, r_second = _run(B, state, 1e-3, 30, average=False)
    assert second.mu1 == whole.mu1
    a, b = B.to_host(r_whole.x), B.to_host(r_second.x)
    tol = 1e-12 if kind == "numpy" else 1e-5  # float32: the same kernels, in one order
    assert np.max(np.abs(a - b)) <= tol * np.max(np.abs(a))
    assert r_second.objective[-1] == pytest.approx(r_whole.objective[-1], rel=tol * 10)


def test_a_new_tau_starts_near_its_minimiser(frame):
    """After a run at 10 tau, 10 more iterations at tau from its state reach a lower
    objective than 10 from its image alone (whose duals start at zero)."""
    B = _backend("numpy", frame)
    pilot, r_pilot = _run(B, B.zeros(), 1e-2, 100, average=False)
    x_image = B.to_host(r_pilot.x).copy()
    _, warm = _run(B, pilot.end_state(), 1e-3, 10, average=False)
    _, cold = _run(B, x_image, 1e-3, 10, average=False)
    _, ref = _run(B, x_image, 1e-3, 2000, average=False)
    f_ref = ref.objective[-1]
    assert warm.objective[-1] - f_ref < 0.5 * (cold.objective[-1] - f_ref)


def test_the_rescaled_duals(frame):
    """The support dual in the new mu3's units, the differences' dual in the new rho's and
    tau's (its multiplier rho u scales with tau); the mu1 balancing's penalty carried."""
    B = _backend("numpy", frame)
    pilot, _ = _run(B, B.zeros(), 1e-2, 30, average=False)
    st = pilot.end_state()
    u1, s = st.u1.copy(), st.s.copy()
    nxt = AdmmCropSolver(B, CropAdmmOptions.from_options(
        {"tau": 1e-3, "iters": 1, "rho": 3.0 * st.rho, "mu": 2.0 * st.mu3},
        method="admm", exact=True), Monitor(B))
    nxt.setup(st)
    assert nxt.mu1 == st.mu1 and not nxt.rhs_ready
    np.testing.assert_allclose(nxt.s, s / 2.0, rtol=1e-12)
    np.testing.assert_allclose(nxt.u1, u1 / 3.0 * 0.1, rtol=1e-12)


@pytest.mark.parametrize("var, continued", [(0.0, True), (0.1, False)])
def test_tau_auto_continues_the_last_pass_on_a_noise_free_frame(var, continued):
    """A frame the pilot passes call noise-free (a mask with an aperture, so the high-pass):
    the final solve continues the last pass, and the record and the note say so; a noisy
    frame's starts from the last pass's image."""
    from skimage import data
    from skimage.transform import resize

    cam = clfza.Camera(pitch=0.01, shape=(64, 64), r1=0.1, z1=20.0, z2=3.0, R=0.3)
    scene = resize(data.camera().astype(float), (40, 40))
    noise = clfza.Noise(gaussian_var=var, seed=1) if var else None
    meas = clfza.simulate(scene, cam, noise=noise)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, info = clfza.reconstruct(meas.y, cam, "admm", tau="auto", backend="numpy",
                                    model="exact")
    a = info.stats["tau_auto"]
    assert a["highpass"] and a["continued"] is continued
    assert (a["rule"] == "noise_free") is continued
    note = next(n for n in info.notes if n.startswith("tau=auto"))
    assert ("continues the last pass" in note) is continued



def test_the_accelerated_proximal_gradient_is_not_continued():
    """``algorithm="apg"`` keeps no crop-split state: its final solve starts from the last
    pass's image, noise-free or not."""
    cam = clfza.Camera(pitch=0.01, shape=(48, 48), r1=0.1, z1=20.0, z2=3.0, R=0.25)
    scene = np.zeros((30, 30))
    scene[5:20, 8:14] = 1.0
    meas = clfza.simulate(scene, cam)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        img, info = clfza.reconstruct(meas.y, cam, "admm", tau="auto", backend="numpy",
                                      model="exact", algorithm="apg", iters=120)
    assert info.stats["tau_auto"]["continued"] is False
    assert np.isfinite(img).all()
