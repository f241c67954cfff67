"""Kernel variants chosen per device by a short measurement, cached on disk (``clfza tune``).

Which variant of a kernel is fastest depends on the implementation and the machine: whether
the one-pass fused TV prox (kernels/tv_fused.cl) beats the three tv.cl kernels, its strip
height, the rows per contribution of twist_combine's reduction and the work-group shapes
(measured: docs/measurements.md, clfza.backends._tuning). So, as FFTW's wisdom or CLBlast's
tuner do, each device measures the variants once per size class at first use (kernels
compiled beforehand; how long that takes: the same section), and the choices are cached next
to the default-device measurement (:func:`clfza.cl._runtime.cache_dir`, ``tuning.json``),
keyed by implementation, its version, device, driver version and a hash of the kernel sources.

The tuned parameters (:data:`PARAMS`):

``prox``    paper mode's TV prox: ``fused`` (tv_fused.cl, CPU float32 only) or ``split``
``strip``   rows per work-item of the fused prox
``rows``    rows per contribution in twist_combine's reduction (RROWS; GPUs and colour
            frames: one-channel float32 frames on CPU devices run twist_combine16)
``local2d`` work-group of the 2-D kernels: ``row`` (one image row, or 256/128/... that
            divides it), ``auto`` (the implementation chooses) or ``WxH``
``local1d`` work-group of the 1-D kernels: ``auto`` or a size
``fgp``     FISTA's FGP prox with 2 inner iterations: ``fused`` (tv_fused.cl's fgp2_fused, CPU
            float32 only) or ``split`` (fgp_step twice, fgp_finish)
``fgp_strip`` rows per work-item of the fused FGP (7 warm-up rows each)
``prox_prefetch``, ``fgp_prefetch`` software prefetch in the fused prox / FGP: ``off``, ``rN``
            (the rows a strip loads N steps ahead) or ``rwN`` (the rows it stores too)

``CLFZA_TUNE`` overrides: ``defaults`` (the built-in :data:`DEFAULTS`, nothing measured) or
``key=value,...`` (those pinned, the others tuned), e.g. ``CLFZA_TUNE=prox=split,strip=8``.
Measuring can be turned off while keeping cached choices with ``CLFZA_TUNE=cached``.
"""

from __future__ import annotations

import hashlib
import os
import threading
import time

import numpy as np

from ..camera import Camera
from ..cl import cache_dir, device_key, kernel_source, read_cache, write_cache
from ..errors import ClfzaError
from ._base import ProxState

# The choices before tuning existed (kept as the fallback and the "before" of the benchmark);
# the one-pass FGP must beat the three kernels by MARGIN to replace them (why "split" is the
# default: docs/measurements.md, clfza.backends._tuning).
DEFAULTS = {"prox": "fused", "strip": 32, "rows": 2, "local2d": "row", "local1d": "auto",
            "fgp": "split", "fgp_strip": 32, "prox_prefetch": "off", "fgp_prefetch": "off"}
PARAMS = tuple(DEFAULTS)
# Software prefetch in the one-pass kernels (tv_fused.cl's prefetch_row): off, rows loaded N
# ahead (rN) or loaded and stored rows N ahead (rwN); with prefetch, longer strips pay off
# (fewer of the 7 warm-up rows). The best form differs per implementation and run, so it is
# raced, between two races of the strip height (measured: docs/measurements.md,
# clfza.backends._tuning).
PREFETCH = ("off", "r4", "rw2", "rw4", "rw8")
PREFETCH_HELP = "off, rN or rwN (N rows ahead, 1-63)"
CANDIDATES = {
    "prox": ("fused", "split"),
    "strip": (8, 16, 32, 64),
    "rows": (1, 2, 4),
    "local2d": ("row", "64x1", "auto"),
    "local1d": ("auto", 256, 1024),
    "fgp": ("fused", "split"),
    "fgp_strip": (16, 32, 64, 128),
    "prox_prefetch": PREFETCH,
    "fgp_prefetch": PREFETCH,
}
GPU_LOCAL2D = ("auto", "64x1", "32x4", "16x16")
GPU_LOCAL1D = ("auto", 64, 256)
# size classes: images up to SMALL_MAX pixels use the choices measured at 512^2, larger ones
# those measured at 2048^2
SMALL_MAX = 1024 * 1024
CLASS_SIZE = {"small": 512, "large": 2048}
MARGIN = 0.05  # a candidate replaces the default only when this much faster (noise)
CACHE_FLUSH_ARRAYS = 6  # large class: arrays streamed through the caches before each call
VERSION = 6  # of the measurement procedure: part of the cache key (a new one measures again)
_LOCK = threading.RLock()
_KERNEL_FILES = ("common", "reduce", "elementwise", "tv", "tv_fused")


