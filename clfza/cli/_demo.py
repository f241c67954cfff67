"""``clfza demo``: simulate the paper's setup on a built-in image, reconstruct, report.

Writes a side-by-side PNG and a JSON of metrics (MSE, PSNR, SSIM after an affine fit, timings,
device) into a new numbered folder, and returns the summary.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np
from skimage import data

from .. import __version__
from ..camera import Camera
from ..cl import get_runtime
from ..io import new_run_dir, write_figure, write_json
from ..metrics import compare
from ..reconstruction import reconstruct
from ..simulation import Noise, simulate
from ..solvers import DEFAULT_BACKEND, METHODS
from ._common import first_run_line

# (label, method, options). The first entry is always back-propagation; iterative solvers
# are appended below when they are available.
DEMO_METHODS: list[tuple[str, str, dict]] = [("BP (Eq. 12)", "bp", {})]


def _demo_methods() -> list[tuple[str, str, dict]]:

    extra = []
    if "twist" in METHODS:
        extra.append(("TwIST-TV (paper mode)", "twist", {"mode": "paper"}))
    if "admm" in METHODS:
        # on Eq. 17 (the fastest) and on the exact model, the simulator's own map (the default
        # here; measurements: docs/measurements.md, clfza.cli._demo)
        extra.append(("ADMM-TV, Eq. 17 (fastest)", "admm", {"iters": 50, "model": "tf"}))
        extra.append(("ADMM-TV, exact model", "admm", {"iters": 200, "model": "exact"}))
    return DEMO_METHODS + extra


def warm_up_methods(y: np.ndarray, cam: Camera, methods, backend: str,
                    device: str | None) -> dict | None:
    """Run each method once (one iteration; the exact model's aside) before the timed runs, so
    that no method's time holds the OpenCL programs' builds, the first launches of its kernels
    (PoCL compiles a kernel then) or the device's first-use tuning: ``{"seconds",
    "compile_s"}``, or None on the numpy backend. A device's very first compile happens
    before, under its own status line (``clfza.cl.check.warm_up``)."""
    if backend != "opencl":
        return None
    rt = get_runtime(device)
    t0, c0 = time.perf_counter(), rt.compile_seconds
    for _label, method, opts in methods:
        if opts.get("model") == "exact":
            # its set-up (the exact model's tables) is work of every call, not of the first,
            # and costs seconds; its one program is in the on-disk cache since the first run
            continue
        short = dict(opts, iters=1) if method != "bp" else dict(opts)
        if method == "twist" and opts.get("mode") == "paper":
            short["iters"] = 2
        reconstruct(y, cam, method, backend=backend, device=device, **short)
    return {"seconds": time.perf_counter() - t0, "compile_s": rt.compile_seconds - c0}


def setup_record(first_run: dict | None, warm: dict | None) -> dict | None:
    """The record's ``setup``: everything before the timed solves, never in a method's time.

    Parameters
    ----------
    first_run : dict or None
        The command's first run on the machine and device, timed where it happened
        (:func:`clfza.cli._common.first_run`: measuring the CPU devices, compiling, tuning).
    warm : dict or None
        :func:`warm_up_methods`' ``{"seconds", "compile_s"}`` (None: numpy backend).

    Returns
    -------
    dict or None
        ``seconds`` and ``compile_s`` over both steps, ``device_s`` and ``tuning_s`` of the
        first run, and the two records as they are (``first_run``, ``warm_up``); None when
        neither ran.
    """
    if first_run is None and warm is None:
        return None
    fr, wu = first_run or {}, warm or {}
    return {"seconds": fr.get("seconds", 0.0) + wu.get("seconds", 0.0),
            "compile_s": fr.get("compile_s", 0.0) + wu.get("compile_s", 0.0),
            "device_s": fr.get("device_s", 0.0), "tuning_s": fr.get("tuning_s", 0.0),
            "first_run": first_run, "warm_up": warm}


def builtin_scene() -> np.ndarray:
    """scikit-image's 512x512 'camera' test image (ships inside scikit-image), in [0, 1]."""

    return data.camera().astype(np.float64) / 255.0


