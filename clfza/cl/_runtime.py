"""Choose an OpenCL device, build programs once per context, and guard device memory.

Device choice, in order: an explicit ``device`` argument (``"gpu"``, ``"cpu"``, ``"P:D"``
platform/device indices, or a substring of the device name, platform name or platform version,
e.g. ``"PoCL 3.0"``, ``"Intel"``), then the ``PYOPENCL_CTX``
environment variable (same syntax as pyopencl's), then the first GPU of any vendor, then the
fastest CPU device by a short measurement cached on disk (:func:`device_scores`; a single
CPU device is taken without measuring). The measurement runs a solve, so it is injected from
the layer above (:func:`set_device_measurer`, :mod:`clfza.reconstruction._device_choice`): this
module imports nothing of clfza's but its errors.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import json
import logging
import os
import re
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from importlib import resources

import numpy as np

from ..errors import DeviceError
from ._kernels import typed_kernel

INSTALL_HINT = (
    "No OpenCL platform was found. Install an OpenCL runtime: on a CPU-only machine "
    "`pip install pocl-binary-distribution` (or `pip install \"pyopencl[pocl]\"`); on a GPU "
    "machine install the vendor's OpenCL driver (NVIDIA: libnvidia-compute with an ICD file in "
    "/etc/OpenCL/vendors, or set OCL_ICD_VENDORS)."
)


def _cl():
    _use_venv_vendors()
    try:
        import pyopencl as cl  # lazy: pyopencl loads only when an OpenCL device is used
    except ImportError as exc:  # pragma: no cover - pyopencl is a hard dependency
        raise DeviceError(f"pyopencl is not importable ({exc}); {INSTALL_HINT}") from None
    return cl


def venv_vendors_dir() -> str:
    """``<sys.prefix>/etc/OpenCL/vendors``: the ICD folder ``python -m clfza.cl.intel_icd``
    writes (Intel's CPU runtime from PyPI next to the system's ICDs)."""

    return os.path.join(sys.prefix, "etc", "OpenCL", "vendors")


SYSTEM_VENDORS = "/etc/OpenCL/vendors"


def _use_venv_vendors() -> None:
    """Point the ICD loader at the environment's vendors folder when one was written and the
    user set none: clfza then sees Intel's CPU runtime installed by pip without any shell
    setup. The folder links the system's ICDs too (the loader reads one folder); one added
    to the system since (a GPU driver) is linked here as well, so it is never hidden. Must
    run before the loader's first platform query (it reads the variable then)."""
    if "OCL_ICD_VENDORS" in os.environ:
        return
    d = venv_vendors_dir()
    if not (os.path.isdir(d) and any(f.endswith(".icd") for f in os.listdir(d))):
        return
    try:
        for f in os.listdir(SYSTEM_VENDORS):
            if f.endswith(".icd") and not os.path.lexists(os.path.join(d, f)):
                os.symlink(os.path.join(SYSTEM_VENDORS, f), os.path.join(d, f))
    except OSError:  # no system folder, or a read-only environment: use what is there
        pass
    os.environ["OCL_ICD_VENDORS"] = d


log = logging.getLogger(__name__)

#: a line of a build log that is a compiler warning: clang's "FILE:L:C: warning: ...", Intel's
#: "warning: kernel ...", clang's "N warnings generated."
_WARNING_LINE = re.compile(r"(^|[\s:])warning:|\bwarnings? generated\b", re.IGNORECASE)


def warning_lines(text: str) -> list[str]:
    """The lines of a build log (or of what a compiler printed) that are warnings.

    Intel's CPU runtime writes a log on every build ("Compilation started ... Device build
    done", vectoriser remarks): those lines are not warnings; clang's diagnostics
    (``FILE:LINE:COL: warning: ...``, ``N warnings generated.``) and Intel's
    ``warning: kernel "K": ...`` are.

    Examples
    --------
    >>> from clfza.cl import warning_lines
    >>> warning_lines("Compilation started\\nx.cl:3:9: warning: unused variable 'a'\\n"
    ...               "1 warning generated.")
    ["x.cl:3:9: warning: unused variable 'a'", '1 warning generated.']
    """
    return [ln.strip() for ln in text.splitlines() if _WARNING_LINE.search(ln)]