def size_class(ny: int, nx: int) -> str:
    return "small" if ny * nx <= SMALL_MAX else "large"


def _kernel_hash() -> str:

    h = hashlib.sha1()
    for name in _KERNEL_FILES:
        h.update(kernel_source(name).encode())
    return h.hexdigest()[:10]


def tuning_key(rt) -> str:
    """Implementation, its version, device, driver version, the kernels' hash and the
    measurement procedure's version."""

    return (device_key(rt.device.platform, rt.device) + f" | kernels {_kernel_hash()}"
            f" | tuning {VERSION}")


CACHE_FILE = "tuning.json"


def cache_path() -> str:
    """Where the tuning cache lives (in :func:`clfza.cl.cache_dir`)."""
    return os.path.join(cache_dir(), CACHE_FILE)


def load_cache() -> dict:
    """Every cached tuning entry, by device key and size class (``{}`` when none)."""
    return read_cache(CACHE_FILE)


def _save(key: str, cls: str, entry: dict) -> None:
    """Merge one entry into the cache file (re-read first: other processes write it too)."""

    data = load_cache()
    data.setdefault(key, {})[cls] = entry
    write_cache(CACHE_FILE, data)  # a read-only home: nothing cached, measured again next time


def _value(v: str):
    v = v.strip()
    return int(v) if v.isdigit() else v


def overrides() -> tuple[dict, str]:
    """``CLFZA_TUNE`` as (pinned choices, mode): mode ``defaults``, ``cached`` or ``tune``."""
    spec = os.environ.get("CLFZA_TUNE", "").strip()
    if not spec:
        return {}, "tune"
    if spec.lower() in ("defaults", "default", "off", "0", "none"):
        return {}, "defaults"
    if spec.lower() == "cached":
        return {}, "cached"
    pins = {}
    for part in spec.split(","):
        if not part.strip():
            continue
        k, sep, v = part.partition("=")
        k = k.strip()
        if not sep or k not in DEFAULTS:
            raise ClfzaError(f"CLFZA_TUNE: {part!r} is not key=value with a key among "
                             f"{', '.join(PARAMS)} (or 'defaults', 'cached')")
        pins[k] = _value(v)
        if not _valid(k, pins[k]):
            raise ClfzaError(f"CLFZA_TUNE: {part.strip()!r}: {k} takes "
                             + {"prox": "fused or split", "fgp": "fused or split",
                                "local2d": "row, auto or WxH",
                                "local1d": "auto or a size",
                                "prox_prefetch": PREFETCH_HELP, "fgp_prefetch": PREFETCH_HELP,
                                }.get(k, "a positive integer"))
    return pins, "tune"


def prefetch_args(v: str) -> tuple[int, int]:
    """A prefetch choice (``off``, ``rN``, ``rwN`` with 0 < N < 64) as the one-pass kernels'
    ``(pf, pfw)`` arguments: rows ahead (0 = none) and whether the stored rows are prefetched
    too. Raises ValueError for anything else."""
    v = str(v)
    if v == "off":
        return 0, 0
    w = v.startswith("rw")
    digits = v[2:] if w else v[1:]
    if v[:1] != "r" or not digits.isdigit() or not 0 < int(digits) < 64:
        raise ValueError(f"not a prefetch choice: {v!r}")
    return int(digits), int(w)


def _valid(k: str, v) -> bool:
    if k in ("prox", "fgp"):
        return v in ("fused", "split")
    if k in ("prox_prefetch", "fgp_prefetch"):
        try:
            prefetch_args(v)
        except ValueError:
            return False
        return True
    if k == "local2d":
        a, x, b = str(v).partition("x")
        return v in ("row", "auto") or (x == "x" and a.isdigit() and b.isdigit())
    if k == "local1d" and v == "auto":
        return True
    return isinstance(v, int) and v > 0


def _is_simulator(rt) -> bool:
    return "oclgrind" in rt.info.platform.lower()


