"""What machine a benchmark ran on, and how fast that machine can possibly go.

Every result file records :func:`machine_record` (CPU model and cores from ``/proc/cpuinfo``,
memory, load average, OpenCL device, library versions, date). The speed limit of a solver
iteration (docs/design.md s.5) is built from two measurements taken in the same run:

- the time of one real FFT pair (``rfft2`` + ``irfft2``) through :mod:`clfza.fft._host`
  (scipy's pocketfft, all cores, writing into preallocated arrays), see :func:`fft_pair_time`;
- the memory bandwidth of a STREAM triad ``a = b + s c`` as an OpenCL kernel
  (``kernels/bench.cl``) and as numpy expressions, see :func:`triad_bandwidth`.

All timings are medians over repeats (the machine may be shared; ratios are only compared
within one run).
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import re
import socket
import time
from collections.abc import Callable
from importlib import metadata

import numpy as np

from ..cl import DeviceArray, get_runtime
from ..fft import host_irfft2, host_rfft2

LIBRARIES = ("clfza", "numpy", "scipy", "pyopencl", "scikit-image", "matplotlib",
             "pocl-binary-distribution")


def _cpuinfo() -> dict:
    model, flags = platform.processor() or "unknown", ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            text = fh.read()
        m = re.search(r"^model name\s*:\s*(.+)$", text, re.M)
        if m:
            model = m.group(1).strip()
        f = re.search(r"^flags\s*:\s*(.+)$", text, re.M)
        if f:
            wanted = ("avx", "avx2", "avx512f", "fma", "sse4_2", "neon")
            flags = " ".join(x for x in f.group(1).split() if x in wanted)
    except OSError:
        pass
    return {"model": model, "simd_flags": flags}


def _memory_gib() -> float | None:
    try:
        with open("/proc/meminfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("MemTotal:"):
                    return round(int(line.split()[1]) / 2**20, 2)
    except OSError:
        pass
    return None


def library_versions() -> dict:
    """Installed versions of the libraries that decide the numbers."""
    out = {}
    for name in LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def device_record(device: str | None = None) -> dict:
    """The OpenCL device a benchmark uses (or why there is none)."""
    try:

        rt = get_runtime(device)
        info = rt.info
        return {"name": info.name, "platform": info.platform, "kind": info.kind,
                "compute_units": info.compute_units, "global_mem_mb": info.global_mem_mb,
                "fp64": info.fp64, "describe": info.describe()}
    except Exception as exc:  # a benchmark must still record the machine
        return {"name": None, "error": str(exc)}


def machine_record(device: str | None = None) -> dict:
    """Machine, device, library versions and date, for every result file."""
    cpu = _cpuinfo()
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        affinity = os.cpu_count()
    try:
        load = [round(v, 2) for v in os.getloadavg()]
    except OSError:  # pragma: no cover
        load = None
    return {
        "cpu_model": cpu["model"],
        "cpu_simd": cpu["simd_flags"],
        "cores": os.cpu_count(),
        "cores_usable": affinity,
        "memory_gib": _memory_gib(),
        "load_average": load,
        "hostname": socket.gethostname(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "device": device_record(device),
        "versions": library_versions(),
        "date": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
    }


def machine_slug(record: dict | None = None) -> str:
    """A short file-name label for the machine: CPU model and usable cores."""
    rec = record or machine_record()
    model = re.sub(r"\((R|TM)\)|CPU|Processor|@.*", "", rec.get("cpu_model") or "cpu")
    slug = re.sub(r"[^a-z0-9]+", "-", model.lower()).strip("-") or "cpu"
    return f"{slug}-{rec.get('cores_usable') or rec.get('cores')}c"


# ------------------------------------------------------------------------------------------
# timing helpers
# ------------------------------------------------------------------------------------------
def median_time(fn: Callable[[], object], repeats: int = 5, warmup: int = 1,
                min_time: float = 0.0) -> float:
    """Median wall time of ``fn()`` in seconds after ``warmup`` calls.

    ``min_time``: keep repeating (beyond ``repeats``) until this much time was spent, which
    steadies very short measurements.
    """
    for _ in range(warmup):
        fn()
    times: list[float] = []
    spent = 0.0
    while len(times) < repeats or spent < min_time:
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        times.append(dt)
        spent += dt
        if len(times) > 200:
            break
    return float(np.median(times))


def fft_pair_time(shape: tuple[int, int], dtype=np.float32, repeats: int = 7) -> float:
    """Median seconds of one ``rfft2`` + ``irfft2`` through :mod:`clfza.fft._host`.

    This is the FFT work one solver iteration cannot avoid (docs/design.md s.2: with the normal
    operator one real FFT pair per iteration suffices). Preallocated outputs, all cores, the
    inverse in its input's memory (``overwrite_x``, as the solvers run it).
    """

    dtype = np.dtype(dtype)
    cdtype = np.result_type(dtype, np.complex64)
    ny, nx = shape
    rng = np.random.default_rng(0)
    x = rng.standard_normal((ny, nx)).astype(dtype)
    X = np.empty((ny, nx // 2 + 1), cdtype)
    y = np.empty((ny, nx), dtype)

    def pair() -> None:
        host_rfft2(x, X)
        host_irfft2(X, nx, y, overwrite_x=True)

    return median_time(pair, repeats=repeats, warmup=2, min_time=0.05)


def triad_bandwidth_opencl(n: int = 1 << 24, dtype=np.float32, repeats: int = 9,
                           device: str | None = None) -> dict:
    """GB/s of the OpenCL triad kernel ``a = b + s c`` over ``n`` elements (3 arrays counted).

    Each repeat enqueues ``batch`` launches and waits once, so launch latency is amortised
    the way a solver's queued iteration amortises it.
    """

    rt = get_runtime(device)
    dtype = np.dtype(dtype)
    k = rt.kernel("bench", "triad", dtype)
    a = DeviceArray.empty(rt, (n,), dtype)
    b = DeviceArray.from_host(rt, np.ones(n, dtype))
    c = DeviceArray.from_host(rt, np.full(n, 2.0, dtype))
    batch = 4
    s = dtype.type(0.5)

    def run() -> None:
        for _ in range(batch):
            k(rt.queue, (n,), None, a.buf, b.buf, c.buf, s, np.int32(n))
        rt.finish()

    t = median_time(run, repeats=repeats, warmup=1) / batch
    ok = bool(np.allclose(a.get()[:16], 2.0))
    nbytes = 3 * n * dtype.itemsize
    return {"gb_per_s": nbytes / t / 1e9, "seconds": t, "elements": n, "bytes": nbytes,
            "dtype": dtype.name, "correct": ok, "kernel": "bench.cl:triad"}


def triad_bandwidth_numpy(n: int = 1 << 24, dtype=np.float32, repeats: int = 9) -> dict:
    """GB/s of the best numpy triad (``multiply`` then ``add`` with ``out=``, 3 arrays
    counted as in STREAM; numpy really moves 5 because it cannot fuse)."""
    dtype = np.dtype(dtype)
    a = np.empty(n, dtype)
    b = np.ones(n, dtype)
    c = np.full(n, 2.0, dtype)
    s = dtype.type(0.5)

    def run() -> None:
        np.multiply(c, s, out=a)
        np.add(a, b, out=a)

    t = median_time(run, repeats=repeats, warmup=1)
    nbytes = 3 * n * dtype.itemsize
    return {"gb_per_s": nbytes / t / 1e9, "seconds": t, "elements": n, "bytes": nbytes,
            "dtype": dtype.name, "kernel": "numpy multiply+add (out=)"}


def triad_bandwidth(n: int = 1 << 24, repeats: int = 9, device: str | None = None) -> dict:
    """Triad bandwidth of the OpenCL device (float32) and of numpy (float32 and float64).

    ``limit_gb_per_s`` is the best of them: the bandwidth the speed limit uses.
    """
    out: dict = {"numpy_f32": triad_bandwidth_numpy(n, np.float32, repeats),
                 "numpy_f64": triad_bandwidth_numpy(n, np.float64, repeats)}
    try:
        out["opencl_f32"] = triad_bandwidth_opencl(n, np.float32, repeats, device)
    except Exception as exc:  # no device: the numpy number still bounds the host
        out["opencl_f32"] = {"error": str(exc)}
    best = max(v.get("gb_per_s", 0.0) for v in out.values())
    out["limit_gb_per_s"] = best
    return out
