"""Scaling: time per iteration from 256^2 to 4096^2 against the N^2 log N expectation (item 3).

Per size, each method runs a short solve with the stopping rule off (``stop="none"``) and two
checkpoints; the time per iteration is the solve clock between them (set-up, the first
iteration and the checkpoint work excluded). BP is timed as a whole reconstruction (median
of three solve clocks after a warm-up). Every method runs a short warm-up solve first
(:func:`warm_up`: compile, first launches, first-use tuning), timed apart in the row's
``warmup_s`` and never counted as iterations. The observation is ``K`` applied to the resized
'camera' image (the error does not matter here, only the work). Next to each time: the
machine limit of the same iteration measured in the same run
(:class:`clfza.benchmarks._timeerror.Limits`).
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
from skimage import data
from skimage.transform import resize

from ..errors import ClfzaError
from ..models import NumpyOperator
from ..reconstruction import reconstruct
from . import _report as report
from ._machine import machine_record, machine_slug
from ._methods import MethodSpec, by_key
from ._timeerror import Limits, bench_camera

DEFAULT_SIZES = (256, 512, 1024, 2048, 4096)


def iterations_for(n: int) -> int:
    """Iterations of a scaling solve: enough for a stable per-iteration time, few at 4096^2."""
    return {256: 30, 512: 20, 1024: 10, 2048: 6}.get(n, 4 if n >= 4096 else 20)


def observation(n: int) -> np.ndarray:
    """``K`` applied to scikit-image's 'camera' resized to ``n x n`` (float64)."""

    cam = bench_camera(n)
    img = resize(data.camera().astype(np.float64) / 255.0, (n, n), order=1,
                 anti_aliasing=n < 512)
    return NumpyOperator(cam, warn=False).forward(img)


