"""Kernels fix their scalar argument types on their first launch (clfza.cl._kernels): pyopencl's
generic conversion of untyped numpy scalars cost ~7 us per scalar per launch. A typed kernel
computes the same, and after a solve of every iterative method every kernel the backend
launched is typed (a call site passing a Python scalar would leave its kernel on the slow
path, or fail)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pyopencl as cl
import pytest

import clfza
from clfza.backends import reuse_backends
from clfza.cl._kernels import TypedKernel

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)


def test_typed_on_first_launch(rt):
    k = rt.kernel("bench", "triad")
    assert isinstance(k, TypedKernel)
    n = 1000
    b = np.arange(n, dtype=np.float32)
    c = np.full(n, 0.5, np.float32)
    mf = cl.mem_flags
    bufs = [cl.Buffer(rt.context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=v)
            for v in (np.zeros(n, np.float32), b, c)]
    k(rt.queue, (n,), None, *bufs, np.float32(2.0), np.int32(n))
    assert k.typed is True
    k(rt.queue, (n,), None, *bufs, np.float32(4.0), np.int32(n))  # the typed path
    out = np.empty(n, np.float32)
    cl.enqueue_copy(rt.queue, out, bufs[0])
    np.testing.assert_array_equal(out, b + 4.0 * c)


def _camera(shape=(48, 48)):
    cam = dataclasses.replace(clfza.Camera.preset("simulation").at_depth(200.0), mask="gzp",
                              R=None)
    return dataclasses.replace(cam, shape=shape, pitch=cam.pitch * 512 / shape[0])


def _launched(B) -> list:
    ks = list(B.k.values())
    ks += [k for k in (getattr(B, "_prox_fused", None), getattr(B, "_fgp_fused", None)) if k]
    for fam in getattr(B, "_ops", {}).values():
        ks += list(getattr(fam, "k", {}).values())
    return [k for k in ks if isinstance(k, TypedKernel) and k.typed is not None]


@pytest.mark.parametrize("method,opts", [
    ("twist", {"mode": "paper"}), ("twist", {"mode": "efficient"}),
    ("fista", {"nonneg": True}), ("fista", {"reg": "l1"}),
    ("admm", {"nonneg": True}), ("admm", {"model": "exact"}),
    ("fista", {"fft": "device"}),
])
def test_solver_kernels_typed(method, opts):
    from skimage import data

    cam = _camera()
    m = clfza.simulate(data.camera(), cam, object_width=200.0)
    with warnings.catch_warnings(), reuse_backends() as cache:
        warnings.simplefilter("ignore")
        clfza.reconstruct(m.y, cam, method, backend="opencl", iters=6, **opts)
        backends = [b for b in cache._items.values() if hasattr(b, "k")]
    assert backends
    launched = [k for B in backends for k in _launched(B)]
    assert len(launched) >= 3
    untyped = [k.function_name for k in launched if not k.typed]
    assert untyped == []