_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def _captured_stderr() -> Iterator[list[str]]:
    """File descriptor 2 into a temporary file while the block runs; the text, once it has
    run, in the yielded list.

    PoCL's compiler prints its diagnostics' summary ("59 warnings generated.") on the
    process's stderr itself, not through Python, so ``warnings`` filters cannot hold it back.
    Output of other threads during a build is captured too and logged with the build's (at
    INFO level): a build is short, and clfza's command line prints nothing from other threads
    meanwhile. Where fd 2 cannot be duplicated (closed), nothing is captured.
    """
    out: list[str] = []
    with _STDERR_LOCK:
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError, AttributeError):
            yield out
            return
        try:
            with tempfile.TemporaryFile(mode="w+b") as tmp:
                os.dup2(tmp.fileno(), 2)
                try:
                    yield out
                finally:
                    os.dup2(saved, 2)
                    tmp.seek(0)
                    out.append(tmp.read().decode("utf-8", "replace"))
        finally:
            os.close(saved)


def build_source(cl, context, src: str, options=()):
    """``cl.Program(context, src).build(options)`` with the compiler kept off stderr.

    Every program clfza builds goes through here. Some implementations return a build log on
    every success (Intel's CPU runtime: "Compilation started ... Device build done"), which
    pyopencl turns into a CompilerWarning on stderr, and PoCL's compiler prints its own
    diagnostics' summary on the process's stderr: noise in the CLI's one-line errors and in
    every user's console. Both are held back: the program's build log is on
    :attr:`Runtime.build_logs`, and what the compiler printed is logged on the
    ``clfza.cl._runtime`` logger (its warnings at INFO, shown by ``clfza --verbose``; the rest
    at DEBUG). Failures still raise, with the log (callers wrap them in DeviceError).
    ``PYOPENCL_COMPILER_OUTPUT=1`` still shows pyopencl's warnings.
    """
    prg, printed = _build(cl, context, src, options)
    _log_compiler_output("the OpenCL compiler printed", printed)
    return prg


def _build(cl, context, src: str, options=()):
    """:func:`build_source`'s build: the program and what the compiler printed on stderr."""
    with warnings.catch_warnings(), _captured_stderr() as printed:
        if not os.environ.get("PYOPENCL_COMPILER_OUTPUT"):
            warnings.simplefilter("ignore", cl.CompilerWarning)
        prg = cl.Program(context, src).build(options=list(options))
    return prg, "".join(printed).strip()


def _log_compiler_output(what: str, text: str) -> None:
    text = text.strip()
    if not text:
        return
    warned = warning_lines(text)
    if warned:
        log.info("%s %d warning line(s): %s", what, len(warned), " | ".join(warned[:20]))
    log.debug("%s:\n%s", what, text)


def build_log(cl, prg, device) -> str:
    """The build log of ``prg`` on ``device`` (empty where the runtime gives none)."""
    try:
        return str(prg.get_build_info(device, cl.program_build_info.LOG) or "").strip()
    except Exception:  # a runtime without a log for cached binaries: nothing to read
        return ""


# ----- status lines of slow first runs ----------------------------------------------------
_STATUS: Callable[[str], contextlib.AbstractContextManager] | None = None


def set_status_writer(writer: Callable[[str], contextlib.AbstractContextManager] | None
                      ) -> None:
    """Register how :func:`status` shows a slow step (None: on the ``clfza.status`` logger).

    Parameters
    ----------
    writer : callable ``(text) -> context manager``, or None
        Called with the step's description ("compiling OpenCL kernels for ..."); its context
        manager spans the step. The command line registers one that prints one line on stderr
        where the step takes over a second, with its time when done (a spinner on a
        terminal); ``--quiet`` registers none.
    """
    global _STATUS
    _STATUS = writer


_STATUS_LOG = logging.getLogger("clfza.status")
STATUS_DELAY = 1.0  # seconds before a status line shows (quicker steps show nothing)
_SPIN = "|/-\\"


@contextlib.contextmanager
def stderr_status(text: str, stream=None, delay: float = STATUS_DELAY) -> Iterator[None]:
    """One status line on stderr for a slow step, ending with the step's time when done.

    The line reads ``clfza: TEXT ... done in 12.3 s``.

    Nothing shows where the step takes less than ``delay`` seconds. After ``delay``, the line
    is written up to ``...``; on a terminal a spinner and the seconds so far follow it, and the
    line ends with the step's time when it is done. It is written between builds, never while
    a program's build (``build_source``) holds the process's stderr. The command line
    registers it (:func:`set_status_writer`) unless ``--quiet``.
    """
    out = sys.stderr if stream is None else stream
    tty = bool(getattr(out, "isatty", lambda: False)())
    head = f"clfza: {text} ..."
    t0 = time.perf_counter()
    stop, shown = threading.Event(), threading.Event()

    def write(s: str) -> None:
        with _STDERR_LOCK:
            out.write(s)
            out.flush()

    def run() -> None:
        if stop.wait(delay):
            return
        write(head)
        shown.set()
        k = 0
        while tty and not stop.wait(0.25):
            write(f"\r{head} {_SPIN[k % 4]} {time.perf_counter() - t0:.0f} s\033[K")
            k += 1

    th = threading.Thread(target=run, name="clfza-status", daemon=True)
    th.start()
    try:
        yield
    finally:
        stop.set()
        th.join()
        if shown.is_set():
            done = f"done in {time.perf_counter() - t0:.1f} s\n"
            write(f"\r{head} {done}\033[K" if tty else f" {done}")