def per_iteration(spec: MethodSpec, y: np.ndarray, n: int, backend: str, iters: int,
                  device: str | None = None, dtype=np.float32) -> tuple[float, int]:
    """Seconds per iteration of ``spec`` on an ``n x n`` grid (and the iterations timed)."""
    cam = bench_camera(n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if not spec.iterative:  # the solve clock of BP (device set-up excluded), median of 3
            reconstruct(y, cam, "bp", backend=backend, device=device, dtype=dtype)
            ts = [reconstruct(y, cam, "bp", backend=backend, device=device, dtype=dtype)
                  .info.timings["solve"] for _ in range(3)]
            return float(np.median(ts)), 1
        opts = dict(spec.options, iters=iters, stop="none", checkpoints=[1, iters])
        if spec.options.get("mode") == "paper":
            opts["min_iters"] = 1
        rec = reconstruct(y, cam, spec.method, backend=backend, device=device, dtype=dtype,
                          **opts)
    recs = {int(r["iteration"]): r["time"] for r in rec.info.checkpoints}
    if 1 in recs and iters in recs and iters > 1:
        return (recs[iters] - recs[1]) / (iters - 1), iters - 1
    return rec.info.timings["solve"] / max(1, rec.info.iterations), rec.info.iterations


def warm_up(spec: MethodSpec, y: np.ndarray, n: int, backend: str, device: str | None = None,
            dtype=np.float32) -> dict:
    """A short solve of ``spec`` at ``n^2`` before the timed one: the OpenCL programs' builds,
    the first launches (PoCL compiles a kernel then) and the device's first-use tuning for
    this size happen here, never in :func:`per_iteration`'s clock. ``{"wall_s",
    "compile_s"}``: its time, recorded beside the row, never counted as iterations."""
    cam = bench_camera(n)
    opts = dict(spec.options)
    if spec.iterative:
        opts.update(iters=2, stop="none")
        if spec.options.get("mode") == "paper":
            opts["min_iters"] = 1
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = reconstruct(y, cam, spec.method, backend=backend, device=device, dtype=dtype,
                          **opts)
    return {"wall_s": time.perf_counter() - t0,
            "compile_s": float(rec.info.timings.get("compile", 0.0))}


def plan(profile: str) -> list[tuple[int, str, list[str]]]:
    """(size, backend, method keys) of a scaling profile."""
    if profile == "tiny":
        return [(64, "opencl", ["bp", "admm-tv"]), (128, "opencl", ["bp", "admm-tv"])]
    if profile == "quick":
        keys = ["bp", "twist-tv-paper", "admm-tv"]
        return [(n, "opencl", keys) for n in (256, 512, 1024)] + \
               [(n, "numpy", ["bp", "admm-tv"]) for n in (256, 512, 1024)]
    if profile != "full":
        raise ClfzaError(f"profile must be 'quick', 'full' or 'tiny', got {profile!r}")
    allk = ["bp", "twist-tv-paper", "twist-tv-efficient", "twist-l1", "fista-tv", "admm-tv"]
    out = [(n, "opencl", allk) for n in DEFAULT_SIZES]
    out += [(n, "numpy", allk) for n in (256, 512, 1024, 2048)]
    out += [(4096, "numpy", ["bp", "admm-tv"])]
    return out


def fit(rows: list[dict]) -> list[dict]:
    """Per (method, backend): exponent k of ``t ~ (N^2)^k`` and the N^2 log N drift."""
    series: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        if "error" not in r:
            series.setdefault((r["key"], r["backend"]), []).append(r)
    out = []
    for (key, backend), rs in series.items():
        rs = sorted(rs, key=lambda r: r["size"])
        if len(rs) < 2:
            continue
        n = np.array([r["size"] for r in rs], float)
        t = np.array([r["per_iter_s"] for r in rs])
        k = float(np.polyfit(np.log(n**2), np.log(t), 1)[0])
        norm = t / (n**2 * np.log2(n))
        ratios = [r["ratio_to_limit"] for r in rs]
        out.append({"key": key, "label": rs[0]["label"], "backend": backend,
                    "sizes": [int(v) for v in n], "exponent_vs_N2": k,
                    "nlogn_ratio": float(norm[-1] / norm[0]),
                    "nlogn_normalised": [float(v) for v in norm / norm[0]],
                    "ratio_to_limit_range": [float(min(ratios)), float(max(ratios))]})
    return out


def run(profile: str = "quick", out: str | Path | None = None, device: str | None = None,
        sizes: list[int] | None = None, methods: list[str] | None = None,
        backends: list[str] | None = None, log=print, label: str | None = None,
        first_run: dict | None = None) -> dict:
    """Measure time per iteration against grid size and write ``scaling_<machine>.*``.

    Parameters
    ----------
    profile : {"quick", "full", "tiny"}
        Which plan (:func:`plan`); ``sizes``, ``methods`` and ``backends`` filter it.
    out : path, optional
        Folder for ``scaling_<machine>.json/.png/.md`` (nothing written when None).
    first_run : dict, optional
        What the run's first use of the device spent before any row (the command line's
        ``clfza.cli._common.first_run``: device measurement, compile, tuning), recorded as is
        in ``first_run``, never in a row's time or iterations.
    """
    t0 = time.perf_counter()
    rec = machine_record(device)
    label = label or machine_slug(rec)
    limits = Limits.for_profile(profile, device)
    rows: list[dict] = []
    limit_rows: list[dict] = []
    ys: dict[int, np.ndarray] = {}
    for n, backend, keys in plan(profile):
        if sizes and n not in sizes:
            continue
        if backends and backend not in backends:
            continue
        if methods:
            keys = [k for k in keys if k in methods]
        if n not in ys:
            ys[n] = observation(n)
            limit_rows.append({"size": n, "fft_pair_f32_s": limits.fft((n, n), np.float32),
                               "fft_pair_f64_s": limits.fft((n, n), np.float64)})
        dtype = np.float32 if backend == "opencl" else np.float64
        for spec in by_key(keys):
            iters = iterations_for(n)
            try:
                warm = warm_up(spec, ys[n], n, backend, device, dtype)
                t, timed = per_iteration(spec, ys[n], n, backend, iters, device, dtype)
            except (ClfzaError, MemoryError) as exc:
                log(f"  {n:5d} {backend:6s} {spec.label:20s} skipped: {exc}")
                rows.append({"key": spec.key, "size": n, "backend": backend,
                             "error": str(exc)})
                continue
            lim = limits.per_iteration(spec, (n, n), 1, dtype)
            rows.append({"key": spec.key, "label": spec.label, "size": n, "backend": backend,
                         "dtype": np.dtype(dtype).name, "per_iter_s": t,
                         "iterations_timed": timed, "limit_per_iter_s": lim,
                         "ratio_to_limit": t / lim, "work_model": spec.bytes_model(),
                         "warmup_s": warm["wall_s"], "warmup_compile_s": warm["compile_s"]})
            log(f"  {n:5d} {backend:6s} {spec.label:20s} {t * 1e3:9.2f} ms/it   limit "
                f"{lim * 1e3:8.2f} ms   x{t / lim:.1f}")
        ys.pop(n // 2, None)
    result = {"kind": "scaling", "profile": profile, "machine": rec,
              "limits": limits.to_dict(), "rows": rows, "limit_rows": limit_rows,
              "fits": fit(rows), "first_run": first_run,
              "elapsed_s": time.perf_counter() - t0,
              "note": __doc__.strip().splitlines()[0]}
    if out is not None:

        result["paths"] = report.write_scaling(result, Path(out), label)
    return result