def run_demo(out: str | Path = "clfza-out", *, backend: str = DEFAULT_BACKEND,
             device: str | None = None, gaussian_var: float = 0.0,
             methods: list[tuple[str, str, dict]] | None = None, quiet: bool = False,
             first_run: dict | None = None) -> dict:
    """Simulate the paper's simulation setup and reconstruct it with each demo method.

    Parameters
    ----------
    out : path
        Base folder; results go to a new ``out/demo-NNN`` folder (nothing is overwritten).
    backend, device : str
        Reconstruction backend and OpenCL device spec.
    gaussian_var : float
        Gaussian noise variance on the observation (the paper's Fig. 7 uses 0.01).
    methods : list, optional
        (label, method, options) triples; default: BP plus the available solvers.
    quiet : bool
        Print nothing.
    first_run : dict, optional
        What the command's first run on this machine and device spent before the demo
        (:func:`clfza.cli._common.first_run`: the CPU devices' measurement, the first compile,
        the tuning), recorded in ``setup`` (:func:`setup_record`).

    Returns
    -------
    dict
        The summary written to ``metrics.json`` plus the output paths. ``setup``
        (:func:`setup_record`) holds the first run's steps (``first_run``) and the run of
        each method before the timed ones (``warm_up``, :func:`warm_up_methods`): device
        measurement, compile and first-use tuning, never in a method's time.
    """
    import matplotlib  # lazy: matplotlib takes ~0.5 s to import; only plots need it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib takes ~0.5 s to import; only plots need it

    cam = Camera.preset("simulation")
    scene = builtin_scene()
    t0 = time.perf_counter()
    meas = simulate(scene, cam, object_width=20.0, noise=Noise(gaussian_var=gaussian_var))
    t_sim = time.perf_counter() - t0
    methods = methods or _demo_methods()
    warm = warm_up_methods(meas.y, cam, methods, backend, device)
    setup = setup_record(first_run, warm)
    line = first_run_line(first_run)
    if not quiet and line:
        print(f"  {line}")
    if not quiet and warm is not None:
        print(f"  {'warm-up (not timed below)':<26s} {warm['seconds']:7.3f} s: OpenCL builds "
              f"{warm['compile_s']:.3f} s, first launches, tuning")
    rows = []
    images = []
    for label, method, opts in methods:
        t = time.perf_counter()
        rec = reconstruct(meas.y, cam, method, backend=backend, device=device, **opts)
        wall = time.perf_counter() - t
        m = compare(rec.image, meas.truth)
        rows.append({"label": label, "method": method, **m, "wall_s": wall,
                     "iterations": rec.info.iterations, "stop_reason": rec.info.stop_reason,
                     "timings": rec.info.timings, "device": rec.info.device})
        images.append((label, rec.image))
        if not quiet:
            print(f"  {label:<26s} PSNR {m['psnr']:6.2f} dB  SSIM {m['ssim']:.3f}  "
                  f"MSE {m['mse']:.5f}  {wall:7.3f} s  ({rec.info.device})")
    run_dir = new_run_dir(out, "demo")
    n = 2 + len(images)
    fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.6))
    panels = [("ground truth (sensor plane)", meas.truth), ("raw observation y", meas.y)]
    panels += [(f"{lab}\n{r['psnr']:.2f} dB", img)
               for (lab, img), r in zip(images, rows, strict=True)]
    for ax, (title, img) in zip(axes, panels, strict=True):
        ax.imshow(img, cmap="gray")
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    png = write_figure(run_dir / "demo.png", fig)
    plt.close(fig)
    summary = {
        "clfza_version": __version__,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": {"platform": platform.platform(), "processor": platform.processor(),
                    "python": platform.python_version()},
        "camera": cam.summary(),
        "scene": "skimage.data.camera, 20 mm wide at z1 = 20 mm",
        "noise": {"gaussian_var": gaussian_var},
        "simulate_s": t_sim,
        "setup": setup,
        "metrics_note": "MSE/PSNR/SSIM after a least-squares affine fit to the truth",
        "results": rows,
    }
    js = write_json(run_dir / "metrics.json", summary)
    summary["paths"] = {"png": str(png), "json": str(js), "dir": str(run_dir)}
    return summary