@contextlib.contextmanager
def status(text: str) -> Iterator[None]:
    """Show ``text`` for a slow step (a first compile, the device measurement) while the block
    runs, through the writer of :func:`set_status_writer`; without one, two INFO records on
    the ``clfza.status`` logger (the step, then its time)."""
    writer = _STATUS
    if writer is not None:
        with writer(text):
            yield
        return
    t0 = time.perf_counter()
    _STATUS_LOG.info("%s ...", text)
    yield
    _STATUS_LOG.info("%s: done in %.1f s", text, time.perf_counter() - t0)


def _platforms():
    cl = _cl()
    try:
        plats = cl.get_platforms()
    except (cl.LogicError, cl.RuntimeError, RuntimeError):
        plats = []
    if not plats:
        raise DeviceError(INSTALL_HINT)
    return plats


@dataclass(frozen=True)
class DeviceInfo:
    """What clfza reports about an OpenCL device."""

    index: str
    platform: str
    name: str
    kind: str
    global_mem_mb: int
    max_alloc_mb: int
    fp64: bool
    compute_units: int
    driver: str = ""  # the implementation's version (PoCL: "3.0-rc2", "3.1+debian")

    def describe(self) -> str:
        plat = f"{self.platform} {self.driver}" if self.driver else self.platform
        return (f"[{self.index}] {self.name} ({self.kind}, {plat}; "
                f"{self.global_mem_mb} MiB, max alloc {self.max_alloc_mb} MiB, "
                f"{self.compute_units} CUs, fp64 {'yes' if self.fp64 else 'no'})")


def _device_kind(dev) -> str:
    cl = _cl()
    if dev.type & cl.device_type.GPU:
        return "GPU"
    if dev.type & cl.device_type.CPU:
        return "CPU"
    if dev.type & cl.device_type.ACCELERATOR:
        return "accelerator"
    return "other"


def _info(pi: int, di: int, plat, dev) -> DeviceInfo:
    return DeviceInfo(
        index=f"{pi}:{di}",
        platform=plat.name.strip(),
        name=dev.name.strip(),
        kind=_device_kind(dev),
        global_mem_mb=int(dev.global_mem_size >> 20),
        max_alloc_mb=int(dev.max_mem_alloc_size >> 20),
        fp64=bool(getattr(dev, "double_fp_config", 0)),
        compute_units=int(dev.max_compute_units),
        driver=str(dev.driver_version).strip(),
    )


def _all_devices():
    out = []
    for pi, plat in enumerate(_platforms()):
        try:
            devs = plat.get_devices()
        except Exception:  # a broken ICD should not hide the others
            continue
        for di, dev in enumerate(devs):
            out.append((pi, di, plat, dev))
    return out


def list_devices() -> list[DeviceInfo]:
    """Every OpenCL device on every platform, with the facts clfza cares about."""
    return [_info(pi, di, p, d) for pi, di, p, d in _all_devices()]


def device_problems() -> dict[str, str | None]:
    """For each device index ``"P:D"``: None if it compiles kernels, else why not."""
    return {f"{pi}:{di}": probe_device(pi, di, d) for pi, di, _, d in _all_devices()}


_PROBE_SRC = "__kernel void probe(__global float *a) { a[get_global_id(0)] += 1.0f; }"
_PROBED: dict[tuple[int, int], str | None] = {}


def probe_device(pi: int, di: int, dev) -> str | None:
    """Build a one-line kernel on ``dev``; None if it works, else the reason (cached).

    Some runtimes list a device they cannot compile for (pip's PoCL 3.0 is built on LLVM 14,
    which does not know AMD Zen 5 and fails with "unknown target CPU 'generic'").
    """
    key = (pi, di)
    if key not in _PROBED:
        cl = _cl()
        try:
            ctx = cl.Context([dev])
            build_source(cl, ctx, _PROBE_SRC)
            _PROBED[key] = None
        except Exception as exc:  # any failure disqualifies the device
            msg = str(exc).strip().splitlines()
            _PROBED[key] = next((m for m in msg if "error" in m.lower()), msg[-1] if msg else
                                type(exc).__name__)
    return _PROBED[key]


