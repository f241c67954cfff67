"""Run time against error (issue 5, items 1 and 2).

For each method, backend, grid size, scene and noise, one solve records PSNR, SSIM and MSE
(after the least-squares affine fit of :func:`clfza.metrics.compare`: reconstructions are
defined up to offset and scale) against the solve's wall time at checkpoints; the per-iteration
time is set next to the machine's limit measured in the same run (:mod:`.machine`,
:mod:`.methods`). Wall times exclude kernel builds and FFT planning: every configuration is
warmed up first, and the solver's own ``timings["solve"]`` is used.

Cameras: the paper's simulation setup (512^2, p = 10 um, r1 = 0.23 mm, z1 = 20 mm, z2 = 3 mm,
R = 5.12 mm: ``r1'^2 / (N p^2) = 1.37``; object 20 mm wide) with the *sinusoidal* zone plate:
the authors' simulation code generates its "FZA" as ``0.5 (1 + cos(pi r^2 / r1^2))`` (the
binarisation is commented out in ``FZA.m``), so the paper row uses ``mask="gzp"``. For other
sizes the same camera with ``r1`` scaled so that the sampling ratio stays 1.37, ``R = N p`` and
the object ``20 N / 512`` mm wide (:func:`bench_camera`).
"""

from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError
from ..metrics import compare
from ..reconstruction import reconstruct
from ..simulation import Noise
from . import _report as report
from . import _scenes as scenes
from ._machine import fft_pair_time, machine_record, machine_slug, triad_bandwidth
from ._methods import MethodSpec, by_key

NOISES: dict[str, Noise | None] = {
    "none": None,
    "gauss0.01": Noise(gaussian_var=0.01, seed=0),
    "poisson1e7": Noise(photons=1e7, seed=0),
}
NOISE_TEXT = {
    "none": "noise-free",
    "gauss0.01": "Gaussian, variance 0.01 on y (paper Fig. 7)",
    "poisson1e7": "Poisson, 10^7 photo-electrons at the brightest raw pixel (SNR of y about "
                  "12 dB on the natural scene; 10^4 gives -18 dB because the FZA frame is a "
                  "small modulation on a large DC)",
}
PAPER_ROW = {"scene": "natural", "noise": "gauss0.01", "size": 512, "method": "twist-tv-paper"}
METRICS_NOTE = ("PSNR/SSIM/MSE against the simulated sensor-plane truth after a least-squares "
                "affine fit a*x + b (clfza.metrics.compare): K loses the DC and the scale is "
                "arbitrary; PSNR peak = the truth's range.")


def bench_camera(n: int, ratio: float | None = None) -> Camera:
    """The paper's simulation camera (sinusoidal mask) on ``n x n`` at the same sampling ratio.

    ``r1`` is scaled so that ``r1'^2 / (N p^2)`` stays at the preset's 1.37 (or ``ratio``),
    and the aperture is ``R = N p`` as in the preset (5.12 mm at 512).
    """
    base = replace(Camera.preset("simulation"), mask="gzp", name="simulation-gzp")
    if ratio is None and n == base.shape[0] == base.shape[1]:
        return base
    ratio = base.regime.ratio if ratio is None else float(ratio)
    r1p = math.sqrt(ratio * n) * base.pitch
    return replace(base, shape=(n, n), r1=r1p / base.shadow_scale, R=n * base.pitch,
                   name=f"simulation-{n}")


def checkpoint_schedule(iters: int, dense: bool = True) -> list[int]:
    """Iteration counts at which the error is recorded (roughly geometric, ends at iters)."""
    base = [1, 2, 3, 5, 7, 10, 15, 20, 30, 50, 70, 100, 150, 200, 300, 500, 700, 1000]
    if not dense:
        base = [1, 3, 10, 30, 100, 300, 1000]
    pts = sorted({k for k in base if k < iters} | {iters})
    return pts


# ------------------------------------------------------------------------------------------
# one solve with an error curve
# ------------------------------------------------------------------------------------------
def _solve(y, camera, spec: MethodSpec, backend: str, iters: int, dtype, device, **extra):
    opts = dict(spec.options)
    if spec.iterative:
        opts["iters"] = iters
    opts.update(extra)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        rec = reconstruct(y, camera, spec.method, backend=backend, device=device, dtype=dtype,
                          **opts)
        wall = time.perf_counter() - t0
    # tau="auto" (the default route): its search counts (it runs before the solve)
    solve = float(rec.info.timings.get("solve", wall)) + float(
        rec.info.timings.get("tau_search", 0.0))
    return rec, solve, wall


