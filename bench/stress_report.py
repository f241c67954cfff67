"""Numerical stability stress report (issues 5 and 14): every case gives a finite image or a
clear error; counts of cases, NaN/Inf images, crashes, objective rises where monotonicity is
promised, and the largest float32/float64 gaps.

The cases are :func:`clfza.benchmarks._stability.cases` (both models on the ``stress_camera``
family) and, defined here, the exact finite-aperture model on the experiment preset binned to
small odd, prime and even grids (:func:`exact_cases`, categories ``exact-*``):

- ``exact-size``: BP, TwIST (paper, efficient, l1), FISTA and ADMM (iterate-weighted mean)
  on the exact model x 29..61 px incl. primes and a non-square grid x OpenCL float32,
  OpenCL float64 and the numpy float64 reference;
- ``exact-admm``: the crop-split ADMM's options: ``average`` on/off, 1 and 2 iterations, the
  400-iteration default, ``stop="none"``, ``adapt``, ``support`` and ``nonneg`` off, the data
  term's high-pass off and at its smallest;
- ``exact-psf``: measured PSFs (``psf=``): the mask's shadow on the frame and 1.6x past it, a
  noisy capture through :func:`clfza.models._psf.load_psf`, a one-hot PSF, a 3x3 box, a PSF with a
  1e9 bright pixel, the shadow scaled by 1e-100 .. 1e100, an
  :class:`~clfza.models._exact.ExactModel` given as ``psf=``; invalid PSFs (negative, zero, NaN)
  must be refused;
- ``exact-tau``: tau from 1e-12 to 1e6 on the exact model;
- ``tau-auto``: ``tau="auto"`` for TwIST, FISTA and ADMM on both models;
- ``exact-frames``: all-zero, constant, one-hot (DC-free and raw), saturated (clipped scene,
  16-bit sensor at 4x exposure) frames and a hot pixel on a scene;
- ``exact-range``: the frame scaled by 1e-12 .. 1e12 (fixed tau and ``tau="auto"``) and a
  scene with a 1e6:1 point source.

FISTA and TwIST promise a non-increasing objective on the exact model too (checked in every
case); :func:`exact_precision_gap` compares OpenCL float32 with the numpy float64 reference
on the exact model over 1000 iterations, and :func:`paired_gaps` every case run in both
precisions (the pytest suite asserts a gap <= 0.1 dB in the categories of :data:`PAIRED`).
Known bugs are named by :func:`known_bug` (and in the report's "Known bugs" section).

Writes ``stress_report.json/.md`` into ``--out`` (default ``bench/results``)::

    python bench/stress_report.py
    python bench/stress_report.py --level test --precision-size 64 --precision-iters 100
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from clfza.benchmarks import _stability as stability
from clfza.benchmarks._methods import MethodSpec
from clfza.benchmarks._stability import StressCase

#: configurations the stability module lacks, registered beside its EXTRA_SPECS (which
#: ``run_case`` looks up by key). ``bp-exact`` is marked iterative only so that
#: ``run_case`` passes ``model=`` and ``psf=`` through (it drops a BP's options otherwise).
EXACT_SPECS = {
    "bp-exact": MethodSpec("bp-exact", "BP exact model", "bp", {"model": "exact"}, iters=1,
                           fft_pairs=1, arrays=2.5, iterative=True),
    "twist-tv-auto": MethodSpec("twist-tv-auto", "TwIST-TV tau=auto", "twist",
                                {"mode": "paper", "reg": "tv", "tau": "auto"}, monotone=True),
    "fista-tv-auto-m": MethodSpec("fista-tv-auto-m", "FISTA-TV tau=auto (monotone)", "fista",
                                  {"reg": "tv", "tau": "auto"}, monotone=True),
}
stability.EXTRA_SPECS.update(EXACT_SPECS)

RUNS = (("opencl", np.float32), ("opencl", np.float64), ("numpy", np.float64))
EXACT_KEYS = ["bp-exact", "twist-tv-paper", "twist-tv-efficient", "twist-l1", "fista-tv",
              "admm-tv"]
AUTO_KEYS = ["twist-tv-auto", "fista-tv-auto-m", "admm-tv-auto"]


# ------------------------------------------------------------------------------------------
# cameras, shots and frames
# ------------------------------------------------------------------------------------------
def preset_camera(shape: tuple[int, int]):
    """The experiment preset (binary FZA, aperture radius 4.56 mm) binned so that the larger
    side of ``shape`` spans the full 2400-pixel sensor: a finite aperture about as wide as
    the sensor, far under critical sampling."""
    from clfza import Camera

    cam0 = Camera.preset("experiment")
    return cam0.with_shape(tuple(shape), cam0.pitch * 2400 / max(shape))


def _scene_shot(cam, noise: float = 0.02, seed: int = 0):
    """The 'camera' scene at 300 mm (200 mm wide) through ``cam``: ``(y, truth)`` with
    Gaussian noise of ``noise`` x std(y)."""
    from skimage import data

    from clfza.simulation import simulate

    m = simulate(data.camera(), cam, object_width=200.0)
    y = m.clean_y
    if noise:
        y = y + np.random.default_rng(seed).normal(0.0, noise * y.std(), y.shape)
    return y, m.truth


def _preset_shot(shape, noise: float = 0.02):
    def make():
        cam = preset_camera(shape)
        y, truth = _scene_shot(cam, noise)
        return y, cam, truth
    return make


def _tf_shot(n: int):
    def make():
        cam = stability.stress_camera(n, 1.0)
        y, truth = stability.model_shot(cam, 0.05)
        return y, cam, truth
    return make


def _exact_frame(shape, kind: str):
    """Degenerate frames on the preset camera (no truth: PSNR is not defined)."""
    def make():
        cam = preset_camera(shape)
        h, w = cam.shape
        if kind == "zero":
            y = np.zeros(cam.shape)
        elif kind == "constant":
            y = np.full(cam.shape, -2.5)
        elif kind in ("one-hot", "one-hot raw"):
            y = np.zeros(cam.shape)
            y[h // 3, w // 5] = 65535.0
            if kind == "one-hot":  # DC-free, in the units of K
                y = (y - y.mean()) * 2 * cam.pitch**2 / cam.r1p**2
        elif kind == "saturated":  # the scene's frame clipped at 30% of its peak
            y, _ = _scene_shot(cam, 0.0)
            y = np.minimum(y, 0.3 * y.max())
            y = y - y.mean()
        elif kind == "saturated sensor":  # 16-bit sensor at 4x its full scale
            from skimage import data

            from clfza.simulation import Noise, simulate

            y = simulate(data.camera(), cam, object_width=200.0,
                         noise=Noise(bit_depth=16, exposure=4.0, seed=3)).y
        elif kind == "hot pixel on scene":
            y, _ = _scene_shot(cam, 0.02)
            y = y.copy()
            y[1, 2] += 1e3 * np.abs(y).max()
        else:
            raise ValueError(kind)
        return y, cam, None
    return make


def _exact_scaled(shape, scale: float):
    def make():
        cam = preset_camera(shape)
        y, truth = _scene_shot(cam, 0.02)
        return y * scale, cam, truth
    return make


def _hdr_shot(shape, ratio: float = 1e6):
    """A dim scene with one point source ``ratio`` times brighter than its brightest pixel
    (off centre), noise-free: dynamic range ``ratio``."""
    def make():
        from skimage import data

        from clfza.simulation import point_sources, simulate

        cam = preset_camera(shape)
        dim = simulate(data.camera(), cam, object_width=200.0)
        spot = point_sources(cam, [(30.0, -20.0, ratio)])
        bright = simulate(spot, cam, sensor_plane=True)
        return dim.clean_y + bright.clean_y, cam, None
    return make


def measured_psf(shape, kind: str) -> np.ndarray:
    """A PSF for the preset camera on ``shape``: the mask's shadow of a point (the light
    pattern a point-source capture records), altered by ``kind``."""
    from clfza.models._psf import load_psf
    from clfza.simulation import shadow_pattern

    cam = preset_camera(shape)
    h, w = cam.shape
    if kind == "shadow":
        return shadow_pattern(cam, (h, w))
    if kind == "shadow 1.6x":
        return shadow_pattern(cam, (int(1.6 * h) | 1, int(1.6 * w) | 1))
    if kind == "noisy capture":  # Poisson counts of a 200-photon peak plus a dark offset
        rng = np.random.default_rng(5)
        raw = rng.poisson(200.0 * shadow_pattern(cam, (h, w))) + rng.normal(0, 3, (h, w))
        return np.array(load_psf(raw, background=4.0, center="peak").array)
    if kind == "one-hot":
        p = np.zeros((h, w))
        p[h // 2, w // 2] = 1.0
        return p
    if kind == "3x3 box":
        return np.ones((3, 3))
    if kind == "bright pixel 1e9":
        p = shadow_pattern(cam, (h, w)).copy()
        p[h // 4, w // 3] = 1e9
        return p
    if kind.startswith("x "):  # "x 1e-30": the shadow in other units (scale-free)
        return shadow_pattern(cam, (h, w)) * float(kind[2:])
    if kind == "negative":
        return -shadow_pattern(cam, (h, w))
    if kind == "zero":
        return np.zeros((h, w))
    if kind == "nan":
        p = shadow_pattern(cam, (h, w)).copy()
        p[0, 0] = np.nan
        return p
    raise ValueError(kind)


# ------------------------------------------------------------------------------------------
# the cases
# ------------------------------------------------------------------------------------------
def exact_model_psf(shape, scale: float = 1.0):
    """An :class:`clfza.models._exact.ExactModel` passed as ``psf=`` (used as it is, no
    normalisation): the camera's own kernel times ``scale``."""
    from clfza.models._exact import ExactModel, shadow_kernel

    cam = preset_camera(shape)
    return ExactModel(shadow_kernel(cam) * scale, cam.shape)


