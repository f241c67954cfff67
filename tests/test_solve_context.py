"""One solve context passed down, nothing hung on the backend (issue 32): the tau rules, the
Wiener start and the solvers read the camera, the data scale and the channel group from a
:class:`~clfza.solvers._context.SolveContext`; a colour frame solved channel by channel keeps
every channel's solver statistics, and the exact model's grid survives the solve's own."""

from __future__ import annotations

import numpy as np
import pytest

import clfza
from clfza.backends import BackendCache, reuse_backends

pytestmark = pytest.mark.agreement


@pytest.fixture(scope="module")
def colour_shot():
    n, p = 64, 0.01
    cam = clfza.Camera(pitch=p, shape=(n, n), r1=np.sqrt(n) * p / (1 + 3.0 / 20.0), z1=20.0,
                       z2=3.0, R=None, mask="gzp")
    t = np.zeros((32, 32, 3))
    t[8:24, 10:20, 0] = 1.0
    t[4:20, 12:28, 1] = 0.6
    t[14:30, 6:22, 2] = 0.3
    return cam, clfza.simulate(t, cam, object_width=2.0,
                               noise=clfza.Noise(gaussian_var=1e-4, seed=1))


@pytest.mark.parametrize("backend", ["numpy", "opencl"])
def test_channel_by_channel_keeps_every_channels_stats(rt, colour_shot, backend):
    cam, m = colour_shot
    rec = clfza.reconstruct(m.y, cam, "wiener", backend=backend)
    channels = rec.info.stats["channels"]
    assert len(channels) == 3
    # each channel's own Wiener weight, from its own noise: three different records
    lams = [c["lam"] for c in channels]
    assert all(v > 0 for v in lams) and len(set(lams)) == 3
    for c, y in enumerate(np.moveaxis(m.y, -1, 0)):
        grey = clfza.reconstruct(y, cam, "wiener", backend=backend)
        assert grey.info.stats["lam"] == pytest.approx(lams[c], rel=1e-9)


def test_exact_model_grid_survives_the_solvers_stats(rt):
    cam = clfza.Camera(pitch=0.01, shape=(48, 48), r1=0.07, z1=20.0, z2=3.0, R=0.3)
    y = clfza.simulate(np.random.default_rng(0).random((24, 24)), cam).y
    rec = clfza.reconstruct(y, cam, "admm", backend="numpy", model="exact", iters=5)
    stats = rec.info.stats
    assert stats["model_grid"][0] >= 48 and stats["operator_norm"] > 0
    assert "mu1_final" in stats  # the solver's own statistics beside the model's


def test_nothing_is_set_on_a_reused_backend(rt, colour_shot):
    """A backend kept between frames carries no state of the previous frame's solve: the
    same frame solved on a fresh and on a reused backend gives the same image."""
    cam, m = colour_shot
    y0, y1 = m.y[..., 0], m.y[..., 1]
    with reuse_backends(BackendCache()) as cache:
        clfza.reconstruct(y0, cam, "admm", tau="auto", iters=20)
        again = clfza.reconstruct(y1, cam, "admm", tau="auto", iters=20)
    assert cache.hits == 1  # the second frame ran on the first frame's backend
    fresh = clfza.reconstruct(y1, cam, "admm", tau="auto", iters=20)
    np.testing.assert_allclose(again.image, fresh.image, rtol=1e-5, atol=1e-6)
    assert again.info.params["tau"] == pytest.approx(fresh.info.params["tau"], rel=1e-6)