def _pick(spec: str | None):
    devices = _all_devices()
    if not devices:
        raise DeviceError(INSTALL_HINT)
    if spec is None:
        spec = os.environ.get("PYOPENCL_CTX") or None
    if spec is None or spec.lower() in ("", "auto", "default"):
        order = sorted(devices, key=lambda d: _device_kind(d[3]) != "GPU")
        usable = [d for d in order if probe_device(d[0], d[1], d[3]) is None]
        if usable:
            return _fastest(usable)
        reasons = [f"{d[3].name.strip()} ({d[2].name.strip()}): "
                   f"{probe_device(d[0], d[1], d[3])}" for d in order]
        raise DeviceError("no OpenCL device can compile kernels: " + "; ".join(reasons)
                          + ". On a new CPU that pip's PoCL 3.0 does not know, install the "
                          "distribution's PoCL (Debian/Ubuntu: apt-get install pocl-opencl-icd)")
    s = spec.strip()
    if s.lower() in ("gpu", "cpu", "accelerator"):
        hits = [d for d in devices if _device_kind(d[3]).lower() == s.lower()]
    elif all(p.isdigit() for p in s.split(":") if p) and s.split(":")[0]:
        parts = s.split(":")
        pi = int(parts[0])
        di = int(parts[1]) if len(parts) > 1 and parts[1] else 0
        hits = [d for d in devices if d[0] == pi and d[1] == di]
    else:
        # part of the platform's name or version string ("PoCL 3.0" for pip's PoCL, "PoCL
        # 3.1" for Debian's, "Intel" for Intel's runtime), else of the device name (which
        # names the CPU: "Intel" is in every device's name on an Intel CPU)
        hits = [d for d in devices if s.lower() in d[2].name.lower()
                or s.lower() in d[2].version.lower()]
        hits = hits or [d for d in devices if s.lower() in d[3].name.lower()]
    if not hits:
        raise DeviceError(f"no OpenCL device matches {spec!r}; available: "
                          + "; ".join(i.describe() for i in list_devices()))
    for d in hits:
        if probe_device(d[0], d[1], d[3]) is None:
            return d
    d = hits[0]
    raise DeviceError(f"OpenCL device {d[3].name.strip()!r} matches {spec!r} but cannot compile "
                      f"kernels: {probe_device(d[0], d[1], d[3])}")


# ----- the default device by measurement ---------------------------------------------------
# Several CPU implementations of OpenCL on one machine (pip's PoCL, the distribution's PoCL,
# Intel's runtime) differ on clfza's kernels, and which is fastest depends on the CPU and the
# versions (measured: docs/measurements.md, clfza.cl._runtime). The default device is the
# fastest by a short measurement (paper-mode TwIST iterations at MEASURE_SIZE^2, float32,
# kernels compiled beforehand), taken once per device and driver version and cached on disk
# (CLFZA_CACHE_DIR, else $XDG_CACHE_HOME/clfza, else ~/.cache/clfza). A usable GPU still wins
# without measuring; an explicit device or PYOPENCL_CTX overrides; CLFZA_DEVICE_CHOICE=first
# restores "first GPU, else first CPU".
# The measurement runs a solve, which lives above this module: it is injected
# (set_device_measurer) by clfza.reconstruction._device_choice, which
# clfza.reconstruction._reconstruct and the command line install.
MEASURE_SIZE = 512
MEASURE_ITERS = 4
MEASURE_ROUNDS = 2  # interleaved over the devices, best kept: a shared machine's load then
# falls on every device alike (measured one device after the other, a load burst hid the
# fastest: docs/measurements.md, clfza.cl._runtime)
_MEASURING = threading.local()
_SCORE_LOCK = threading.Lock()


def cache_dir() -> str:
    """The folder of clfza's measurement caches: ``CLFZA_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/clfza``, else ``~/.cache/clfza`` (it may not exist yet)."""
    d = os.environ.get("CLFZA_CACHE_DIR")
    if not d:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"),
                                                                  ".cache")
        d = os.path.join(base, "clfza")
    return d


