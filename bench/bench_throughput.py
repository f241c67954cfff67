"""Throughput of a frame stream: frames/s end to end (read, solve, write) on Dask vs one process.

For each size (512^2, optionally 2048^2) and method (ADMM-TV, TwIST-TV paper mode; OpenCL),
a stream of simulated raw frames (uint16 .npy files) is reconstructed by

* ``single``: :func:`clfza.reconstruct_many` in this process (the single-process batch);
* ``dask-1``: a LocalCluster of 1 worker process;
* ``dask-2``: 2 worker processes, each free to use every core (PoCL and scipy.fft threads);
* ``dask-2-pinned``: 2 worker processes, one core each (``pin_cpus=True``).

Each configuration is warmed up first (kernels compile once per worker process; the compile
time of a worker's first frame is reported separately), then timed in steady state. The
per-frame time is split into read, prepare, compile, plan, solve and write (the workers'
records) and scheduling + transfer: the workers' idle time per frame, ``(wall x workers -
sum of task times) / frames``; a no-op task round trip is measured too. A cost model
projects N workers from these measurements (stated as a projection, not measured).

    .venv/bin/python bench/bench_throughput.py [--frames 12] [--sizes 512,2048] [--iters 50]

Writes ``bench/results/throughput_<machine>.json`` and ``.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

import clfza
from clfza.cluster import open_client
from clfza.distributed import reconstruct_many
from clfza.io import write_array

RESULTS = Path(__file__).resolve().parent / "results"
# model "tf" (the FFT-grid operator) pinned, so that solves compare with the README's
METHODS = {"admm": {"stop": "none", "model": "tf"}, "twist": {"mode": "paper", "model": "tf"}}
PARTS = ("read", "prepare", "compile", "plan", "solve", "write")


def make_frames(d: Path, n: int, size: int) -> tuple[list[Path], clfza.Camera]:
    """``n`` simulated raw frames (uint16 .npy) of the paper's camera at ``size``^2."""
    from skimage import data, transform

    cam = clfza.Camera.preset("simulation")
    if size != cam.shape[0]:
        cam = cam.with_shape((size, size), cam.pitch * cam.shape[0] / size)
    base = data.camera().astype(float) / 255
    rng = np.random.default_rng(0)
    files = []
    for i in range(n):
        scene = np.roll(base, (8 * i, 5 * i), axis=(0, 1))
        scene = transform.resize(scene, (size // 4, size // 4)) + 0.01 * rng.random((size // 4,
                                                                                      size // 4))
        f = clfza.simulate(scene, cam, object_width=20.0).frame
        files.append(write_array(d / f"frame{i:03d}.npy",
                                 np.round(f / f.max() * 60000).astype(np.uint16)))
    return files, cam


def noop(i: int) -> int:
    return i


def round_trip(client, n: int = 200) -> float:
    """Seconds per no-op task, submitted and gathered like the batch (scheduling + transfer)."""
    client.gather([client.submit(noop, i, pure=False) for i in range(4)])
    t0 = time.perf_counter()
    client.gather([client.submit(noop, i, pure=False) for i in range(n)])
    return (time.perf_counter() - t0) / n


def _split(res, wall: float, workers: int) -> dict:
    ok = [r for r in res.results if r.ok]
    per = {k: float(np.mean([r.timings.get(k, 0.0) for r in ok])) for k in PARTS + ("task",)}
    idle = (wall * workers - sum(r.timings["task"] for r in ok)) / max(len(ok), 1)
    per["sched_transfer"] = max(idle, 0.0)
    per["compile_first_frame"] = float(max(r.timings.get("compile", 0.0) for r in ok))
    return per


def run_config(name: str, files, cam, method: str, iters: int, out: Path, workers: int | None,
               pin: bool) -> dict:
    """Warm up, then time the whole stream under one configuration."""
    opts = {"iters": iters, **METHODS[method]}
    t_start = time.perf_counter()
    kw = {}
    ctx = open_client(workers=workers, pin_cpus=pin) if workers else None
    c = ctx.__enter__()[0] if ctx else None
    startup = time.perf_counter() - t_start
    try:
        if c is not None:
            kw["client"] = c
        nwarm = max(1, workers or 1)
        warm = reconstruct_many(files[:nwarm], cam, method, out_dir=out / f"{name}-warm",
                                **kw, **opts)
        rt = round_trip(c) if c is not None else 0.0
        t0 = time.perf_counter()
        res = reconstruct_many(files, cam, method, out_dir=out / name, **kw, **opts)
        wall = time.perf_counter() - t0
    finally:
        if ctx is not None:
            ctx.__exit__(None, None, None)
    assert not res.failed, [r.error for r in res.failed]
    split = _split(res, wall, workers or 1)
    split["compile_first_frame"] = float(max(r.timings.get("compile", 0.0)
                                             for r in warm.results))
    return {"config": name, "workers": workers or 0, "pinned": pin, "frames": len(files),
            "wall_s": wall, "frames_per_s": len(files) / wall, "startup_s": startup,
            "noop_round_trip_s": rt, "per_frame_s": split,
            "iterations": res.results[0].record["iterations"]}


def project(rows: list[dict], cores: int) -> dict:
    """Cost model: N single-core workers run independent frames, so frames/s(N) =
    N / (t_task + t_sched) while N <= cores (and memory bandwidth holds); beyond, flat."""
    pinned = next((r for r in rows if r["config"] == "dask-2-pinned"), None)
    if pinned is None:
        return {}
    t = pinned["per_frame_s"]["task"] + pinned["per_frame_s"]["sched_transfer"]
    return {"model": "fps(N) = min(N, cores) / (t_task_1core + t_sched)",
            "t_task_1core_s": pinned["per_frame_s"]["task"],
            "t_sched_s": pinned["per_frame_s"]["sched_transfer"],
            "projected_fps": {str(n): min(n, cores) / t for n in (1, 2, 4, 8, 16)},
            "note": "projection from measurements, not measured; assumes one core per worker, "
                    "no memory-bandwidth limit and a file system that keeps up"}


def machine() -> dict:
    import dask
    import distributed

    from clfza.cl import get_runtime

    rt = get_runtime()
    return {"platform": platform.platform(), "processor": platform.processor(),
            "cpus": os.cpu_count(), "python": platform.python_version(),
            "clfza": clfza.__version__, "dask": dask.__version__,
            "distributed": distributed.__version__, "numpy": np.__version__,
            "device": rt.info.describe(), "load_average_1_5_15": list(os.getloadavg())}


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = report["rows"]
    cases = sorted({(r["size"], r["method"]) for r in rows})
    fig, axes = plt.subplots(2, len(cases), figsize=(4.2 * len(cases), 7.5), squeeze=False)
    for j, (size, method) in enumerate(cases):
        sub = [r for r in rows if (r["size"], r["method"]) == (size, method)]
        ax = axes[0][j]
        ax.bar([r["config"] for r in sub], [r["frames_per_s"] for r in sub], color="C0")
        ax.set_title(f"{method.upper()} {size}^2, {sub[0]['iterations']} it")
        ax.set_ylabel("frames/s (end to end)")
        ax.tick_params(axis="x", rotation=30)
        ax = axes[1][j]
        bottom = np.zeros(len(sub))
        for k, part in enumerate(PARTS + ("sched_transfer",)):
            v = np.array([r["per_frame_s"][part] * 1e3 for r in sub])
            ax.bar([r["config"] for r in sub], v, bottom=bottom, label=part, color=f"C{k}")
            bottom += v
        ax.set_ylabel("ms per frame (per worker)")
        ax.tick_params(axis="x", rotation=30)
    axes[1][0].legend(fontsize=7)
    m = report["machine"]
    fig.suptitle(f"clfza stream throughput; {m['cpus']} cores, {m['device'][:60]}; "
                 f"dask {m['dask']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=12, help="frames per stream at 512^2")
    ap.add_argument("--sizes", default="512", help="comma list, e.g. 512,2048")
    ap.add_argument("--iters", type=int, default=50)
    ap.add_argument("--methods", default="admm,twist")
    ap.add_argument("--tag", default="amd-epyc-2c")
    args = ap.parse_args()
    rows = []
    configs = [("single", None, False), ("dask-1", 1, False), ("dask-2", 2, False),
               ("dask-2-pinned", 2, True)]
    with tempfile.TemporaryDirectory() as tmp:
        for size in (int(s) for s in args.sizes.split(",")):
            n = args.frames if size <= 512 else max(4, args.frames // 4)
            files, cam = make_frames(Path(tmp) / f"in{size}", n, size)
            for method in args.methods.split(","):
                for name, w, pin in configs:
                    r = run_config(name, files, cam, method, args.iters,
                                   Path(tmp) / f"out{size}-{method}", w, pin)
                    r.update(size=size, method=method)
                    rows.append(r)
                    _save(rows, args)  # partial results survive an interrupted run
                    print(f"{size}^2 {method:6s} {name:14s} {r['frames_per_s']:7.2f} frames/s "
                          f"solve {r['per_frame_s']['solve'] * 1e3:7.1f} ms  sched+transfer "
                          f"{r['per_frame_s']['sched_transfer'] * 1e3:6.1f} ms  no-op "
                          f"{r['noop_round_trip_s'] * 1e3:5.2f} ms", flush=True)
    out = _save(rows, args)
    print(f"wrote {out} and {out.with_suffix('.png')}")


def _save(rows: list[dict], args) -> Path:
    report = {"machine": machine(), "iters": args.iters, "rows": rows,
              "projection": {f"{s}-{m}": project([r for r in rows if (r["size"], r["method"])
                                                  == (s, m)], os.cpu_count() or 1)
                             for s, m in sorted({(r["size"], r["method"]) for r in rows})}}
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / f"throughput_{args.tag}.json"
    out.write_text(json.dumps(report, indent=2) + "\n")
    plot(report, out.with_suffix(".png"))
    return out


if __name__ == "__main__":
    main()
