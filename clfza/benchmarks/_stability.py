"""Numerical stability stress cases (issue 5, item 4) and the report that counts them.

Every case runs one reconstruction and ends in one of four outcomes:

- ``finite``: an image with only finite values (the expected outcome of valid input);
- ``clear_error``: a :class:`~clfza.errors.ClfzaError` with a message (the expected outcome of
  invalid input: NaN/Inf data, bad parameters);
- ``nonfinite``: an image containing NaN or Inf (always a failure);
- ``crash``: any other exception, a ClfzaError where the library admits an internal failure
  ("bug"), or a clear error where a finite image was expected (always a failure).

Categories: float32 against float64 over 1000 iterations (PSNR and objective gaps); sampling
regimes ``r1'^2 / (N p^2)`` from 0.25 to 4; ``tau`` from 1e-6 to 10; noise up to 50% of the
signal; 16-bit frames with saturation; non-square and odd shapes; all-zero, constant and
single-hot-pixel frames; extreme scales; NaN and Inf inputs and invalid parameters (rejected).
Methods that promise a non-increasing objective (TwIST in both modes with ``monotone=True``,
MFISTA) have their objective history checked.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from skimage import data
from skimage.transform import resize

from ..camera import Camera
from ..errors import ClfzaError
from ..metrics import compare, fit_affine, psnr
from ..models import NumpyOperator
from ..reconstruction import reconstruct
from ..simulation import Noise, simulate
from . import _report as report
from ._machine import machine_record
from ._methods import MethodSpec, by_key

MONOTONE_RTOL = {"float32": 1e-6, "float64": 1e-12}
ALL_KEYS = ["bp", "twist-tv-paper", "twist-tv-efficient", "twist-l1", "fista-tv", "admm-tv"]


def stress_camera(n: int | tuple[int, int] = 128, ratio: float = 1.0) -> Camera:
    """A GZP camera on ``n`` (square int or (rows, cols)) at sampling ratio ``r1'^2/(N p^2)``
    (N = the larger side), aperture ``R = N p``, object at 20 mm, sensor 3 mm behind."""
    shape = (n, n) if isinstance(n, int) else tuple(n)
    p, z1, z2 = 0.01, 20.0, 3.0
    big = max(shape)
    r1p = float(np.sqrt(ratio * big) * p)
    return Camera(pitch=p, shape=shape, r1=r1p / (1 + z2 / z1), z1=z1, z2=z2, R=big * p,
                  mask="gzp", name=f"stress-{shape[0]}x{shape[1]}-r{ratio:g}")


def scene_truth(shape: tuple[int, int]) -> np.ndarray:
    """The 'camera' image resized to ``shape`` (sensor plane, in [0, 1])."""

    return resize(data.camera().astype(np.float64) / 255.0, shape, order=1, anti_aliasing=True)


def model_shot(camera: Camera, noise_frac: float = 0.0, seed: int = 0
               ) -> tuple[np.ndarray, np.ndarray]:
    """``y = K o`` for the resized 'camera' image, plus Gaussian noise of standard deviation
    ``noise_frac`` x std(K o). Returns (y, truth)."""
    truth = scene_truth(camera.shape)
    y = NumpyOperator(camera, warn=False).forward(truth)
    if noise_frac:
        rng = np.random.default_rng(seed)
        y = y + rng.normal(0.0, noise_frac * y.std(), size=y.shape)
    return y, truth


@dataclass
class StressCase:
    """One reconstruction under stress."""

    category: str
    name: str
    make: Callable[[], tuple[np.ndarray, Camera, np.ndarray | None]]
    key: str
    backend: str = "opencl"
    options: dict = field(default_factory=dict)
    expect: str = "finite"  # "finite", "error" or "any"
    dtype: type = np.float32

    @property
    def id(self) -> str:
        return f"{self.category}/{self.name}/{self.key}/{self.backend}"


#: issue 14's configurations, beside the benchmark's methods (see :func:`_spec`)
EXTRA_SPECS = {
    "wiener": MethodSpec("wiener", "Wiener (direct)", "wiener", {}, iters=1, fft_pairs=1,
                         arrays=3, iterative=False),
    "admm-tv-auto": MethodSpec("admm-tv-auto", "ADMM-TV tau=auto", "admm",
                               {"reg": "tv", "tau": "auto"}, fft_pairs=1, arrays=13.5),
    "fista-tv-auto": MethodSpec("fista-tv-auto", "FISTA-TV tau=auto", "fista",
                                {"reg": "tv", "tau": "auto"}, fft_pairs=1, arrays=32.5),
}
ISSUE14_KEYS = ALL_KEYS + list(EXTRA_SPECS)


def _spec(key: str) -> MethodSpec:
    if key in EXTRA_SPECS:
        return EXTRA_SPECS[key]
    return {s.key: s for s in by_key([key])}[key]


def run_case(case: StressCase) -> dict:
    """Run one case and classify its outcome (never raises)."""
    out: dict = {"category": case.category, "name": case.name, "key": case.key,
                 "backend": case.backend, "expect": case.expect}
    t0 = time.perf_counter()
    try:
        y, cam, truth = case.make()
    except ClfzaError as exc:  # the input itself was refused while being built
        out.update(outcome="clear_error" if case.expect != "finite" else "crash",
                   message=str(exc).splitlines()[0])
        return out
    spec = _spec(case.key)
    opts = dict(spec.options)
    opts.update(case.options)
    if not spec.iterative:  # BP takes no options; invalid-option cases target solvers only
        opts = {k: v for k, v in case.options.items() if k == "model" and spec.method != "bp"}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = reconstruct(y, cam, spec.method, backend=case.backend,
                              dtype=case.dtype, **opts)
    except ClfzaError as exc:
        msg = str(exc).splitlines()[0]
        internal = "bug" in msg.lower() or "report it" in msg.lower()
        ok = case.expect in ("error", "any") and not internal
        out.update(outcome="clear_error" if ok else "crash", message=msg,
                   error_type=type(exc).__name__, seconds=time.perf_counter() - t0)
        return out
    except Exception as exc:  # noqa: BLE001 - counting crashes is the point
        out.update(outcome="crash", message=f"{type(exc).__name__}: {exc}",
                   traceback=traceback.format_exc(limit=4), seconds=time.perf_counter() - t0)
        return out
    img = rec.image
    out["seconds"] = time.perf_counter() - t0
    out["iterations"] = rec.info.iterations
    out["stop_reason"] = rec.info.stop_reason
    if not np.isfinite(img).all():
        out.update(outcome="nonfinite", message=f"{int((~np.isfinite(img)).sum())} non-finite "
                                                "pixels")
        return out
    out["outcome"] = "finite" if case.expect in ("finite", "any") else "crash"
    if case.expect == "error":
        out["message"] = "expected a ClfzaError, got an image"
    if truth is not None and np.ptp(truth) > 0 and img.shape == truth.shape:
        out["psnr"] = psnr(fit_affine(img, truth), truth)  # SSIM needs >= 7x7
    if spec.monotone and spec.iterative:
        hist = rec.info.objective
        if hist and isinstance(hist[0], list):  # one history per channel
            seqs = hist
        else:
            seqs = [hist]
        rtol = MONOTONE_RTOL.get(rec.info.dtype, 1e-6)
        rises = 0
        worst = 0.0
        for h in seqs:
            h = np.asarray(h, float)
            if len(h) > 1:
                d = h[1:] - h[:-1] * (1 + rtol)
                bad = d > np.abs(h[:-1]) * 0.0
                rises += int(bad.sum())
                if bad.any():
                    worst = max(worst, float(np.max((h[1:] - h[:-1]) / np.abs(h[:-1]))))
        out["monotone_checked"] = True
        out["monotone_violations"] = rises
        out["largest_relative_rise"] = worst
    return out


# ------------------------------------------------------------------------------------------
# the cases
# ------------------------------------------------------------------------------------------
def _shot(n, ratio=1.0, noise=0.0):
    def make():
        cam = stress_camera(n, ratio)
        y, truth = model_shot(cam, noise)
        return y, cam, truth
    return make


def _simulated(n, noise):
    def make():

        cam = stress_camera(n, 1.0)
        m = simulate(scene_truth((n, n)), cam, sensor_plane=True, noise=noise)
        return m.y, cam, m.truth
    return make


def _frame(n, kind):
    def make():
        cam = stress_camera(n)
        if kind == "zero":
            y = np.zeros(cam.shape)
        elif kind == "constant":
            y = np.full(cam.shape, 3.7)
        elif kind == "hot-pixel":
            f = np.zeros(cam.shape)
            f[cam.shape[0] // 3, cam.shape[1] // 5] = 65535.0
            y = (f - f.mean()) * 2 * cam.pitch**2 / cam.r1p**2
        elif kind == "hot-pixel-on-scene":
            y, _ = model_shot(cam)
            y = y.copy()
            y[5, 7] += 1e3 * np.abs(y).max()
        elif kind == "saturated":  # a scene clipped at 30% of its peak: a flat-topped frame
            y, _ = model_shot(cam)
            y = np.minimum(y, 0.3 * y.max())
            y = y - y.mean()
        else:
            raise ValueError(kind)
        return y, cam, None
    return make


def _scaled(n, scale):
    def make():
        cam = stress_camera(n)
        y, truth = model_shot(cam, 0.05)
        return y * scale, cam, truth
    return make


def _bad(n, what):
    def make():
        cam = stress_camera(n)
        y, truth = model_shot(cam)
        y = y.copy()
        if what == "nan":
            y[3, 4] = np.nan
        elif what == "+inf":
            y[0, 0] = np.inf
        elif what == "-inf":
            y[-1, -1] = -np.inf
        elif what == "all-nan":
            y[:] = np.nan
        elif what == "wrong-shape":
            y = y[:-1]
        elif what == "complex":
            y = y.astype(np.complex128)
        return y, cam, truth
    return make


def _rgb(n, constant_channel: bool):
    def make():
        cam = stress_camera(n)
        y, truth = model_shot(cam)
        y3 = np.stack([y, 0.5 * y, np.zeros_like(y) if constant_channel else -y], axis=-1)
        t3 = np.stack([truth, truth, truth], -1)
        return y3, cam, (None if constant_channel else t3)
    return make


def cases(level: str = "report") -> list[StressCase]:
    """All stress cases. ``level="test"`` uses smaller grids and fewer iterations."""
    small = level == "test"
    n = 64 if small else 128
    it = 30 if small else 60
    out: list[StressCase] = []
    iterative = ALL_KEYS[1:]
    base = {"iters": it}
    for ratio in (0.25, 0.5, 1.0, 2.0, 4.0):
        for k in ALL_KEYS:
            out.append(StressCase("sampling", f"r1'^2/(Np^2)={ratio:g}", _shot(n, ratio, 0.02),
                                  k, options=base))
    for tau in (1e-6, 1e-4, 1e-2, 1.0, 10.0):
        for k in iterative:
            out.append(StressCase("tau", f"tau={tau:g}", _shot(n, 1.0, 0.05), k,
                                  options=dict(base, tau=tau)))
    for frac in (0.1, 0.25, 0.5):
        for k in ALL_KEYS:
            out.append(StressCase("noise", f"gaussian {frac:.0%} of signal std",
                                  _shot(n, 1.0, frac), k, options=base))

    for name, noise in (("poisson 100 photons", Noise(photons=100.0, seed=1)),
                        ("16-bit, exposure 1.5 (saturated)",
                         Noise(bit_depth=16, exposure=1.5, photons=1e5, seed=2)),
                        ("16-bit, exposure 4 (heavily saturated)",
                         Noise(bit_depth=16, exposure=4.0, seed=3)),
                        ("8-bit", Noise(bit_depth=8, seed=4))):
        for k in ALL_KEYS:
            out.append(StressCase("frames", name, _simulated(n, noise), k, options=base))
    shapes = [(n, n + 1), (n - 1, n + 1), (97, 61), (n, 40), (5, 3), (3, 3), (2, 2)]
    for shp in shapes:
        for k in ALL_KEYS:
            out.append(StressCase("shape", f"{shp[0]}x{shp[1]}", _shot(shp, 1.0, 0.02), k,
                                  options=base))
    for kind in ("zero", "constant", "hot-pixel", "hot-pixel-on-scene"):
        for k in ALL_KEYS:
            for be in ("opencl", "numpy"):
                out.append(StressCase("degenerate", kind, _frame(n, kind), k, backend=be,
                                      options=base))
    for scale in (1e-12, 1e-6, 1e6, 1e12):
        for k in ALL_KEYS:
            out.append(StressCase("scale", f"y x {scale:g}", _scaled(n, scale), k,
                                  options=base, expect="any"))
    for what in ("nan", "+inf", "-inf", "all-nan", "wrong-shape", "complex"):
        for k in ALL_KEYS:
            out.append(StressCase("rejected", what, _bad(n, what), k, options=base,
                                  expect="error"))
    bad_opts = [("tau=0", {"tau": 0.0}), ("tau=-1", {"tau": -1.0}),
                ("tau=nan", {"tau": float("nan")}), ("tau=inf", {"tau": float("inf")}),
                ("iters=0", {"iters": 0}), ("tv_iters=-1", {"tv_iters": -1}),
                ("unknown option", {"bogus": 1})]
    for name, o in bad_opts:
        for k in iterative:
            out.append(StressCase("rejected", name, _shot(n), k, options=o, expect="error"))
    for const in (False, True):
        for k in ("bp", "twist-tv-paper", "admm-tv"):
            out.append(StressCase("rgb", "one constant channel" if const else "3 channels",
                                  _rgb(n, const), k, options=base))
    for k in ALL_KEYS:  # float64 on the OpenCL device and the numpy reference
        out.append(StressCase("float64", "opencl float64", _shot(n, 1.0, 0.05), k,
                              options=base, dtype=np.float64))
        out.append(StressCase("float64", "numpy reference", _shot(n, 1.0, 0.05), k,
                              backend="numpy", options=base))
    out += issue14_cases(level)
    return out


def issue14_cases(level: str = "report") -> list[StressCase]:
    """Issue 14: every configuration (the benchmark's methods, Wiener, ADMM/FISTA with
    ``tau="auto"``) on both models (Eq. 17 and the exact finite-aperture model; Wiener on the
    exact model must refuse clearly) x odd and prime sizes x OpenCL float32, OpenCL float64
    and the numpy reference; degenerate frames (zero, constant, one hot pixel, saturated);
    extreme ``tau`` and dynamic range."""
    small = level == "test"
    it = 20 if small else 40
    sizes = [(31, 31), (37, 29)] if small else [(61, 61), (67, 67), (97, 53), (89, 89),
                                                 (101, 59), (128, 127), (53, 53)]
    runs = [("opencl", np.float32), ("opencl", np.float64), ("numpy", np.float64)]
    out: list[StressCase] = []

    def add(cat, name, make, key, model, **kw):
        expect = kw.pop("expect", "finite")
        if key == "wiener" and model == "exact":
            expect = "error"
        opts = {"iters": it, "model": model, **kw.pop("options", {})}
        out.append(StressCase(cat, f"{name} model={model}", make, key, options=opts,
                              expect=expect, **kw))

    for model in ("tf", "exact"):
        for shp in sizes:
            for k in ISSUE14_KEYS:
                for be, dt in runs:
                    add("issue14-size", f"{shp[0]}x{shp[1]} {np.dtype(dt).name}",
                        _shot(shp, 1.0, 0.05), k, model, backend=be, dtype=dt)
        n = sizes[0][0]
        for kind in ("zero", "constant", "hot-pixel", "saturated"):
            for k in ISSUE14_KEYS:
                for be, dt in (runs if not small else runs[::2]):
                    add("issue14-degenerate", kind, _frame(n, kind), k, model, backend=be,
                        dtype=dt)
        for tau in (1e-9, 1e3):
            for k in ISSUE14_KEYS[1:6]:
                add("issue14-tau", f"tau={tau:g}", _shot(n, 1.0, 0.05), k, model,
                    options={"tau": tau})
        for scale in (1e-9, 1e9):
            for k in ISSUE14_KEYS:
                add("issue14-scale", f"y x {scale:g}", _scaled(n, scale), k, model,
                    expect="any")
    return out


# ------------------------------------------------------------------------------------------
# float32 against float64
# ------------------------------------------------------------------------------------------
def precision_gap(key: str, n: int = 256, iters: int = 1000, ref_backend: str = "numpy"
                  ) -> dict:
    """Run ``key`` for ``iters`` iterations (no early stop) in OpenCL float32 and in float64
    (``ref_backend``: the numpy reference or ``"opencl64"``) on the same shot; report the PSNR
    gap, the relative gap of the final objectives and the relative image difference."""
    spec = _spec(key)
    cam = stress_camera(n, 1.0)
    y, truth = model_shot(cam, 0.05)
    # truth= makes every solver keep its objective history (ADMM skips it otherwise)
    opts = dict(spec.options, iters=iters, stop="none", truth=truth, checkpoints=[iters])
    res = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for tag, be, dt in (("f32", "opencl", np.float32),
                            ("f64", "opencl" if ref_backend == "opencl64" else "numpy",
                             np.float64)):
            t0 = time.perf_counter()
            rec = reconstruct(y, cam, spec.method, backend=be, dtype=dt, **opts)
            res[tag] = (rec, time.perf_counter() - t0)
    (r32, t32), (r64, t64) = res["f32"], res["f64"]
    p32, p64 = compare(r32.image, truth)["psnr"], compare(r64.image, truth)["psnr"]
    o32 = r32.info.objective[-1] if r32.info.objective else float("nan")
    o64 = r64.info.objective[-1] if r64.info.objective else float("nan")
    diff = float(np.linalg.norm(r32.image - r64.image) / max(np.linalg.norm(r64.image), 1e-300))
    rises = {}
    for tag, r in (("f32", r32), ("f64", r64)):
        h = np.asarray(r.info.objective, float)
        rtol = MONOTONE_RTOL["float32" if tag == "f32" else "float64"]
        rises[tag] = int(np.sum(h[1:] > h[:-1] * (1 + rtol))) if spec.monotone else None
    return {"key": key, "label": spec.label, "size": n, "iterations": r32.info.iterations,
            "iterations_f64": r64.info.iterations, "reference": ref_backend,
            "psnr_f32": p32, "psnr_f64": p64, "psnr_gap_db": abs(p32 - p64),
            "objective_f32": o32, "objective_f64": o64,
            "objective_gap": (abs(o32 - o64) / max(abs(o64), 1e-300)
                              if np.isfinite(o32) and np.isfinite(o64) else None),
            "image_rel_diff": diff, "finite": bool(np.isfinite(r32.image).all()
                                                   and np.isfinite(r64.image).all()),
            "monotone_rises": rises, "seconds_f32": t32, "seconds_f64": t64}


# ------------------------------------------------------------------------------------------
# the report
# ------------------------------------------------------------------------------------------
def summarise(rows: list[dict], precision: list[dict]) -> dict:
    """The counts the issue asks for."""
    mono = [r for r in rows if r.get("monotone_checked")]
    prec_rises = sum(v or 0 for p in precision for v in p["monotone_rises"].values())
    return {
        "cases": len(rows) + 2 * len(precision),
        "finite": sum(r["outcome"] == "finite" for r in rows)
        + sum(2 * p["finite"] for p in precision),
        "clear_errors": sum(r["outcome"] == "clear_error" for r in rows),
        "nonfinite": sum(r["outcome"] == "nonfinite" for r in rows)
        + sum(2 * (not p["finite"]) for p in precision),
        "crashes": sum(r["outcome"] == "crash" for r in rows),
        "monotone_checked": len(mono) + sum(2 for p in precision if p["monotone_rises"]["f32"]
                                            is not None),
        "monotone_violations": sum(r.get("monotone_violations", 0) for r in mono) + prec_rises,
        "max_psnr_gap_db": max((p["psnr_gap_db"] for p in precision), default=0.0),
        "max_objective_gap": max((p["objective_gap"] for p in precision
                                  if p["objective_gap"] is not None), default=0.0),
        "max_image_rel_diff": max((p["image_rel_diff"] for p in precision), default=0.0),
    }


def _worker(level: str, indices: list[int]) -> None:
    """Run cases by index, one JSON line each on stdout (used by :func:`run_isolated`)."""

    allc = cases(level)
    for i in indices:
        r = run_case(allc[i])
        r.pop("traceback", None)
        sys.stdout.write(json.dumps({"index": i, **r}, default=str) + "\n")
        sys.stdout.flush()


def run_isolated(level: str, indices: list[int], log=print, timeout: float = 900.0, *,
                 worker=None, all_cases=None) -> list[dict]:
    """Run cases in a child process, restarting it after a hard crash (abort, segfault).

    A native crash cannot be caught in-process; here it is recorded as a ``crash`` of the case
    that was running, with the child's exit status and the last line of its stderr, and the
    remaining cases continue in a fresh child. ``worker(todo)`` gives the child's command line
    for the indices left and ``all_cases`` the list they index (default: this module's
    :func:`cases` and :func:`_worker`; ``bench/stress_report.py`` passes its own).
    """

    allc = cases(level) if all_cases is None else all_cases
    if worker is None:
        def worker(todo: list[int]) -> list[str]:
            return [sys.executable, "-c",
                    "import sys, json; from clfza.benchmarks._stability import _worker; "
                    "_worker(sys.argv[1], json.loads(sys.argv[2]))", level, json.dumps(todo)]
    todo = list(indices)
    rows: dict[int, dict] = {}
    while todo:
        try:
            proc = subprocess.run(worker(todo), capture_output=True, text=True,
                                  timeout=timeout)
            stdout, stderr, rc = proc.stdout, proc.stderr, proc.returncode
        except subprocess.TimeoutExpired as exc:
            stdout = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
            stderr, rc = "timeout", "timeout"
        for line in stdout.splitlines():
            if line.startswith("{"):
                r = json.loads(line)
                rows[r.pop("index")] = r
        todo = [i for i in todo if i not in rows]
        if not todo:
            break
        if rc != 0:  # the case that was running died with its process
            lost, why = [todo.pop(0)], f"process died (exit {rc})"
        else:  # a clean exit with cases left: should not happen
            lost, todo, why = todo, [], "worker exited without a result"
        tail = [ln for ln in stderr.strip().splitlines() if ln.strip()][-1:] or ["?"]
        for i in lost:
            c = allc[i]
            rows[i] = {"category": c.category, "name": c.name, "key": c.key,
                       "backend": c.backend, "expect": c.expect, "outcome": "crash",
                       "dtype": np.dtype(c.dtype).name, "message": f"{why}: {tail[0][:200]}"}
            log(f"  crash in {c.id}: {rows[i]['message']}")
    return [rows[i] for i in indices]


def run(out: str | Path | None = None, level: str = "report", precision_size: int = 256,
        precision_iters: int = 1000, precision_keys: list[str] | None = None,
        log=print, categories: list[str] | None = None, isolate: bool = True) -> dict:
    """Run every stress case and the float32/float64 comparison; write
    ``stress_report.json/.md`` into ``out``.

    ``isolate``: run the cases in child processes (:func:`run_isolated`) so that a native
    crash is counted instead of ending the run.
    """
    t0 = time.perf_counter()
    allc = cases(level)
    idx = [i for i, c in enumerate(allc) if not categories or c.category in categories]
    if isolate:
        rows = run_isolated(level, idx, log)
    else:
        rows = [run_case(allc[i]) for i in idx]
    for i, r in zip(idx, rows, strict=True):
        if r["outcome"] in ("nonfinite", "crash") or r.get("monotone_violations"):
            log(f"  {allc[i].id}: {r['outcome']} {r.get('message', '')} "
                f"rises={r.get('monotone_violations')}")
    log(f"  {len(rows)} cases in {time.perf_counter() - t0:.0f} s")
    precision = []
    keys = precision_keys if precision_keys is not None else [
        "twist-tv-paper", "twist-l1", "fista-tv", "admm-tv"]
    if "precision" not in (categories or ["precision"]):
        keys = []
    for k in keys:
        p = precision_gap(k, precision_size, precision_iters)
        precision.append(p)
        log(f"  float32/float64 {p['label']}: PSNR {p['psnr_f32']:.3f} / {p['psnr_f64']:.3f} "
            f"(gap {p['psnr_gap_db']:.2e} dB), objective gap {p['objective_gap']:.2e}, "
            f"image diff {p['image_rel_diff']:.2e}")
    result = {"kind": "stress", "level": level, "machine": machine_record(),
              "monotone_rtol": MONOTONE_RTOL, "counts": summarise(rows, precision),
              "precision": precision, "cases": rows,
              "elapsed_s": time.perf_counter() - t0,
              "note": __doc__.strip().split("\n\n")[0]}
    if out is not None:

        result["paths"] = report.write_stability(result, Path(out))
    return result


__all__ = ["StressCase", "cases", "run_case", "run_isolated", "precision_gap", "run",
           "stress_camera", "model_shot"]