def choices(rt, ny: int, nx: int, backend_cls) -> dict:
    """The kernel variants for images of ny x nx on ``rt``'s device: the environment's pins,
    then the cached measurement for the size class, measured now (with ``backend_cls``, the
    OpenCL backend class) if there is none."""
    pins, mode = overrides()
    if mode == "defaults" or (len(pins) == len(PARAMS)):
        return {**DEFAULTS, **pins}
    cls = size_class(ny, nx)
    with _LOCK:
        key = tuning_key(rt)
        entry = load_cache().get(key, {}).get(cls)
        if entry is None and mode == "tune" and not _is_simulator(rt):
            try:
                entry = measure(rt, cls, backend_cls)
            except ClfzaError:
                raise
            except Exception as exc:  # a failed measurement must not stop a solve
                entry = {"choices": dict(DEFAULTS), "error": f"{type(exc).__name__}: {exc}"}
            _save(key, cls, entry)
    got = dict(DEFAULTS)
    if entry is not None:
        got.update({k: v for k, v in entry.get("choices", {}).items() if k in DEFAULTS})
    got.update(pins)
    return got


# ----- measuring --------------------------------------------------------------------------
def _camera(n: int):

    p = 0.01
    return Camera(pitch=p, shape=(n, n), r1=np.sqrt(n) * p / (1 + 3.0 / 20.0), z1=20.0,
                  z2=3.0, R=None, mask="gzp")


def _time(fn, rt, reps: int, evict=None) -> float:
    """ms per call of ``fn``: ``reps`` calls back to back, or with ``evict`` (the large size
    class) each call timed alone after ``evict`` has streamed other arrays through the caches,
    as a solver's kernels run after its FFTs (a warm loop ranks the variants differently:
    docs/measurements.md, clfza.backends._tuning)."""
    if evict is None:
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        rt.finish()
        return (time.perf_counter() - t0) / reps * 1e3
    total = 0.0
    for _ in range(reps):
        evict()
        rt.finish()
        t0 = time.perf_counter()
        fn()
        rt.finish()
        total += time.perf_counter() - t0
    return total / reps * 1e3


def _race(B, param: str, cands, op, rounds: int, reps: int, seen: dict,
          evict=None) -> dict:
    """Interleaved rounds of ``op`` under each candidate of ``param``: the best round's ms per
    call (on a shared machine the best round is the one least disturbed, where medians move
    between runs: docs/measurements.md, clfza.backends._tuning). ``seen`` keeps every round per (op,
    configuration): a configuration raced again for another parameter (the strip race's
    winner is the prox race's fused candidate) keeps its earlier rounds too."""
    base = dict(B.tune)
    ms = {c: seen.setdefault((op, tuple(sorted({**base, param: c}.items(), key=str))), [])
          for c in cands}
    for c in cands:  # warm-up: builds programs, first-touch pages
        B.apply_tuning({**base, param: c})
        op()
        B.rt.finish()
    for _ in range(rounds):
        for c in cands:
            B.apply_tuning({**base, param: c})
            ms[c].append(_time(op, B.rt, reps, evict))
    B.apply_tuning(base)
    return {c: min(v) for c, v in ms.items()}


def _pick(med: dict, default):
    best = min(med, key=med.get)
    if default in med and med[best] > (1 - MARGIN) * med[default]:
        return default
    return best


def candidates(rt) -> dict:
    c = dict(CANDIDATES)
    if not rt.is_cpu:
        c.update(prox=("split",), strip=(DEFAULTS["strip"],), local2d=GPU_LOCAL2D,
                 local1d=GPU_LOCAL1D, fgp=("split",), fgp_strip=(DEFAULTS["fgp_strip"],),
                 prox_prefetch=("off",), fgp_prefetch=("off",))
    return c


def _evictor(B, n: int):
    """Large images: a call that streams CACHE_FLUSH_ARRAYS other arrays of the size through
    the caches (two triads), run before each timed call."""
    flush = [B.from_host(np.ones((1, n, n))) for _ in range(CACHE_FLUSH_ARRAYS)]

    def evict():
        for i in range(0, CACHE_FLUSH_ARRAYS, 3):
            B.triad(flush[i], flush[i + 1], flush[i + 2], 1.0)

    return evict