def read_cache(name: str) -> dict:
    """The JSON object cached in the file ``name`` of :func:`cache_dir`.

    Parameters
    ----------
    name : str
        The file's name, e.g. ``"device_scores.json"``.

    Returns
    -------
    dict
        Its content; ``{}`` when the file is missing, unreadable or not a JSON object (a cache
        is measured again, never trusted blindly).

    Examples
    --------
    >>> from clfza.cl import read_cache, write_cache
    >>> write_cache("example.json", {"a": 1})
    >>> read_cache("example.json")
    {'a': 1}
    """
    try:
        with open(os.path.join(cache_dir(), name), encoding="utf-8") as f:
            data = json.load(f)
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def write_cache(name: str, data: dict) -> None:
    """Write ``data`` as JSON to the file ``name`` of :func:`cache_dir`, atomically.

    The file is written beside its place and renamed over it, so that processes that measure
    at the same time never read half a file; where the folder cannot be written (a read-only
    home) nothing is cached and the measurement runs again next time.

    Parameters
    ----------
    name : str
        The file's name, e.g. ``"tuning.json"``.
    data : dict
        JSON-serialisable content (written with sorted keys).

    Examples
    --------
    >>> from clfza.cl import read_cache, write_cache
    >>> write_cache("example.json", {"a": 1})
    >>> read_cache("example.json")["a"]
    1
    """
    try:
        os.makedirs(cache_dir(), exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=cache_dir(), prefix=f".{os.path.splitext(name)[0]}-")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=1, sort_keys=True)
        os.replace(tmp, os.path.join(cache_dir(), name))
    except OSError:  # a read-only home: measure again next time
        pass


SCORES_FILE = "device_scores.json"


def _scores_path() -> str:
    return os.path.join(cache_dir(), SCORES_FILE)


def device_key(plat, dev) -> str:
    """What a measurement is valid for: implementation, its version, device, driver."""
    return " | ".join(str(x).strip() for x in (plat.name, plat.version, dev.name,
                                                dev.driver_version))


_MEASURER: Callable[[str, int, int], float] | None = None


def set_device_measurer(measure: Callable[[str, int, int], float] | None) -> None:
    """Register the measurement that ranks CPU devices (None: none).

    Parameters
    ----------
    measure : callable ``(index, n, iters) -> float``, or None
        Milliseconds per solver iteration at ``n^2`` on device ``index`` ("P:D"). It runs a
        solve, which lives above this layer, so it is injected from there:
        :func:`clfza.reconstruction._device_choice.install` registers it
        (``clfza.reconstruction._reconstruct`` and the command line do so when they load). This
        module never imports the layers above it.
    """
    global _MEASURER
    _MEASURER = measure


def measure_device(index: str, n: int = MEASURE_SIZE, iters: int = MEASURE_ITERS
                   ) -> float | None:
    """Milliseconds per paper-mode TwIST iteration at n^2 (float32) on device ``index``
    ("P:D"), by the registered measurement (:func:`set_device_measurer`,
    :func:`clfza.reconstruction._device_choice.measure_device`); None when none is registered: the
    device is then not measured, nothing is cached, and the default is the first usable device
    unless scores are cached."""
    measure = _MEASURER
    return None if measure is None else measure(index, n, iters)


def device_scores(devices=None, measure: bool = True) -> dict[str, dict]:
    """Per usable CPU device index: {"key", "ms" (None: not measured), "cached"}.

    Measures the devices that have no cached score for their key when ``measure`` (and a
    measurement is registered, :func:`set_device_measurer`)."""
    devices = _all_devices() if devices is None else devices
    out: dict[str, dict] = {}
    with _SCORE_LOCK:
        scores = read_cache(SCORES_FILE)
        todo: dict[str, str] = {}
        for pi, di, plat, dev in devices:
            if _device_kind(dev) != "CPU" or probe_device(pi, di, dev) is not None:
                continue
            key = device_key(plat, dev)
            ms = scores.get(key)
            out[f"{pi}:{di}"] = {"key": key, "ms": ms, "cached": ms is not None}
            if ms is None and measure:
                todo[f"{pi}:{di}"] = key
        if todo and _MEASURER is not None:
            with status(f"measuring {len(todo)} CPU OpenCL device{'s' * (len(todo) > 1)} "
                        "to choose the default (first run on this machine; cached "
                        "afterwards)"):
                best = _measure_interleaved(list(todo))
        else:
            best = _measure_interleaved(list(todo))
        changed = False
        for index, ms in best.items():
            out[index]["ms"] = ms
            if ms is not None:  # None: no measurement registered, nothing to cache
                scores[todo[index]] = ms if np.isfinite(ms) else 1e30
                changed = True
        if changed:
            write_cache(SCORES_FILE, scores)
    return out