#: cases that show a known bug (see :func:`known_bug`); the pytest suite runs them as
#: strict xfails, the report counts them as they come out
#: fixed: a PSF or ExactModel scaled by 1e-100 or 1e100 gave NaN (BP) or ZeroDivisionError
#: (solvers): clfza.models._exact.operator_norm no longer under/overflows its squares, BP scales the
#: frame before the device, the exact solves see the frame at a fixed RMS, and a tau that
#: the float32 solver cannot carry is a one-line error (clfza.solvers._check_tau_range)
FIXED_PSF_SCALE = True


BUG_F32_OBJECTIVE = (
    "fixed: float32 TwIST and MFISTA stalled on the exact model with a finite aperture, "
    "because the OpenCL exact backend's data term sum (Cy - hx)^2 - n m^2 cancelled where "
    "the window mean m of H x (the aperture's DC) is large (1e-5..1e-3 relative noise in the "
    "objective, good steps rejected by the monotone tests); window_row_sums now sums "
    "(Cy - hx + m0)^2 with m0 the previous evaluation's mean and subtracts n (m - m0)^2")


def known_bug(case: StressCase) -> str | None:
    """The known bug a case shows, or None."""
    del case  # none open (FIXED_PSF_SCALE); the float32 stall is a precision case
    return None