def measure(rt, cls: str, backend_cls, rounds: int | None = None) -> dict:
    """Time every variant on ``rt`` at the size class's reference size; returns the cache
    entry {"choices", "ms" (per parameter, per candidate: best ms per call), "size",
    "seconds", "when"}. One parameter at a time, in an order where each op depends only on
    parameters already chosen; a candidate replaces the default only when MARGIN faster.
    ``backend_cls``: :class:`clfza.backends.OpenCLBackend` (passed in: the backend imports
    this module)."""

    t0 = time.perf_counter()
    n = CLASS_SIZE[cls]
    rounds = rounds or (7 if cls == "small" else 5)
    reps = 4 if cls == "small" else 2
    pins, _ = overrides()
    B = backend_cls(_camera(n), 1, runtime=rt, tune={**DEFAULTS, "prox": "split",
                                                     "fgp": "split"})
    rng = np.random.default_rng(0)
    x, g, o, xm = (B.from_host(rng.random((1, n, n))) for _ in range(4))
    cand = candidates(rt)
    chosen = dict(B.tune)
    table: dict[str, dict] = {}
    seen: dict = {}

    evict = _evictor(B, n) if cls == "large" else None

    def run(param, op):
        cs = [pins[param]] if param in pins else list(cand[param])
        med = _race(B, param, cs, op, rounds, reps, seen, evict)
        table[param] = {str(k): v for k, v in med.items()}
        chosen[param] = _pick(med, DEFAULTS[param] if DEFAULTS[param] in med else cs[0])
        B.apply_tuning({**B.tune, param: chosen[param]})

    st = ProxState()  # cold (not warm) but keeps its dual buffers: no allocation per call

    def one_d():
        B.lincomb(o, 1.0, x, 0.5, g)
        B.prox_step("l1", x, g, 0.5, 0.01, o, 1, st)

    def split_prox():
        B.prox_step("tv", x, g, 0.5, 0.005, o, 2, st)
        B.reg_value(o)

    def prox():
        B.prox_step("tv", x, g, 0.5, 0.005, o, 2, st)

    B.use_kernels(("elementwise", ("twist_combine",)))  # TwIST's combination: rows raced

    def combine():  # the row-blocked kernel (GPUs, colour frames; twist_combine16 has no rows)
        B.launch_rows_reduce("twist_combine", o.buf, xm.buf, x.buf, g.buf, B.r(-0.9),
                             B.r(0.8), B.r(1.1), B.i32(0), B.i32(1), B.fpar.buf, planes=3)

    run("local1d", one_d)
    run("local2d", split_prox)
    run("rows", combine)
    fst = ProxState(warm=True)

    def fgp():
        B.fgp_prox("tv", o, x, 0.05, 2, fst, True)

    if rt.is_cpu:
        B.apply_tuning({**B.tune, "prox": "fused", "fgp": "fused"})
        # strip heights and prefetch depend on each other (a deeper prefetch favours longer
        # strips): strip, prefetch at that strip, strip again with that prefetch
        for strip_param, pf_param, op in (("strip", "prox_prefetch", prox),
                                          ("fgp_strip", "fgp_prefetch", fgp)):
            run(strip_param, op)
            run(pf_param, op)
            run(strip_param, op)
        run("prox", prox)
        run("fgp", fgp)
    else:
        chosen.update(prox="split", fgp="split", prox_prefetch="off", fgp_prefetch="off")
    chosen.update(pins)
    return {"choices": chosen, "ms": table, "size": n, "rounds": rounds, "reps": reps,
            "seconds": round(time.perf_counter() - t0, 2),
            "load": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
            "when": time.strftime("%Y-%m-%dT%H:%M:%S")}


def retune(rt, backend_cls, classes=("small", "large")) -> dict:
    """Measure again (``clfza tune``), replacing the cached entries; returns {class: entry}."""
    out = {}
    with _LOCK:
        key = tuning_key(rt)
        for cls in classes:
            out[cls] = measure(rt, cls, backend_cls)
            _save(key, cls, out[cls])
    return out


def table_lines(entry: dict) -> list[str]:
    """A printable table of one measurement: parameter, candidates' ms, choice."""
    lines = [f"  at {entry.get('size')}^2 (ms per call, best of {entry.get('rounds')} "
             "interleaved rounds; * chosen)"]
    for param, med in entry.get("ms", {}).items():
        ch = str(entry["choices"].get(param))
        cells = "  ".join(f"{k}{'*' if k == ch else ''}={v:.3f}" for k, v in med.items())
        lines.append(f"    {param:8s} {cells}")
    return lines


def report(rt) -> list[str]:
    """``clfza info``'s lines for one runtime: the cached choices per size class."""
    entries = load_cache().get(tuning_key(rt), {})
    pins, mode = overrides()
    lines = []
    for cls in ("small", "large"):
        e = entries.get(cls)
        if e is None:
            lines.append(f"      tuning ({cls}): not measured yet (at first use, or `clfza tune`)")
        else:
            ch = ", ".join(f"{k}={v}" for k, v in e["choices"].items())
            lines.append(f"      tuning ({cls}, measured at {e.get('size')}^2): {ch}")
    if mode != "tune" or pins:
        lines.append(f"      CLFZA_TUNE={os.environ.get('CLFZA_TUNE')} overrides these")
    return lines