def _measure_interleaved(indices: list[str]) -> dict[str, float | None]:
    """Best of :data:`MEASURE_ROUNDS` rounds of :func:`measure_device` over ``indices``, the
    devices taken in turn within each round. A device that fails is never preferred (inf)."""
    best: dict[str, float | None] = {i: None for i in indices}
    for _ in range(MEASURE_ROUNDS if indices else 0):
        for index in indices:
            if best[index] == float("inf"):
                continue
            _MEASURING.on = True
            try:
                ms = measure_device(index)
            except Exception:
                ms = float("inf")
            finally:
                _MEASURING.on = False
            if ms is None:
                return best  # no measurement registered
            best[index] = ms if best[index] is None else min(best[index], ms)
    return best


def _fastest(usable):
    """The default among usable devices (GPUs first in ``usable``)."""
    first = usable[0]
    if (_device_kind(first[3]) == "GPU" or len(usable) == 1
            or getattr(_MEASURING, "on", False)
            or os.environ.get("CLFZA_DEVICE_CHOICE", "").lower() == "first"):
        return first
    cpus = [d for d in usable if _device_kind(d[3]) == "CPU"]
    if len(cpus) < 2:
        return first
    sc = device_scores(cpus)
    best = min(cpus, key=lambda d: (sc.get(f"{d[0]}:{d[1]}", {}).get("ms") or float("inf")))
    return best


def choice_report() -> list[str]:
    """Lines for ``clfza info``: the measured CPU devices, fastest first, and how to get the
    implementations that are missing here."""
    sc = device_scores()
    lines = []
    if sc:
        lines.append(f"CPU devices by measurement (paper-mode TwIST at {MEASURE_SIZE}^2, float32, "
                     f"ms/iteration; cached in {_scores_path()}):")
        ranked = sorted(sc.items(), key=lambda kv: kv[1]["ms"] or float("inf"))
        for i, (idx, v) in enumerate(ranked):
            ms = v["ms"]
            val = ("not measured" if ms is None else f"{ms:7.2f} ms" if ms < 1e29
                   else "  failed")
            lines.append(f"  [{idx}] {val}  {v['key'].split(' | ')[0]} "
                         f"{v['key'].split(' | ')[-1]}" + ("   <- fastest" if i == 0 else ""))
    plats = " ".join(f"{d.platform} {d.driver}" for d in list_devices())
    hints = []
    if "Intel(R) OpenCL" not in plats:
        hints.append("Intel's CPU runtime: pip install \"clfza[intel]\" && "
                     "python -m clfza.cl.intel_icd")
    try:  # pip's PoCL (pocl-binary-distribution X.Y reports driver "X.Y..."), if installed
        pip_pocl = importlib.metadata.version("pocl-binary-distribution")
    except importlib.metadata.PackageNotFoundError:
        pip_pocl = None
    pocl = [d.driver for d in list_devices() if d.platform == "Portable Computing Language"]
    if not any(pip_pocl is None or not v.startswith(pip_pocl) for v in pocl):
        hints.append("the distribution's PoCL: apt-get install pocl-opencl-icd")
    if hints:
        lines.append("not installed here (often faster on CPUs): " + "; ".join(hints))
    return lines


def kernel_source(name: str) -> str:
    """Text of ``kernels/<name>.cl`` shipped as package data (``clfza.kernels``).

    ``CLFZA_KERNEL_DIR`` (read on each call) names a folder whose ``<name>.cl`` files are
    used instead, where present: benchmarks compare kernel variants in one process with it
    (a new :class:`Runtime` per variant, since programs are cached per context).
    """
    alt = os.environ.get("CLFZA_KERNEL_DIR")
    if alt and os.path.isfile(os.path.join(alt, f"{name}.cl")):
        with open(os.path.join(alt, f"{name}.cl"), encoding="utf-8") as f:
            return f.read()
    try:  # no clfza.kernels package when clfza runs from a checkout on CLFZA_KERNEL_DIR alone
        return resources.files("clfza.kernels").joinpath(f"{name}.cl").read_text("utf-8")
    except (FileNotFoundError, ModuleNotFoundError):
        where = f" or from CLFZA_KERNEL_DIR={alt}" if alt else ""
        raise DeviceError(f"OpenCL source {name}.cl is missing from the clfza installation"
                          f"{where}; reinstall clfza") from None


COMPILED_FILE = "compiled.json"


def kernels_hash() -> str:
    """A digest of clfza's version and every ``kernels/*.cl`` it would build (those of
    ``CLFZA_KERNEL_DIR`` where set): what a warm device cache (:meth:`Runtime.first_run`) is
    valid for."""
    h = hashlib.sha1(importlib.metadata.version("clfza").encode() if _installed() else b"")
    try:
        names = sorted(f.name[:-3] for f in resources.files("clfza.kernels").iterdir()
                       if f.name.endswith(".cl"))
    except (FileNotFoundError, ModuleNotFoundError):
        names = []
    for n in names:
        h.update(n.encode())
        h.update(kernel_source(n).encode())
    return h.hexdigest()[:16]


