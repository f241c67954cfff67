"""Benchmark the FFT paths of clfza against scipy.fft on the same machine.

For each square size N^2 it times the real 2-D forward (rfft2) and inverse (irfft2) transform
of every available path and reports the median of several runs and GFLOP/s. Flop convention:
the usual 5 N log2 N for a complex transform of N points; a real transform is counted as half
of that, 2.5 N log2 N with N = Ny * Nx (as FFTW and VkFFT report R2C/C2R).

Paths
-----
* ``scipy``: scipy.fft.rfft2/irfft2 in float32 with workers = cores (host arrays, no device).
* ``host-scipy``: clfza's HostFFT engine on DeviceArrays (zero-copy on CPU devices).
* ``opencl-stockham``: clfza's OpenCL kernels (DeviceFFT).
* ``vkfft``: pyvkfft's OpenCL backend, when installed.

Writes ``bench/results/fft_<device>.json`` and a PNG plot next to it and prints a table::

    python bench/bench_fft.py                     # 256 .. 4096
    python bench/bench_fft.py --sizes 256,512 --repeats 3 --device gpu
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import re
import socket
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _versions() -> dict:
    import pyopencl
    import scipy

    import clfza

    out = {"python": platform.python_version(), "numpy": np.__version__,
           "scipy": scipy.__version__, "pyopencl": pyopencl.VERSION_TEXT,
           "clfza": getattr(clfza, "__version__", "dev")}
    try:
        import pyvkfft

        out["pyvkfft"] = getattr(pyvkfft, "__version__", "unknown")
    except Exception:
        pass
    return out


def _slug(s: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "-", s).strip("-").lower()[:48]


def bench(sizes, repeats: int, device: str | None, dtype=np.float32) -> dict:
    import scipy.fft

    from clfza.cl import DeviceArray, get_runtime
    from clfza.fft._host import WORKERS, HostFFT
    from clfza.fft._opencl import DeviceFFT
    from clfza.fft._vkfft import VkFFTEngine, vkfft_available

    rt = get_runtime(device)
    load0 = os.getloadavg() if hasattr(os, "getloadavg") else None
    cdt = np.complex64 if np.dtype(dtype) == np.float32 else np.complex128
    rows = []
    for n in sizes:
        shape = (n, n)
        flops = 2.5 * n * n * np.log2(n * n)
        x = np.random.default_rng(0).standard_normal(shape).astype(dtype)
        # scipy on host arrays
        X = scipy.fft.rfft2(x, workers=WORKERS)
        paths = {"scipy": (lambda x=x: scipy.fft.rfft2(x, workers=WORKERS),
                           lambda X=X, s=shape: scipy.fft.irfft2(X, s=s, workers=WORKERS),
                           lambda: None)}
        engines = [("host-scipy", lambda s=shape: HostFFT(rt, s, dtype)),
                   ("opencl-stockham", lambda s=shape: DeviceFFT(rt, s, dtype))]
        if vkfft_available():
            engines.append(("vkfft", lambda s=shape: VkFFTEngine(rt, s, dtype)))
        keep = []
        for name, make in engines:
            eng = make()
            xd = DeviceArray.from_host(rt, x)
            Xd = DeviceArray.empty(rt, (n, n // 2 + 1), cdt)
            yd = DeviceArray.empty(rt, shape, dtype)
            keep.append((eng, xd, Xd, yd))
            paths[name] = (lambda e=eng, a=xd, b=Xd: e.rfft2(a, b),
                           lambda e=eng, a=Xd, b=yd: e.irfft2(a, b), rt.finish)
        # A/B: every repetition times every path in turn, so that the load of a shared
        # machine affects all paths alike
        times = {name: ([], []) for name in paths}
        for fwd, inv, sync in paths.values():  # warm-up: builds, plans, first-touch
            fwd()
            inv()
            sync()
        for _ in range(repeats):
            for name, (fwd, inv, sync) in paths.items():
                for fn, ts in zip((fwd, inv), times[name], strict=True):
                    t0 = time.perf_counter()
                    fn()
                    sync()
                    ts.append(time.perf_counter() - t0)
        for name, (tf, ti) in times.items():
            mf, mi = float(np.median(tf)), float(np.median(ti))
            rows.append({"n": n, "path": name, "rfft2_ms": mf * 1e3, "irfft2_ms": mi * 1e3,
                         "rfft2_min_ms": min(tf) * 1e3, "irfft2_min_ms": min(ti) * 1e3,
                         "rfft2_gflops": flops / mf / 1e9, "irfft2_gflops": flops / mi / 1e9})
        del keep
        rt.finish()
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return {
        "benchmark": "fft rfft2/irfft2, square grids",
        "flop_convention": "real 2-D transform of N = Ny*Nx points counted as 2.5 N log2 N "
                           "(half of the complex 5 N log2 N)",
        "statistic": f"median of {repeats} runs after one warm-up (min also given); the paths "
                     "are timed in turn within every repetition (A/B)",
        "dtype": np.dtype(dtype).name,
        "date": _dt.datetime.now().isoformat(timespec="seconds"),
        "machine": {"hostname": socket.gethostname(), "cpu": _cpu_model(),
                    "cores": os.cpu_count(), "platform": platform.platform(),
                    "load_average_at_start": load0, "load_average_at_end": load},
        "device": {"name": rt.info.name, "kind": rt.info.kind, "platform": rt.info.platform,
                   "version": rt.device.version, "driver": rt.device.driver_version},
        "scipy_workers": WORKERS,
        "opencl_mapping": DeviceFFT(rt, (8, 8), dtype).mapping,
        "ratio_opencl_to_scipy": _ratios(rows),
        "versions": _versions(),
        "results": rows,
    }


def _ratios(rows) -> dict:
    """opencl-stockham time / scipy time per size (A/B medians): {"N": [rfft2, irfft2]}."""
    by = {(r["n"], r["path"]): r for r in rows}
    out = {}
    for (n, p), d in by.items():
        s = by.get((n, "scipy"))
        if p == "opencl-stockham" and s:
            out[str(n)] = [d["rfft2_ms"] / s["rfft2_ms"], d["irfft2_ms"] / s["irfft2_ms"]]
    return out


def table(res: dict) -> str:
    rows = res["results"]
    paths = list(dict.fromkeys(r["path"] for r in rows))
    sizes = sorted({r["n"] for r in rows})
    by = {(r["n"], r["path"]): r for r in rows}
    hdr = f"{'N':>6} " + " ".join(f"{p + ' fwd/inv':>26}" for p in paths)
    lines = [f"GFLOP/s (ms), {res['device']['name']}, {res['dtype']}", hdr]
    for n in sizes:
        cells = []
        for p in paths:
            r = by.get((n, p))
            cells.append(f"{r['rfft2_gflops']:6.2f}/{r['irfft2_gflops']:5.2f} "
                         f"({r['rfft2_ms']:6.1f}/{r['irfft2_ms']:6.1f})" if r else " " * 26)
        lines.append(f"{n:>5}^2 " + " ".join(f"{c:>26}" for c in cells))
    # ratio of the device kernels to scipy
    if "opencl-stockham" in paths:
        lines.append("opencl-stockham time / scipy time (fwd, inv):")
        for n in sizes:
            d, s = by[(n, "opencl-stockham")], by[(n, "scipy")]
            lines.append(f"  {n}^2: {d['rfft2_ms'] / s['rfft2_ms']:.2f}x, "
                         f"{d['irfft2_ms'] / s['irfft2_ms']:.2f}x")
    return "\n".join(lines)


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["results"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, kind in zip(axes, ("rfft2", "irfft2"), strict=True):
        for p in dict.fromkeys(r["path"] for r in rows):
            rr = [r for r in rows if r["path"] == p]
            ax.plot([r["n"] for r in rr], [r[f"{kind}_gflops"] for r in rr], "o-", label=p)
        ax.set_xscale("log", base=2)
        ax.set_xlabel("N (grid N x N)")
        ax.set_title(kind)
        ax.grid(True, alpha=0.3)
    axes[0].set_ylabel("GFLOP/s (2.5 N log2 N)")
    axes[0].legend()
    fig.suptitle(f"{res['device']['name']} ({res['machine']['cores']} cores), "
                 f"{res['dtype']}, {res['date'][:10]}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="256,512,1024,2048,4096",
                    help="comma-separated grid sizes N (N x N), default 256..4096")
    ap.add_argument("--repeats", type=int, default=9, help="timed runs per case (median)")
    ap.add_argument("--device", default=None, help="OpenCL device spec (see clfza info)")
    ap.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    ap.add_argument("--out", default=None, help="JSON path (default bench/results/fft_<dev>)")
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    res = bench(sizes, args.repeats, args.device, np.dtype(args.dtype))
    print(table(res))
    out = Path(args.out) if args.out else RESULTS / f"fft_{_slug(res['device']['name'])}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1))
    plot(res, out.with_suffix(".png"))
    print(f"wrote {out} and {out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