def _metrics(x: np.ndarray, truth: np.ndarray) -> dict:
    m = compare(x, truth)
    return {"psnr": m["psnr"], "ssim": m["ssim"], "mse": m["mse"]}


def _combine_channels(records: list[dict], truth: np.ndarray) -> list[dict]:
    """Merge per-channel checkpoint records of an independent RGB solve into one curve.

    Channels are solved one after another, so the time to iteration k of the colour image is
    the sum of the channels' times at k; MSE is the channel mean, PSNR is computed from it with
    the RGB truth's range, SSIM is the channel mean (what scikit-image does with
    ``channel_axis``). Every channel uses its own affine fit, as :func:`compare` does.
    """
    by_it: dict[int, list[dict]] = {}
    for r in records:
        by_it.setdefault(int(r["iteration"]), []).append(r)
    nch = truth.shape[2]
    rng = float(truth.max() - truth.min()) or 1.0
    out = []
    for it in sorted(by_it):
        rs = by_it[it]
        if len(rs) != nch:
            continue
        m = float(np.mean([r["mse"] for r in rs]))
        out.append({"iteration": it, "time": float(sum(r["time"] for r in rs)), "mse": m,
                    "psnr": float(10 * np.log10(rng**2 / m)) if m > 0 else float("inf"),
                    "ssim": float(np.mean([r["ssim"] for r in rs]))})
    return out


def trace(y: np.ndarray, camera: Camera, spec: MethodSpec, backend: str, truth: np.ndarray,
          iters: int | None = None, dtype=np.float32, device: str | None = None,
          dense: bool = True, warmup: bool = True, repeats: int = 1) -> dict:
    """Solve ``repeats`` times and record error against time at checkpoints, of the run of
    median time.

    The solvers' checkpoint facility (:class:`clfza.solvers._common.Monitor`) stops the solve
    clock while it copies the iterate and computes MSE/PSNR/SSIM against ``truth`` (after the
    affine fit), so one solve gives the whole curve with undistorted times.

    Parameters
    ----------
    y, camera, truth
        Observation, camera and ground truth of a simulated shot.
    spec : MethodSpec
        The method configuration.
    backend : {"opencl", "numpy"}
    iters : int, optional
        Iterations of the full run (default ``spec.iters``).
    dtype : numpy dtype
        OpenCL working precision (the numpy backend is float64).
    dense : bool
        Dense or sparse checkpoint schedule.
    warmup : bool
        Run two iterations first so that kernel builds and FFT plans are not timed.
    repeats : int
        Solves of the configuration; the curve and the times are those of the run whose time
        (its search included) is the median (of an even number, the lower middle), so that one
        slow run on a shared machine does not become the figure.

    Returns
    -------
    dict
        ``curve`` (list of iteration, time_s, psnr, ssim, mse), ``final`` metrics, ``solve_s``,
        ``iterations``, ``stop_reason``, ``per_iter_s``, ``evaluations_per_iter``, the
        solver's ``timings`` and the warm-up's ``warmup_s`` and ``warmup_compile_s`` (its wall
        time and program builds, never in the curve; None without ``warmup``),
        ``repeats`` and every run's time in ``runs_s``.
    """
    _check_repeats(repeats)
    iters = spec.iters if iters is None else int(iters)
    warm = None
    if warmup:
        wrec, _, wwall = _solve(y, camera, spec, backend, 2 if spec.iterative else 1, dtype,
                                device)
        warm = {"wall_s": wwall, "compile_s": float(wrec.info.timings.get("compile", 0.0))}
    curve: list[dict] = []
    evals = None
    if not spec.iterative:
        runs = [_solve(y, camera, spec, backend, 1, dtype, device) for _ in range(repeats)]
        rec, solve, wall = _median_run(runs)
        curve.append({"iteration": 1, "time_s": solve, **_metrics(rec.image, truth)})
    else:
        points = [0] + checkpoint_schedule(iters + 1, dense)  # paper mode runs iters + 1
        runs = [_solve(y, camera, spec, backend, iters, dtype, device, truth=truth,
                       checkpoints=points) for _ in range(repeats)]
        rec, solve, wall = _median_run(runs)
        records = rec.info.checkpoints
        if truth.ndim == 3 and any("channel" in r for r in records):
            records = _combine_channels(records, truth)
        # tau="auto": the trace is the final solve's, which starts once the search is done
        start = float(rec.info.timings.get("tau_search", 0.0))
        for r in records:
            curve.append({"iteration": int(r["iteration"]), "time_s": start + float(r["time"]),
                          "psnr": float(r["psnr"]), "ssim": float(r["ssim"]),
                          "mse": float(r["mse"])})
        curve.sort(key=lambda p: p["iteration"])
        if rec.info.iterations:
            evals = getattr(rec.info, "evaluations", 0) / rec.info.iterations / (
                truth.shape[2] if truth.ndim == 3 else 1)
    final = curve[-1]
    if spec.iterative:
        # per iteration between the first iteration and the end (setup excluded)
        first = next((p for p in curve if p["iteration"] >= 1), curve[0])
        span = final["iteration"] - first["iteration"]
        per_iter = ((final["time_s"] - first["time_s"]) / span if span > 0
                    else final["time_s"] / max(1, final["iteration"]))
    else:
        per_iter = final["time_s"]
    return {
        "curve": curve,
        "final": {k: final[k] for k in ("psnr", "ssim", "mse")},
        "solve_s": float(rec.info.timings.get("solve", final["time_s"])),
        "iterations": int(rec.info.iterations),
        "stop_reason": rec.info.stop_reason,
        "per_iter_s": float(per_iter),
        "evaluations_per_iter": evals,
        "timings": {k: float(v) for k, v in rec.info.timings.items()
                    if isinstance(v, (int, float))},
        "device": rec.info.device,
        "dtype": rec.info.dtype,
        "warmup_s": None if warm is None else warm["wall_s"],
        "warmup_compile_s": None if warm is None else warm["compile_s"],
        "repeats": len(runs),
        "runs_s": [r[1] for r in runs],
    }