def exact_cases(level: str = "report") -> list[StressCase]:
    """The exact-model categories (module docstring): the same cases at both levels (the
    grids are small), 40 iterations at ``level="report"``, 20 at ``"test"``."""
    it = 20 if level == "test" else 40
    sizes = [(29, 29), (31, 31), (37, 37), (48, 48), (53, 53), (61, 61), (37, 53)]
    n0 = (37, 37)
    out: list[StressCase] = []

    def add(cat, name, make, key, be="opencl", dt=np.float32, expect="finite", **opts):
        if key != "bp-exact":
            opts = {"iters": it, "model": "exact", **opts}
        tag = f"{be} {np.dtype(dt).name}"
        out.append(StressCase(cat, f"{name} [{tag}]", make, key, backend=be, options=opts,
                              expect=expect, dtype=dt))

    for shp in sizes:
        for k in EXACT_KEYS:
            for be, dt in RUNS:
                add("exact-size", f"{shp[0]}x{shp[1]}", _preset_shot(shp), k, be, dt)

    admm_variants = [("average, 1 iteration", {"iters": 1}),
                     ("average, 2 iterations", {"iters": 2}),
                     ("last iterate, 1 iteration", {"iters": 1, "average": False}),
                     ("last iterate", {"average": False}),
                     ("average, stop=none, 3x iters", {"iters": 3 * it, "stop": "none"}),
                     ("average, adapt=False", {"adapt": False}),
                     ("average, support and nonneg off", {"support": False,
                                                          "nonneg": False}),
                     ("last iterate, nonneg off", {"average": False, "nonneg": False}),
                     ("average, no data high-pass", {"highpass": 0}),
                     ("average, high-pass k=1", {"highpass": 1})]
    for shp in (n0, (53, 53)):
        for name, o in admm_variants:
            for be, dt in RUNS:
                add("exact-admm", f"{shp[0]}x{shp[1]} {name}", _preset_shot(shp), "admm-tv",
                    be, dt, **o)
    # the exact model's default: 400 iterations, the weighted mean (no iters given)
    for be, dt in RUNS:
        out.append(StressCase("exact-admm", f"{n0[0]}x{n0[1]} default 400 iterations "
                              f"[{be} {np.dtype(dt).name}]", _preset_shot(n0), "admm-tv",
                              backend=be, options={"model": "exact"}, dtype=dt))

    psf_keys = ["bp-exact", "twist-tv-paper", "fista-tv", "admm-tv", "fista-tv-auto-m",
                "admm-tv-auto"]
    psfs = [(f"psf {kind}", measured_psf(n0, kind)) for kind in (
        "shadow", "shadow 1.6x", "noisy capture", "one-hot", "3x3 box", "bright pixel 1e9",
        "x 1e-30", "x 1e+30", "x 1e-100", "x 1e+100")]
    psfs += [("psf exact model object", exact_model_psf(n0)),
             ("psf exact model object x 1e-100", exact_model_psf(n0, 1e-100))]
    for name, psf in psfs:
        for k in psf_keys:
            for be, dt in RUNS[::2]:
                # a model object is used as is: with tau in the user's units its normalised
                # tau (~1e92 at 1e-100) is beyond float32, a one-line error is the answer
                tiny_model = name.endswith("object x 1e-100") and k != "bp-exact"
                add("exact-psf", name, _preset_shot(n0), k, be, dt, psf=psf,
                    expect="any" if tiny_model and dt == np.float32 else "finite")
    for kind in ("negative", "zero", "nan"):
        psf = measured_psf(n0, kind)
        for k in ("bp-exact", "fista-tv", "admm-tv"):
            # BP does not check the PSF's sign (the solvers refuse a non-positive sum)
            expect = "any" if (kind == "negative" and k == "bp-exact") else "error"
            add("exact-psf", f"psf {kind} (refused)", _preset_shot(n0), k, expect=expect,
                psf=psf)

    taus = (1e-12, 1e-6, 1e2, 1e6)
    tau_keys = ["twist-tv-paper", "twist-tv-efficient", "twist-l1", "fista-tv", "admm-tv"]
    for tau in taus:
        for k in tau_keys:
            for be, dt in RUNS[::2]:
                add("exact-tau", f"tau={tau:g}", _preset_shot(n0, 0.05), k, be, dt, tau=tau)

    for k in AUTO_KEYS:
        for be, dt in RUNS:
            add("tau-auto", f"{n0[0]}x{n0[1]} exact, tau=auto", _preset_shot(n0, 0.05), k,
                be, dt)
            out.append(StressCase("tau-auto", f"{n0[0]}x{n0[1]} tf, tau=auto "
                                  f"[{be} {np.dtype(dt).name}]", _tf_shot(n0[0]), k,
                                  backend=be, options={"iters": it, "model": "tf"},
                                  dtype=dt))

    frame_kinds = ["zero", "constant", "one-hot", "one-hot raw", "saturated",
                   "saturated sensor", "hot pixel on scene"]
    frame_keys = ["bp-exact", "twist-tv-paper", "twist-l1", "fista-tv", "admm-tv",
                  "admm-tv-auto"]
    for kind in frame_kinds:
        for k in frame_keys:
            for be, dt in RUNS[::2]:
                add("exact-frames", kind, _exact_frame(n0, kind), k, be, dt)

    range_keys = ["twist-tv-paper", "fista-tv", "admm-tv", "twist-tv-auto", "fista-tv-auto-m",
                  "admm-tv-auto"]
    for scale in (1e-12, 1e-6, 1.0, 1e6, 1e12):
        for k in range_keys:
            for be, dt in RUNS[::2]:
                add("exact-range", f"y x {scale:g}", _exact_scaled(n0, scale), k, be, dt)
    for k in range_keys:
        for be, dt in RUNS[::2]:
            add("exact-range", "point source 1e6 x the scene", _hdr_shot(n0), k, be, dt)
    return out


