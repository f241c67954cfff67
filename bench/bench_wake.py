"""What an OpenCL implementation's idle workers cost TwIST on a CPU: the wake-up per device
visit, measured, and its share of a paper-mode iteration against the machine limit.

Usage::

    .venv/bin/python bench/bench_wake.py [--devices 1:0 0:0 2:0] [--n 512] [--rounds 3]
                                         [--host-us 450]

A paper-mode TwIST iteration on a CPU device alternates host and device: the prox and the
two-step combination (device), the forward FFT (host, scipy), the spectral kernel (device),
the inverse FFT (host). Each objective evaluation so visits the device twice, and each visit
starts after ``--host-us`` of host work (one FFT at 512^2: 0.42-0.48 ms), by which time an
implementation whose workers sleep at once when idle has to wake them. Per device, in one
fresh process per device and round (the devices interleaved, the order rotating), a small
kernel (clfza's triad, 4096 floats) launched and waited for:

* **chained**: 20 launches back to back and one wait, per launch (the workers stay busy);
* **after a finish**: each launch waited for before the next (an implementation whose workers
  sleep as soon as the queue is empty wakes them for every launch);
* **after host work**: right after ``--host-us`` of host work on the calling thread;
* **gated**: enqueued before that host work behind a user event, completed after it (the
  launch off the critical path: does enqueueing early avoid the wake?).

The wake per visit is *after host work* less *chained*. In the same process: TwIST paper mode's
steady-state iteration at ``--n`` (``(T_long - T_short) / (long - short)``, as bench_xlimit),
its objective evaluations per iteration, and the machine limit of one iteration (bench_xlimit:
one FFT pair plus 4 arrays at triad bandwidth, best probe). Reported: the iteration against
the limit, the estimated wake per iteration (2 visits per evaluation) and the iteration
without it against the limit. Medians over rounds.

Writes ``bench/results/wake_<machine>.json``, ``.md`` and ``.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_solvers import camera, probe  # noqa: E402
from bench_xlimit import PROBE_REPS, limit_ms, solve  # noqa: E402

from clfza.benchmarks._machine import machine_record, machine_slug  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
KERNEL_FLOATS = 4096  # the latency kernel's size: its own run time is a few microseconds
REPS = 300  # launches per latency figure (medians)
CHAIN = 20  # launches per wait in the chained figure
SHORT, LONG = 50, 200  # TwIST solves for the steady-state iteration


def busy(seconds: float) -> None:
    """Host work on the calling thread (a spin: the other cores go idle, as between two
    device visits of a solver)."""
    t = time.perf_counter()
    while time.perf_counter() - t < seconds:
        pass


def latencies(device: str, host_s: float, reps: int = REPS) -> dict:
    """Microseconds from launch to completion of a small kernel: chained (per launch of
    :data:`CHAIN` back to back), after a finish, after ``host_s`` of host work, and gated
    (enqueued before the host work behind a user event). Medians of ``reps`` launches."""
    from clfza.cl import get_runtime

    rt = get_runtime(device)
    cl, q = rt.cl, rt.queue
    k = rt.kernel("bench", "triad")
    a, b, c = (cl.Buffer(rt.context, cl.mem_flags.READ_WRITE, 4 * KERNEL_FLOATS)
               for _ in range(3))
    args = (a, b, c, np.float32(2.0), np.int32(KERNEL_FLOATS))

    def launch(**kw):
        return k(q, (KERNEL_FLOATS,), None, *args, **kw)

    for _ in range(50):
        launch()
    q.finish()
    chained, idle, after, gated = [], [], [], []
    for _ in range(reps // CHAIN):  # back to back, one wait: the workers stay busy
        t = time.perf_counter()
        for _ in range(CHAIN):
            launch()
        q.finish()
        chained.append((time.perf_counter() - t) / CHAIN)
    for _ in range(reps):  # each launch waited for before the next
        t = time.perf_counter()
        launch()
        q.finish()
        idle.append(time.perf_counter() - t)
    for _ in range(reps):
        busy(host_s)
        t = time.perf_counter()
        launch()
        q.finish()
        after.append(time.perf_counter() - t)
    for _ in range(reps):
        gate = cl.UserEvent(rt.context)
        launch(wait_for=[gate])
        q.flush()
        busy(host_s)
        t = time.perf_counter()
        gate.set_status(cl.command_execution_status.COMPLETE)
        q.finish()
        gated.append(time.perf_counter() - t)
    us = {name: statistics.median(v) * 1e6 for name, v in
          (("chained_us", chained), ("after_finish_us", idle), ("after_host_us", after),
           ("gated_us", gated))}
    us["wake_us"] = us["after_host_us"] - us["chained_us"]
    return us


def twist_steady(device: str, n: int) -> dict:
    """TwIST paper mode at ``n^2`` on ``device`` (bench_xlimit's camera and scene): the
    steady-state ms per iteration and objective evaluations per iteration."""
    from skimage import data

    import clfza

    cam = camera(n)
    m = clfza.simulate(data.camera(), cam, object_width=200.0)
    opts = {"mode": "paper"}
    solve(m, cam, "twist", opts, 3, device)  # compile, tune, warm up
    (ts, i_s, es), (tl, il, el) = (solve(m, cam, "twist", opts, it, device)
                                   for it in (SHORT, LONG))
    return {"steady_ms": (tl - ts) / (il - i_s) * 1e3,
            "evaluations_per_iteration": (el - es) / (il - i_s)}


def one_round(device: str, n: int, host_s: float) -> dict:
    """One device's figures in this process (:func:`run_child` runs it in a fresh one)."""
    from clfza.cl import get_runtime

    info = get_runtime(device).info
    p0 = probe(n, PROBE_REPS, device)
    out = {"name": f"{info.platform} {info.driver}", "device": info.name,
           **latencies(device, host_s), **twist_steady(device, n)}
    out["probes"] = [p0, probe(n, PROBE_REPS, device)]
    return out


def run_child(device: str, n: int, host_s: float) -> dict:
    """:func:`one_round` in a fresh process (``--child``): one implementation's threads per
    process, as a user's process runs one."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", device, str(n),
           repr(host_s)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode:
        raise SystemExit(f"bench_wake: the round on {device} failed:\n{res.stderr[-3000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def summarise(n: int, rounds: list[dict]) -> dict:
    """Medians over one device's rounds, the limit from its best probes, and the wake's share
    (2 device visits per objective evaluation)."""
    med = {k: statistics.median(r[k] for r in rounds) for k in
           ("chained_us", "after_finish_us", "after_host_us", "gated_us", "wake_us", "steady_ms",
            "evaluations_per_iteration")}
    lim = limit_ms(n, "twist", [p for r in rounds for p in r["probes"]])
    visits = 2 * med["evaluations_per_iteration"]
    wake_ms = max(0.0, med["wake_us"]) * visits / 1e3
    return {"name": rounds[0]["name"], "device": rounds[0]["device"], **med,
            "visits_per_iteration": visits, "wake_ms_per_iteration": wake_ms,
            "limit_ms": lim, "steady_x": med["steady_ms"] / lim,
            "steady_without_wake_x": (med["steady_ms"] - wake_ms) / lim,
            "rounds": rounds}


def measure(devices: list[str], n: int, rounds: int, host_s: float) -> dict:
    got: dict = {d: [] for d in devices}
    for r in range(rounds):
        k0 = r % len(devices)
        for d in devices[k0:] + devices[:k0]:
            got[d].append(run_child(d, n, host_s))
        print(f"  round {r + 1}/{rounds} done", flush=True)
    return {d: summarise(n, got[d]) for d in devices}


def markdown(res: dict) -> str:
    m = res["machine"]
    n = res["n"]
    lines = [
        f"# Idle OpenCL workers waking, and TwIST at {n}^2 ({m['date']})", "",
        f"Machine: {m['cpu_model']} ({m['cores_usable']} usable cores), load average at start "
        f"{res['load_start']}, at end {res['load_end']}. `bench/bench_wake.py --n {n} "
        f"--rounds {res['rounds']} --host-us {res['host_us']:.0f}`, revision "
        f"{res['revision']}. One fresh process per device and round, the devices interleaved; "
        "medians over rounds.", "",
        f"A small kernel (triad, {KERNEL_FLOATS} floats), per launch: {CHAIN} back to back and "
        "one wait (chained: the workers stay busy), each launch waited for before the next "
        f"(after a finish), right after {res['host_us']:.0f} us of host work on the calling "
        "thread (a TwIST iteration's device visits each follow a host FFT of about that "
        "length), and enqueued before the host work behind a user event completed after it "
        "(gated). Wake = after host work - chained.", "",
        "| device | chained us | after a finish us | after host work us | gated us | wake us |",
        "|---|---|---|---|---|---|"]
    for d in res["devices"].values():
        lines.append(f"| {d['name']} | {d['chained_us']:.1f} | {d['after_finish_us']:.1f} | "
                     f"{d['after_host_us']:.1f} | {d['gated_us']:.1f} | {d['wake_us']:.1f} |")
    lines += [
        "", f"## TwIST paper mode at {n}^2: the wake's share", "",
        "Steady-state ms per iteration (bench_xlimit's camera and scene, "
        f"{SHORT}- and {LONG}-iteration solves), the limit of one iteration (one FFT pair + 4 "
        "arrays at triad bandwidth, best probe; target 2.0x), and the wake per iteration "
        "estimated as 2 device visits per objective evaluation times the wake per visit.", "",
        "| device | ms/iteration | evaluations/it | x limit | wake ms/it | x limit without "
        "the wake |", "|---|---|---|---|---|---|"]
    for d in res["devices"].values():
        lines.append(f"| {d['name']} | {d['steady_ms']:.3f} | "
                     f"{d['evaluations_per_iteration']:.2f} | x{d['steady_x']:.2f} | "
                     f"{d['wake_ms_per_iteration']:.3f} | x{d['steady_without_wake_x']:.2f} |")
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    devs = list(res["devices"].values())
    names = [d["name"].replace("Portable Computing Language", "PoCL")[:28] for d in devs]
    x = np.arange(len(devs))
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    bars = (("chained_us", "chained"), ("after_finish_us", "after a finish"),
            ("after_host_us", "after host work"), ("gated_us", "gated"))
    for i, (key, label) in enumerate(bars):
        a1.bar(x + (i - 1.5) * 0.2, [d[key] for d in devs], 0.2, label=label)
    a1.set_xticks(x, names, fontsize=7)
    a1.set_ylabel("launch to completion (us)")
    a1.set_title("a small kernel")
    a1.legend(fontsize=8)
    wake = [d["wake_ms_per_iteration"] for d in devs]
    rest = [d["steady_ms"] - w for d, w in zip(devs, wake, strict=True)]
    a2.bar(x, rest, 0.5, label="iteration less wake")
    a2.bar(x, wake, 0.5, bottom=rest, label="wake (estimate)")
    for i, d in enumerate(devs):
        a2.hlines(2.0 * d["limit_ms"], i - 0.3, i + 0.3, colors="k")
    a2.set_xticks(x, names, fontsize=7)
    a2.set_ylabel("ms per iteration")
    a2.set_title(f"TwIST paper mode at {res['n']}^2 (line: 2x limit)")
    a2.legend(fontsize=8, loc="lower center")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:
        warnings.simplefilter("ignore")
        print(json.dumps(one_round(argv[1], int(argv[2]), float(argv[3]))))
        return 0
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--devices", nargs="+", default=None)
    p.add_argument("--n", type=int, default=512)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--host-us", type=float, default=450.0)
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    if a.n < 64 or a.rounds < 1 or a.host_us <= 0:
        p.error("--n must be at least 64, --rounds at least 1, --host-us positive")
    warnings.simplefilter("ignore")
    from bench_tau import revision

    from clfza.reconstruction._device_choice import usable_devices

    mach = machine_record()
    devices = a.devices or [d for d in usable_devices() if d_is_cpu(d)]
    res = {"machine": mach, "revision": revision(), "n": a.n, "rounds": a.rounds,
           "host_us": a.host_us, "load_start": mach["load_average"],
           "pyopencl_ctx": os.environ.get("PYOPENCL_CTX")}
    res["devices"] = measure(devices, a.n, a.rounds, a.host_us * 1e-6)
    res["load_end"] = machine_record()["load_average"]
    paths = write_result_files(Path(a.out) / f"wake_{machine_slug(mach)}", res, markdown(res),
                               plot)
    print(markdown(res))
    print("wrote", *paths)
    return 0


def d_is_cpu(device: str) -> bool:
    """Whether OpenCL device ``"P:D"`` is a CPU (the wake is a CPU implementation's cost)."""
    from clfza.cl import get_runtime

    return get_runtime(device).is_cpu


if __name__ == "__main__":
    raise SystemExit(main())
