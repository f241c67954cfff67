"""FISTA's extrapolated point in the memory of the data term's FFT scratch
(clfza.backends._base.Backend.scratch_image): the OpenCL backend's scratch image really shares
the spectrum's memory, and FISTA gives the same iterates with it as with an array of its own,
on both models, grey and joint colour, on the host FFT and on the device FFT a GPU takes."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import clfza
from clfza.backends import get_backend
from clfza.backends._opencl import OpenCLBackend
from clfza.cl._arrays import DeviceArray
from clfza.errors import ClfzaError

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)

N = 40


def _camera(shape=(N, N)):
    cam = dataclasses.replace(clfza.Camera.preset("simulation").at_depth(200.0), mask="gzp",
                              R=None)
    return dataclasses.replace(cam, shape=shape, pitch=cam.pitch * 512 / shape[0])


def test_leading_view_shares_memory(rt):
    parent = DeviceArray.from_host(rt, np.arange(24, dtype=np.float32).reshape(2, 3, 4))
    view = parent.leading_view((2, 5), np.float32)
    np.testing.assert_array_equal(view.get(), np.arange(10, dtype=np.float32).reshape(2, 5))
    view.set(np.full((2, 5), -1.0, np.float32))
    got = parent.get().reshape(-1)
    np.testing.assert_array_equal(got[:10], -1.0)
    np.testing.assert_array_equal(got[10:], np.arange(10, 24))
    with pytest.raises(ClfzaError, match="does not fit"):
        parent.leading_view((25,), np.float32)


@pytest.mark.parametrize("shape", [(N, N), (30, 34), (33, 45)])
def test_scratch_image_is_the_spectrum_memory(rt, shape):
    B = get_backend("opencl", _camera(shape), device=rt.info.index)
    s = B.scratch_image()
    assert s.shape == B.empty().shape and s.dtype == B.dtype
    s.set(np.ones(s.shape))
    B.set_measurement(np.zeros(shape))
    x = B.from_host(np.random.default_rng(0).random(s.shape))
    g = B.empty()
    B.resid_grad(x, g)  # the data term's FFTs go through the scratch
    assert not np.all(s.get() == 1.0)
    assert get_backend("numpy", _camera(shape)).scratch_image() is None


def _solve(m, cam, monkeypatch, own: bool, **kw):
    """FISTA with its extrapolated point in an array of its own (``own``) or in the scratch;
    returns the result and how many scratch images the backend handed out."""
    made = []
    original = OpenCLBackend.scratch_image

    def scratch(self):
        made.append(1)
        return original(self)

    monkeypatch.setattr(OpenCLBackend, "scratch_image",
                        (lambda self: None) if own else scratch)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = clfza.reconstruct(m.y, cam, "fista", backend="opencl", iters=15, stop="none", **kw)
    monkeypatch.undo()
    return r, len(made)


def _scene(colour: bool = False):
    """A box on the sensor plane of a small GZP camera (FISTA moves its objective there in
    every variant below; on a DC-free natural scene with ``nonneg`` it stays at x = 0)."""
    n = 48
    cam = clfza.Camera(pitch=0.02, shape=(n, n), r1=0.098 / 1.015 * 2, z1=200.0, z2=3.0,
                       mask="gzp")
    t = np.zeros((n, n))
    t[10:35, 15:30] = 1.0
    if colour:
        t = np.stack([t, np.roll(t, 5, axis=0), 0.5 * np.roll(t, 7, axis=1)], axis=-1)
    return cam, clfza.simulate(t, cam, sensor_plane=True)


@pytest.mark.parametrize("kw", [
    {"nonneg": True},
    {"reg": "l1"},
    {"fft": "device"},
    {"model": "exact"},
    {"colour": "joint"},
])
def test_fista_same_with_the_scratch(monkeypatch, kw):
    cam, m = _scene(colour="colour" in kw)
    own, _ = _solve(m, cam, monkeypatch, True, **kw)
    shared, made = _solve(m, cam, monkeypatch, False, **kw)
    assert made >= 1
    obj = shared.info.objective
    assert obj[-1] < obj[0]  # FISTA moved: the extrapolated point mattered
    np.testing.assert_array_equal(shared.image, own.image)
    assert obj == own.info.objective
    assert shared.info.iterations == own.info.iterations == 15
