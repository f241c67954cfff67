"""One synchronisation per objective evaluation on devices with their own memory
(clfza.backends._base.read_all): the solvers read an evaluation's data term and regulariser sums
with one blocking copy, not one per sum, and get the same numbers.

On CPU devices the sums are host memory and nothing is copied, so the device-memory path a GPU
takes is forced here by building the backend with the runtime's zero-copy switched off (the
same kernels; the host FFT then copies through host memory, as it does on a GPU)."""

from __future__ import annotations

import dataclasses
import warnings
from contextlib import contextmanager

import numpy as np
import pytest

import clfza
from clfza.backends._base import Ready, read_all
from clfza.backends._opencl import DeviceScalars
from clfza.cl._arrays import DeviceArray

pytestmark = pytest.mark.agreement  # rerun on every OpenCL device (.ci/run)

N = 48


@contextmanager
def blocking_copies():
    """Count, while active, copies to host memory: (blocking, all), 2-D destinations only
    (the partial sums' (planes, m) arrays; images and spectra are 3-D)."""
    import pyopencl as cl

    counts = {"blocking": 0, "all": 0}
    copy = cl.enqueue_copy

    def counted(queue, dest, src, **k):
        if isinstance(dest, np.ndarray) and dest.ndim == 2:
            counts["all"] += 1
            counts["blocking"] += bool(k.get("is_blocking", True))
        return copy(queue, dest, src, **k)

    cl.enqueue_copy = counted
    try:
        yield counts
    finally:
        cl.enqueue_copy = copy


def _device_scalars(rt, sums: np.ndarray) -> DeviceScalars:
    part = DeviceArray.from_host(rt, sums)
    assert part.host is None  # device memory: a read is a copy
    return DeviceScalars(part, sums.shape[1], scale=0.5, planes=2)


def test_read_all_one_blocking_copy(rt, monkeypatch):
    monkeypatch.setattr(rt, "zero_copy", False)
    rng = np.random.default_rng(1)
    a_sums = rng.random((2, 300)).astype(np.float32)
    b_sums = rng.random((2, 77)).astype(np.float32)
    a, b = _device_scalars(rt, a_sums), _device_scalars(rt, b_sums)
    with blocking_copies() as n:
        va, vb, vr = read_all(a, b, Ready(3.0, 4.0))
    assert n == {"blocking": 0, "all": 2}  # both started; their events are the waits
    want_a = 0.5 * a_sums.astype(np.float64).sum(axis=1)
    want_b = 0.5 * b_sums.astype(np.float64).sum(axis=1)
    np.testing.assert_array_equal(va, want_a)
    np.testing.assert_array_equal(vb, want_b)
    np.testing.assert_array_equal(vr, [3.0, 4.0])
    # the last read waits for the queue: one blocking copy, the others started before it
    a2, b2 = _device_scalars(rt, a_sums), _device_scalars(rt, b_sums)
    with blocking_copies() as n:
        va2, vb2 = read_all(a2, b2)
    assert n == {"blocking": 1, "all": 2}
    np.testing.assert_array_equal(va2, want_a)
    np.testing.assert_array_equal(vb2, want_b)
    # a started read is a snapshot: reading again gives the same values without a copy
    with blocking_copies() as n:
        np.testing.assert_array_equal(a2.get(), want_a)
    assert n["all"] == 0


def _camera():
    cam = dataclasses.replace(clfza.Camera.preset("simulation").at_depth(200.0), mask="gzp",
                              R=None)
    return dataclasses.replace(cam, shape=(N, N), pitch=cam.pitch * 512 / N)


# blocking reads besides the iterations' evaluations: FISTA starts from a Wiener estimate,
# whose lam search reads |H|^2 once and whose solve reads its sums once (its inverse filter is
# filled on the device: no read); ADMM on this camera runs the exact model (crop split), whose
# finish reads the last iterate's and the mean's objectives and whose penalty balancing reads
# its residuals once in these 12 iterations (at iteration 10)
START_READS = {"twist": 0, "fista": 2, "admm": 3}


@pytest.mark.parametrize("method,opts", [
    ("twist", {"mode": "paper"}),
    ("fista", {"nonneg": True}),
    # a tau given: tau="auto" (ADMM's default) runs pilot solves first, whose reads are theirs
    ("admm", {"stop": "objective", "min_iters": 12, "tau": 0.005}),
])
def test_solvers_one_read_per_evaluation(rt, monkeypatch, method, opts):
    """Device memory (as on a GPU): one blocking read of sums per objective evaluation, and
    the same iterates and objectives as with the sums in host memory."""
    from skimage import data

    cam = _camera()
    m = clfza.simulate(data.camera(), cam, object_width=200.0)
    kw = {"iters": 12, "stop": "none", **opts}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = clfza.reconstruct(m.y, cam, method, backend="opencl", **kw)
        monkeypatch.setattr(rt, "zero_copy", False)
        with blocking_copies() as n:
            got = clfza.reconstruct(m.y, cam, method, backend="opencl", **kw)
    assert got.info.device == ref.info.device
    np.testing.assert_array_equal(got.image, ref.image)
    assert got.info.objective == ref.info.objective
    # one blocking read per objective evaluation (TwIST and FISTA read two sums each: the
    # other read is started, and its wait is the blocking one's)
    assert n["blocking"] == got.info.evaluations + START_READS[method]
    assert got.info.evaluations >= 12
