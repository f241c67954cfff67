"""The measurement behind the default OpenCL device: a short solve on each CPU device.

:mod:`clfza.cl._runtime` takes the fastest of several CPU devices by default, from scores it
caches on disk (``device_scores.json`` in :func:`clfza.cl._runtime.cache_dir`). Measuring a
device means running a solver on it, and the solvers sit above the runtime layer, so the
runtime does not import them: it calls the measurement registered with
:func:`clfza.cl._runtime.set_device_measurer`. This module holds that measurement and
:func:`install` registers it; :mod:`clfza.reconstruction._reconstruct` and the command line
(:mod:`clfza.cli._commands`) install it when they load, so every ``clfza.reconstruct`` and every
``clfza`` command chooses by measurement. The dependency goes one way: ``api -> device_choice ->
solvers -> cl.runtime``.
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..cl import (
    MEASURE_ITERS,
    MEASURE_SIZE,
    device_problems,
    set_device_measurer,
)
from ..solvers import run_solver


def usable_devices() -> list[str]:
    """The OpenCL devices (``"P:D"``) that compile kernels: those
    :func:`clfza.cl._runtime.device_problems` finds no problem with."""
    return [k for k, why in device_problems().items() if why is None]


def measure_device(index: str, n: int = MEASURE_SIZE,
                   iters: int = MEASURE_ITERS) -> float:
    """Milliseconds per paper-mode TwIST iteration at ``n^2`` (float32) on device ``index``.

    Best of three short solves after a warm-up solve that compiles the kernels. The solves are
    those ``clfza.reconstruct(y, camera, "twist", mode="paper", backend="opencl",
    device=index, model="tf", ...)`` runs (:func:`clfza.solvers.run_solver`), on a random
    measurement of a critically sampled camera.

    Parameters
    ----------
    index : str
        OpenCL device as ``"P:D"`` (platform and device indices).
    n : int
        Grid size (rows and columns).
    iters : int
        Iterations of each timed solve.

    Returns
    -------
    float
        Milliseconds per iteration of the fastest timed solve.
    """

    rng = np.random.default_rng(0)
    p = 0.01
    cam = Camera(pitch=p, shape=(n, n), r1=np.sqrt(n) * p / (1 + 3.0 / 20.0), z1=20.0, z2=3.0,
                 R=None, mask="gzp")
    y = rng.standard_normal((n, n)).astype(np.float32)
    kw = dict(method="twist", mode="paper", backend="opencl", device=index, model="tf",
              min_iters=iters, stop="none")
    run_solver(y, cam, iters=1, **{k: v for k, v in kw.items() if k != "min_iters"})
    best = float("inf")
    for _ in range(3):
        r = run_solver(y, cam, iters=iters, **kw)
        best = min(best, r.info.timings["solve"] / max(1, r.info.iterations))
    return best * 1e3


def install() -> None:
    """Register :func:`measure_device` as the runtime's device measurement (idempotent)."""
    set_device_measurer(measure_device)