#: categories at ordinary settings, where float32 must give the float64 PSNR (extreme tau
#: and scale make the problem ill-conditioned: their gaps are reported, not asserted)
PAIRED = ("exact-size", "exact-admm", "exact-psf", "tau-auto")
CATEGORIES = ("exact-size", "exact-admm", "exact-psf", "exact-tau", "tau-auto",
              "exact-frames", "exact-range")


# ------------------------------------------------------------------------------------------
# running them (child processes, as clfza.benchmarks._stability.run_isolated)
# ------------------------------------------------------------------------------------------
def _worker(level: str, indices: list[int]) -> None:
    allc = exact_cases(level)
    for i in indices:
        r = stability.run_case(allc[i])
        r.pop("traceback", None)
        r["dtype"] = np.dtype(allc[i].dtype).name
        sys.stdout.write(json.dumps({"index": i, **r}, default=str) + "\n")
        sys.stdout.flush()


def run_isolated(level: str, indices: list[int], log=print, timeout: float = 1800.0
                 ) -> list[dict]:
    """Run exact-model cases by index in a child process, restarting it after a hard crash
    (recorded as a ``crash`` of the case that was running): the stability module's runner
    with this script's worker."""
    script = str(Path(__file__).resolve())
    return stability.run_isolated(
        level, indices, log, timeout, all_cases=exact_cases(level),
        worker=lambda todo: [sys.executable, script, "--worker", level, json.dumps(todo)])