def _installed() -> bool:
    try:
        importlib.metadata.version("clfza")
        return True
    except importlib.metadata.PackageNotFoundError:
        return False


class Runtime:
    """One OpenCL context and in-order queue on one device, with a program cache.

    Use :func:`get_runtime` rather than constructing this directly, so that programs are built
    once per device.
    """

    def __init__(self, device: str | None = None):
        cl = _cl()
        pi, di, plat, dev = _pick(device)
        self.cl = cl
        self.device = dev
        self.info = _info(pi, di, plat, dev)
        self.context = cl.Context([dev])
        self.queue = cl.CommandQueue(self.context)
        self.is_cpu = self.info.kind == "CPU"
        self.has_fp64 = self.info.fp64
        # On CPU devices host memory *is* device memory: wrap numpy arrays (zero-copy).
        self.zero_copy = self.is_cpu
        self._programs: dict[tuple, object] = {}
        self._kernels: dict[tuple[int, str], object] = {}
        self.compile_seconds = 0.0  # time spent building programs on this runtime
        self.key = device_key(plat, dev)
        #: per program built on this runtime (``"name [options]"``): its build log, then what
        #: the compiler printed on stderr (:func:`build_source`); read by
        #: :meth:`compiler_warnings` and ``tests/test_build_logs.py``
        self.build_logs: dict[str, str] = {}
        self._graveyard: list = []
        self._lock = threading.Lock()

    # ----- programs -----------------------------------------------------------------
    def check_dtype(self, dtype) -> np.dtype:
        """``dtype`` if this device computes in it; DeviceError for float64 without fp64."""
        dtype = np.dtype(dtype)
        if dtype == np.float64 and not self.has_fp64:
            raise DeviceError(f"device {self.info.name!r} has no float64 support; use "
                              "dtype=float32 or the numpy backend")
        return dtype

    def program(self, name: str, dtype=np.float32, defines: dict | None = None, *,
                include: tuple[str, ...] = ("common",), flags: tuple[str, ...] = (),
                source: str | None = None):
        """Build ``include`` + ``kernels/<name>.cl`` (or the generated ``source``, cached under
        ``name``) for ``dtype`` (real type ``real``/``real2``), once per runtime.

        Every program of clfza is built here, so the rules are in one place: compiler flags
        (``-cl-mad-enable`` for float32, then ``flags``), defines (``REAL_IS_DOUBLE`` for
        float64, ``CLFZA_POCL`` on PoCL, ``CLFZA_CPU`` on CPU devices, ``CLFZA_INTEL_CPU`` on
        Intel's CPU runtime, then ``defines``), the fp64 check, the build time
        (:attr:`compile_seconds`), the build logs (:attr:`build_logs`) and one cache
        (:meth:`clear_programs`). Raises DeviceError with the compiler's build log when the
        build fails.
        """
        dtype = self.check_dtype(dtype)
        opts = (["-cl-mad-enable"] if dtype == np.float32 else []) + list(flags)
        defs = {"REAL_IS_DOUBLE": 1} if dtype == np.float64 else {}
        if "portable computing language" in self.info.platform.lower():
            defs["CLFZA_POCL"] = 1
        if self.is_cpu:
            defs["CLFZA_CPU"] = 1
            if self.info.platform.startswith("Intel"):
                defs["CLFZA_INTEL_CPU"] = 1
        defs.update(defines or {})
        opts += [f"-D{k}={v}" for k, v in sorted(defs.items())]
        key = (name, tuple(include), " ".join(opts))
        with self._lock:
            prg = self._programs.get(key)
            if prg is None:
                t0 = time.perf_counter()
                body = kernel_source(name) if source is None else source
                src = "\n".join([kernel_source(p) for p in include] + [body])
                what = f"{name}.cl" if source is None else name
                try:
                    prg, printed = _build(self.cl, self.context, src, opts)
                except self.cl.RuntimeError as exc:
                    raise DeviceError(
                        f"OpenCL build of {what} failed on {self.info.name}:\n{exc}"
                    ) from None
                text = "\n".join(t for t in (build_log(self.cl, prg, self.device), printed)
                                 if t)
                self.build_logs[f"{what} [{' '.join(opts)}]"] = text
                _log_compiler_output(f"building {what} on {self.info.name}", text)
                self._programs[key] = prg
                self.compile_seconds += time.perf_counter() - t0
        return prg

    def compiler_warnings(self) -> dict[str, list[str]]:
        """The warning lines (:func:`warning_lines`) of every program built on this runtime
        that has any, by program: ``{}`` when the kernels compiled cleanly. Programs come from
        the implementation's cache when built before (PoCL's, pyopencl's), and a cached build
        may have an empty log: build on fresh caches to see every warning."""
        out = {}
        for what, text in self.build_logs.items():
            lines = warning_lines(text)
            if lines:
                out[what] = lines
        return out

    def first_run(self) -> bool:
        """True until :meth:`mark_warm` has recorded this device (implementation, version,
        driver) with the kernel sources of this clfza: its programs are then in the on-disk
        caches (PoCL's, pyopencl's) and its tuning measured."""
        return read_cache(COMPILED_FILE).get(self.key) != kernels_hash()

    def mark_warm(self) -> None:
        """Record that this device's kernels were compiled and tuned (see :meth:`first_run`)."""
        done = read_cache(COMPILED_FILE)
        done[self.key] = kernels_hash()
        write_cache(COMPILED_FILE, done)

    def clear_programs(self) -> None:
        """Forget every built program and kernel object (they are rebuilt on next use)."""
        with self._lock:
            self._programs.clear()
            self._kernels.clear()

    def build(self, src: str, options=()):
        """Build OpenCL C source on this context (see :func:`build_source`); raises the
        runtime's RuntimeError with the build log when it fails."""
        return build_source(self.cl, self.context, src, options)

    def kernel(self, program: str, kernel: str, dtype=np.float32, defines: dict | None = None):
        """A cached kernel object of a cached program.

        Kernel objects are shared: callers set every argument on each launch (pyopencl's
        ``__call__`` does), so sharing is safe on one thread.
        """
        prg = self.program(program, dtype, defines)
        key = (id(prg), kernel)
        k = self._kernels.get(key)
        if k is None:
            k = typed_kernel(self.cl, prg, kernel)
            self._kernels[key] = k
        return k

    # ----- memory -------------------------------------------------------------------
    def check_alloc(self, nbytes: int, what: str = "array") -> None:
        """Raise DeviceError before an allocation the device cannot hold."""
        dev = self.device
        if nbytes > dev.max_mem_alloc_size:
            raise DeviceError(
                f"{what} needs {nbytes / 2**20:.1f} MiB but {self.info.name} allows at most "
                f"{dev.max_mem_alloc_size / 2**20:.1f} MiB per buffer; use a smaller grid, bin "
                "the frame, or choose another device")
        if nbytes > dev.global_mem_size:
            raise DeviceError(
                f"{what} needs {nbytes / 2**20:.1f} MiB but {self.info.name} has only "
                f"{dev.global_mem_size / 2**20:.1f} MiB")

    def check_total(self, nbytes: int, what: str = "the solve") -> None:
        """Raise DeviceError when a whole working set exceeds device memory."""
        if nbytes > self.device.global_mem_size:
            raise DeviceError(
                f"{what} needs about {nbytes / 2**20:.0f} MiB of device memory but "
                f"{self.info.name} has {self.device.global_mem_size / 2**20:.0f} MiB; use a "
                "smaller grid, bin the frame, or use float32")

    def defer_release(self, host, buf) -> None:
        """Keep a dropped zero-copy array's memory alive until queued work has finished.

        Called by :class:`~clfza.cl._arrays.DeviceArray` on deletion; released by
        :meth:`finish`. Past a bound, the queue is drained here so the list cannot grow.
        """
        self._graveyard.append((host, buf))
        if len(self._graveyard) > 256:
            self.finish()

    def finish(self) -> None:
        """Wait for all queued work, then release the memory of dropped zero-copy arrays."""
        self.queue.finish()
        self._graveyard.clear()

    def __repr__(self) -> str:
        return f"Runtime({self.info.describe()})"


_RUNTIMES: dict[str, Runtime] = {}
_RT_LOCK = threading.RLock()  # re-entered: the default device is measured with runtimes


def get_runtime(device: str | None = None) -> Runtime:
    """The cached :class:`Runtime` for a device spec (None: PYOPENCL_CTX, else GPU, else CPU)."""
    key = device if device is not None else f"env:{os.environ.get('PYOPENCL_CTX', '')}"
    with _RT_LOCK:
        rt = _RUNTIMES.get(key)
        if rt is None:
            rt = Runtime(device)
            _RUNTIMES[key] = rt
    return rt