def _median_run(runs: list[tuple]) -> tuple:
    """Of ``(rec, time, wall)`` runs (at least one), the one of median time (of an even
    number, the lower middle)."""
    return sorted(runs, key=lambda r: r[1])[(len(runs) - 1) // 2]


def _check_repeats(repeats) -> None:
    """``repeats`` is an integer of at least 1, or a one-line error before any solve."""
    if isinstance(repeats, bool) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
        raise ClfzaError(f"repeats must be an integer >= 1, got {repeats!r}")


# ------------------------------------------------------------------------------------------
# the machine limit for a grid
# ------------------------------------------------------------------------------------------
@dataclass
class Limits:
    """FFT pair times per (size, dtype) and the triad bandwidth, measured once per run."""

    bandwidth: dict = field(default_factory=dict)
    fft_pair: dict = field(default_factory=dict)

    def measure_bandwidth(self, device: str | None = None, tries: int = 3,
                          elements: int = 1 << 24) -> None:
        """Triad bandwidth; the best of ``tries`` medians (the machine is shared)."""
        best: dict | None = None
        for _ in range(tries):
            b = triad_bandwidth(elements, device=device)
            if best is None or b["limit_gb_per_s"] > best["limit_gb_per_s"]:
                best = b
        self.bandwidth = best or {}

    @classmethod
    def for_profile(cls, profile: str, device: str | None = None) -> Limits:
        """Limits with the triad bandwidth measured (briefly for the "tiny" profile)."""
        lim = cls()
        if profile == "tiny":
            lim.measure_bandwidth(device, tries=1, elements=1 << 20)
        else:
            lim.measure_bandwidth(device)
        return lim

    def fft(self, n: tuple[int, int], dtype) -> float:
        key = f"{n[0]}x{n[1]}-{np.dtype(dtype).name}"
        if key not in self.fft_pair:
            self.fft_pair[key] = fft_pair_time(tuple(n), dtype)
        return self.fft_pair[key]

    def per_iteration(self, spec: MethodSpec, shape: tuple[int, int], channels: int,
                      dtype) -> float:
        """Seconds of the machine limit for one iteration of ``spec`` (all channels)."""
        if not self.bandwidth:
            self.measure_bandwidth()
        bw = self.bandwidth["limit_gb_per_s"] * 1e9
        t = self.fft(shape, dtype)
        n = shape[0] * shape[1]
        return channels * spec.limit_seconds(n, np.dtype(dtype).itemsize, t, bw)

    def to_dict(self) -> dict:
        return {"triad": self.bandwidth, "fft_pair_s": dict(self.fft_pair),
                "bandwidth_used_gb_per_s": self.bandwidth.get("limit_gb_per_s"),
                "note": "limit per iteration = fft_pairs * t_fft_pair(N, dtype) + arrays * "
                        "N^2 * itemsize / bandwidth_used (best triad of the run); see "
                        "clfza.benchmarks._methods for the per-method model"}


# ------------------------------------------------------------------------------------------
# the grid
# ------------------------------------------------------------------------------------------
@dataclass
class Case:
    """One (scene, noise, size, backend) cell of the grid with the methods to run there."""

    scene: str
    noise: str
    size: int
    backend: str
    methods: list[str] | None = None  # keys; None = all available
    iters: int | None = None  # override every method's iteration count
    dense: bool = True


def grid(profile: str) -> list[Case]:
    """The benchmark grid of a profile.

    ``"quick"`` (under 2 minutes on 2 cores): the paper row (natural, Gaussian 0.01, 512^2)
    on OpenCL with every method, BP and ADMM on numpy, and the text scene at 256^2.
    ``"full"``: every scene x noise at 512^2 on OpenCL, the paper row and two scenes on numpy,
    sizes 256^2 to 2048^2 for the natural scene (2048^2 for BP, ADMM and efficient TwIST, with
    fewer iterations).
    ``"tiny"``: 64^2, 2 iterations (tests).
    """
    if profile == "tiny":
        return [Case("natural", "gauss0.01", 64, "opencl", ["bp", "twist-tv-paper", "admm-tv"],
                     iters=2, dense=False),
                Case("points", "none", 64, "numpy", ["bp", "admm-tv"], iters=2, dense=False)]
    if profile == "quick":
        return [Case("natural", "gauss0.01", 512, "opencl", None, dense=False),
                Case("natural", "gauss0.01", 512, "numpy", ["bp", "twist-tv-paper", "admm-tv"],
                     dense=False),
                Case("usaf", "none", 256, "opencl", ["bp", "twist-tv-paper", "admm-tv"],
                     dense=False)]
    if profile != "full":
        raise ClfzaError(f"profile must be 'quick', 'full' or 'tiny', got {profile!r}")
    cases = []
    for noise in NOISES:
        for scene in scenes.SCENES:
            cases.append(Case(scene, noise, 512, "opencl"))
    cases.append(Case("natural", "gauss0.01", 512, "numpy"))
    cases.append(Case("natural", "none", 512, "numpy"))
    cases.append(Case("usaf", "gauss0.01", 512, "numpy"))
    cases.append(Case("natural", "gauss0.01", 256, "opencl"))
    cases.append(Case("natural", "gauss0.01", 256, "numpy"))
    cases.append(Case("natural", "gauss0.01", 1024, "opencl"))
    cases.append(Case("natural", "gauss0.01", 1024, "numpy",
                      ["bp", "twist-tv-paper", "admm-tv"], dense=False))
    cases.append(Case("natural", "gauss0.01", 2048, "opencl",
                      ["bp", "twist-tv-efficient", "admm-tv"], iters=50, dense=False))
    return cases


def run_case(case: Case, limits: Limits, device: str | None = None, log=print,
             repeats: int = 1) -> list[dict]:
    """Simulate the case's shot and trace each method on it (``repeats`` solves each, the
    median run kept: :func:`trace`)."""
    cam = bench_camera(case.size)
    sm = scenes.measurement(case.scene, cam, NOISES[case.noise],
                            object_width=20.0 * case.size / 512)
    meas = sm.measurement
    rows = []
    specs = by_key(case.methods)
    channels = 1 if meas.y.ndim == 2 else meas.y.shape[2]
    for spec in specs:
        dtype = np.float32 if case.backend == "opencl" else np.float64
        iters = case.iters if (case.iters and spec.iterative) else None
        try:
            tr = trace(meas.y, cam, spec, case.backend, meas.truth, iters, dtype, device,
                       dense=case.dense, repeats=repeats)
        except ClfzaError as exc:
            log(f"  {spec.key:20s} {case.backend:6s} skipped: {exc}")
            rows.append({"key": spec.key, "error": str(exc), "scene": case.scene,
                         "noise": case.noise, "size": case.size, "backend": case.backend})
            continue
        lim = limits.per_iteration(spec, cam.shape, channels, np.dtype(tr["dtype"]))
        row = {
            "key": spec.key, "label": spec.label, "method": spec.method,
            "options": dict(spec.options, iters=iters or spec.iters) if spec.iterative
            else {},
            "scene": case.scene, "noise": case.noise, "size": case.size,
            "channels": channels, "backend": case.backend,
            "sampling_ratio": cam.regime.ratio, "snr_db": meas.info.get("snr_db"),
            **tr,
            "limit_per_iter_s": lim,
            "bandwidth_gb_per_s": limits.bandwidth.get("limit_gb_per_s"),
            "ratio_to_limit": tr["per_iter_s"] / lim if lim > 0 else None,
            "work_model": spec.bytes_model(),
            "paper_reference": (case.scene == PAPER_ROW["scene"]
                                and case.noise == PAPER_ROW["noise"]
                                and case.size == PAPER_ROW["size"]
                                and spec.key == PAPER_ROW["method"]),
        }
        rows.append(row)
        f = tr["final"]
        log(f"  {spec.label:26s} {case.backend:6s} {row['iterations']:4d} it  "
            f"{tr['solve_s']:8.3f} s  PSNR {f['psnr']:6.2f}  SSIM {f['ssim']:.3f}  "
            f"{tr['per_iter_s'] * 1e3:8.2f} ms/it  x{row['ratio_to_limit']:.1f} limit")
    return rows


def time_to_target(curve: list[dict], target: float) -> float | None:
    """Time of the first checkpoint with PSNR >= target (None when never reached)."""
    for p in curve:
        if p["psnr"] >= target - 1e-9:
            return float(p["time_s"])
    return None


def summarise(rows: list[dict]) -> list[dict]:
    """Per (scene, noise, size, backend): every method's time to the paper-mode final PSNR."""
    out = []
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        if "error" in r:
            continue
        groups.setdefault((r["scene"], r["noise"], r["size"], r["backend"]), []).append(r)
    for (scene, noise, size, backend), rs in groups.items():
        ref = next((r for r in rs if r["key"] == "twist-tv-paper"), None)
        if ref is None:
            continue
        target = ref["final"]["psnr"]
        t_ref = time_to_target(ref["curve"], target)
        for r in rs:
            t = time_to_target(r["curve"], target)
            out.append({"scene": scene, "noise": noise, "size": size, "backend": backend,
                        "key": r["key"], "label": r["label"], "target_psnr": target,
                        "time_to_target_s": t,
                        "speedup_vs_paper": (t_ref / t) if (t and t_ref) else None,
                        "final_psnr": r["final"]["psnr"], "final_ssim": r["final"]["ssim"],
                        "solve_s": r["solve_s"]})
    return out


def run(profile: str = "quick", out: str | Path | None = None, device: str | None = None,
        cases: list[Case] | None = None, log=print, label: str | None = None,
        merge: bool = False, first_run: dict | None = None, repeats: int = 1) -> dict:
    """Run the time-vs-error grid and write JSON, PNG and markdown into ``out``.

    Parameters
    ----------
    profile : {"quick", "full", "tiny"}
        Which grid (:func:`grid`); ignored when ``cases`` is given.
    out : path, optional
        Folder for ``time_error_<machine>.json/.png/.md`` (nothing written when None).
    cases : list of Case, optional
        A custom grid.
    label : str, optional
        File-name label (default: the machine slug).
    merge : bool
        Keep rows of an existing JSON in ``out`` whose (scene, noise, size, backend, key) this
        run does not redo (lets a full grid be built in several shorter runs).
    first_run : dict, optional
        What the run's first use of the device spent before any case (the command line's
        ``clfza.cli._common.first_run``: device measurement, compile, tuning), recorded as is
        in ``first_run``, never in a row.
    repeats : int
        Solves of each method and case; each row is the run of median time (:func:`trace`).
    """
    _check_repeats(repeats)  # before the machine's measurements and the first case
    t0 = time.perf_counter()
    rec = machine_record(device)
    label = label or machine_slug(rec)
    limits = Limits.for_profile(profile, device)
    rows: list[dict] = []
    for case in cases if cases is not None else grid(profile):
        log(f"[{case.scene} / {case.noise} / {case.size}^2 / {case.backend}]")
        rows.extend(run_case(case, limits, device, log, repeats))
    result = {
        "kind": "time_error",
        "profile": profile if cases is None else f"custom ({len(cases)} case(s))",
        "machine": rec,
        "limits": limits.to_dict(),
        "metrics_note": METRICS_NOTE,
        "camera_note": " ".join(__doc__.split("Cameras: ")[1].split()),
        "noise_models": NOISE_TEXT,
        "scenes": {s: scenes.describe(s) for s in scenes.SCENES},
        "paper_row": PAPER_ROW,
        "rows": rows,
        "repeats": repeats,
        "first_run": first_run,
        "elapsed_s": time.perf_counter() - t0,
    }
    if out is not None:

        path = Path(out) / f"time_error_{label}.json"
        if merge and path.exists():

            old = json.loads(path.read_text())
            done = {(r["scene"], r["noise"], r["size"], r["backend"], r["key"]) for r in rows}
            kept = [r for r in old.get("rows", [])
                    if (r["scene"], r["noise"], r["size"], r["backend"], r["key"]) not in done]
            result["rows"] = kept + rows
            result["merged_from"] = old.get("machine", {}).get("date")
        result["time_to_paper"] = summarise(result["rows"])
        result["paths"] = report.write_time_error(result, Path(out), label)
    else:
        result["time_to_paper"] = summarise(rows)
    return result