def paired_gaps(rows: list[dict]) -> list[dict]:
    """The same case in OpenCL float32 and in float64 (OpenCL and numpy): PSNR gaps of the
    cases where both gave an image with a PSNR."""
    by: dict[tuple, dict] = {}
    for r in rows:
        if r.get("psnr") is None:
            continue
        base = r["name"].rsplit(" [", 1)[0]
        by.setdefault((r["category"], base, r["key"]), {})[
            f"{r['backend']} {r.get('dtype', '')}"] = r["psnr"]
    out = []
    for (cat, name, key), d in by.items():
        p32 = d.get("opencl float32")
        for ref in ("opencl float64", "numpy float64"):
            if p32 is not None and d.get(ref) is not None:
                out.append({"category": cat, "name": name, "key": key, "reference": ref,
                            "psnr_f32": p32, "psnr_f64": d[ref],
                            "psnr_gap_db": abs(p32 - d[ref])})
    return out


def exact_precision_gap(key: str, n: int = 64, iters: int = 1000, **extra) -> dict:
    """:func:`clfza.benchmarks._stability.precision_gap` on the exact model: the preset camera
    on ``n x n``, OpenCL float32 against the numpy float64 reference, ``iters`` iterations
    (no early stop); same record."""
    import warnings

    from clfza import reconstruct
    from clfza.metrics import compare

    spec = stability._spec(key)
    y, truth = _scene_shot(preset_camera((n, n)), 0.02)
    cam = preset_camera((n, n))
    opts = dict(spec.options, model="exact", iters=iters, stop="none", truth=truth,
                checkpoints=[iters], **extra)
    res = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for tag, be, dt in (("f32", "opencl", np.float32), ("f64", "numpy", np.float64)):
            t0 = time.perf_counter()
            res[tag] = (reconstruct(y, cam, spec.method, backend=be, dtype=dt, **opts),
                        time.perf_counter() - t0)
    (r32, t32), (r64, t64) = res["f32"], res["f64"]
    p32, p64 = compare(r32.image, truth)["psnr"], compare(r64.image, truth)["psnr"]
    o32, o64 = r32.info.objective[-1], r64.info.objective[-1]
    rises = {}
    for tag, r in (("f32", r32), ("f64", r64)):
        h = np.asarray(r.info.objective, float)
        rtol = stability.MONOTONE_RTOL["float32" if tag == "f32" else "float64"]
        rises[tag] = int(np.sum(h[1:] > h[:-1] * (1 + rtol))) if spec.monotone else None
    label = spec.label + " exact" + "".join(f" {k}={v}" for k, v in extra.items())
    return {"key": key, "label": label, "size": n, "iterations": r32.info.iterations,
            "iterations_f64": r64.info.iterations, "reference": "numpy",
            "psnr_f32": p32, "psnr_f64": p64, "psnr_gap_db": abs(p32 - p64),
            "objective_f32": o32, "objective_f64": o64,
            "objective_gap": abs(o32 - o64) / max(abs(o64), 1e-300),
            "image_rel_diff": float(np.linalg.norm(r32.image - r64.image)
                                    / max(np.linalg.norm(r64.image), 1e-300)),
            "finite": bool(np.isfinite(r32.image).all() and np.isfinite(r64.image).all()),
            "monotone_rises": rises, "seconds_f32": t32, "seconds_f64": t64,
            "stats_f32": _solver_counts(r32.info.stats),
            "stats_f64": _solver_counts(r64.info.stats)}


def _solver_counts(stats: dict) -> dict:
    """The counters that show a stalled run: MFISTA's rejected steps, TwIST's fallbacks,
    max_svd doublings and no-op steps, ADMM's returned candidate."""
    keys = ("rejected", "fallbacks", "max_svd_doublings", "noop_ist_steps", "returned")
    return {k: stats[k] for k in keys if k in stats}


EXACT_PRECISION = [("twist-tv-paper", {}), ("fista-tv", {}), ("admm-tv", {}),
                   ("admm-tv", {"average": False})]


# ------------------------------------------------------------------------------------------
# the report
# ------------------------------------------------------------------------------------------
def _range_table(rows: list[dict]) -> list[str]:
    """PSNR of the exact-range cases by scale of the frame (a scale-free method gives the
    same PSNR at every scale)."""
    table: dict[tuple, dict] = {}
    scales = []
    for r in rows:
        if r["category"] != "exact-range" or not r["name"].startswith("y x "):
            continue
        sc = r["name"].rsplit(" [", 1)[0][4:]
        if sc not in scales:
            scales.append(sc)
        table.setdefault((r["key"], f"{r['backend']} {r.get('dtype', '')}"), {})[sc] = \
            r.get("psnr")
    if not table:
        return []
    lines = ["", "## Exact model: PSNR against the frame's scale (exact-range)", "",
             "With a fixed tau the problem changes with the scale (tau is in the frame's "
             "units); with tau=auto (tau chosen in proportion to the frame), a scale-free "
             "method gives the same PSNR at every scale.", "",
             "| method | run | " + " | ".join(f"y x {sc}" for sc in scales) + " |",
             "|---|---|" + "---|" * len(scales)]
    for (key, run), d in table.items():
        cells = ["-" if d.get(sc) is None else f"{d[sc]:.2f}" for sc in scales]
        lines.append(f"| {key} | {run} | " + " | ".join(cells) + " |")
    return lines


def _extra_markdown(rows: list[dict], pairs: list[dict], precision: list[dict],
                    elapsed: dict) -> str:
    lines = ["", "## Known bugs (cases kept as strict xfails in tests/test_stress.py)", ""]
    bugs: dict[str, list[dict]] = {}
    for r in rows:
        if r.get("known_bug"):
            bugs.setdefault(r["known_bug"], []).append(r)
    for reason, rs in bugs.items():
        lines += [f"- {reason}.", ""]
        lines += [f"  - {r['name']} {r['key']}: {r['outcome']} "
                  f"{(r.get('message') or '')[:80]}" for r in rs]
        lines.append("")
    ex = [g for g in precision if g["label"].endswith(" exact") or " exact " in g["label"]]
    if ex:
        lines += [f"- {BUG_F32_OBJECTIVE}. The exact-model float32/float64 runs "
                  f"({ex[0]['iterations_f64']} iterations, experiment preset on "
                  f"{ex[0]['size']}^2; asserted <= 0.1 dB by "
                  "test_exact_float32_against_float64_1000_iterations):", "",
                  "| method | PSNR f32 | PSNR f64 | PSNR gap (dB) | objective gap | "
                  "counters f32 | counters f64 |", "|---|---|---|---|---|---|---|"]
        lines += [f"| {g['label']} | {g['psnr_f32']:.3f} | {g['psnr_f64']:.3f} | "
                  f"{g['psnr_gap_db']:.3g} | {g['objective_gap']:.3g} | "
                  f"{g.get('stats_f32', {})} | {g.get('stats_f64', {})} |" for g in ex]
    lines += ["", "## Exact model: float32 against float64 per case", ""]
    if pairs:
        worst = sorted(pairs, key=lambda p: -p["psnr_gap_db"])[:10]
        lines += [f"{len(pairs)} pairs (the same case in OpenCL float32 and in OpenCL or "
                  f"numpy float64, both with a PSNR); largest gap "
                  f"{worst[0]['psnr_gap_db']:.3g} dB. The ten largest:", "",
                  "| category | case | method | reference | PSNR f32 | PSNR f64 | gap (dB) |",
                  "|---|---|---|---|---|---|---|"]
        lines += [f"| {p['category']} | {p['name']} | {p['key']} | {p['reference']} | "
                  f"{p['psnr_f32']:.3f} | {p['psnr_f64']:.3f} | {p['psnr_gap_db']:.2e} |"
                  for p in worst]
        ordinary = [p["psnr_gap_db"] for p in pairs if p["category"] in PAIRED]
        lines += ["", f"Largest gap in the ordinary categories {', '.join(PAIRED)} "
                  f"(asserted <= 0.1 dB by tests/test_stress.py): "
                  f"{max(ordinary, default=0.0):.3g} dB over {len(ordinary)} pairs."]
    lines += _range_table(rows)
    lines += ["", "## Run time", ""]
    lines += [f"- {k}: {v:.0f} s" for k, v in elapsed.items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--level", choices=("report", "test"), default="report",
                   help="report: 128^2 cases; test: 64^2 and fewer iterations")
    p.add_argument("--precision-size", type=int, default=256)
    p.add_argument("--precision-iters", type=int, default=1000)
    p.add_argument("--exact-precision-size", type=int, default=96)
    p.add_argument("--categories", nargs="+", default=None,
                   help="only these categories (stability's, the exact ones, 'precision')")
    p.add_argument("--no-isolate", action="store_true",
                   help="run cases in this process (a native crash then ends the run)")
    p.add_argument("--out", default=str(Path(__file__).parent / "results"))
    a = p.parse_args(argv)
    from clfza.benchmarks import _report as report

    t0 = time.perf_counter()
    cats = a.categories
    base = stability.run(None, level=a.level, precision_size=a.precision_size,
                         precision_iters=a.precision_iters, categories=cats,
                         isolate=not a.no_isolate)
    t1 = time.perf_counter()
    allc = exact_cases(a.level)
    idx = [i for i, c in enumerate(allc) if not cats or c.category in cats]
    if a.no_isolate:
        rows = []
        for i in idx:
            r = stability.run_case(allc[i])
            rows.append({**r, "dtype": np.dtype(allc[i].dtype).name})
    else:
        rows = run_isolated(a.level, idx)
    for i, r in zip(idx, rows, strict=True):
        if known_bug(allc[i]):
            r["known_bug"] = known_bug(allc[i])
        if r["outcome"] in ("nonfinite", "crash") or r.get("monotone_violations"):
            print(f"  {allc[i].id}: {r['outcome']} {r.get('message', '')} "
                  f"rises={r.get('monotone_violations')}")
    t2 = time.perf_counter()
    print(f"  {len(rows)} exact-model cases in {t2 - t1:.0f} s")
    precision = list(base["precision"])
    if "precision" in (cats or ["precision"]):
        for key, extra in EXACT_PRECISION:
            g = exact_precision_gap(key, a.exact_precision_size, a.precision_iters, **extra)
            precision.append(g)
            print(f"  float32/float64 {g['label']}: PSNR {g['psnr_f32']:.3f} / "
                  f"{g['psnr_f64']:.3f} (gap {g['psnr_gap_db']:.2e} dB)")
    t3 = time.perf_counter()
    all_rows = base["cases"] + rows
    pairs = paired_gaps(rows)
    counts = stability.summarise(all_rows, precision)
    counts["max_paired_psnr_gap_db"] = max((q["psnr_gap_db"] for q in pairs), default=0.0)
    elapsed = {"stability cases and their float32/float64 runs": t1 - t0,
               "exact-model cases": t2 - t1, "exact-model float32/float64 runs": t3 - t2,
               "total": t3 - t0}
    result = {**base, "counts": counts, "precision": precision, "cases": all_rows,
              "paired_gaps": pairs, "elapsed_s": t3 - t0, "elapsed": elapsed,
              "note": __doc__.strip().split("\n\n")[0]}
    paths = report.write_stability(result, Path(a.out))
    with open(paths["md"], "a", encoding="utf-8") as f:
        f.write(_extra_markdown(rows, pairs, precision, elapsed))
    print()
    for k, v in counts.items():
        print(f"  {k:24s} {v}")
    print("wrote", ", ".join(str(v) for v in paths.values()))
    bad = counts["nonfinite"] + counts["crashes"] + counts["monotone_violations"]
    return 1 if bad else 0


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--worker":
        _worker(sys.argv[2], json.loads(sys.argv[3]))
    else:
        raise SystemExit(main())
