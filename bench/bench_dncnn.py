"""Issue 38: the DnCNN denoiser on OpenCL: time per call, FLOP rate, and denoising PSNR.

Usage::

    python bench/bench_dncnn.py [--device P:D [P:D ...]] [--sizes 256 512]
                                [--variants 6N 17N] [--rounds 3] [--kernel auto]
                                [--sigmas 0.02 0.05 0.1 0.2] [--no-quality] [--out bench/results]

Per device (default: the default device; several in one run are interleaved round by round,
so their ratios come from the same minutes of a shared machine), per image size and variant
(6 and 17 layers):

* **ms/call (device)**: every layer queued on images already on the device, until the queue
  drains: the denoiser's cost inside a solver whose iterate lives there;
* **ms/call (host)**: the same with the image copied in and the result read back;
* **GFLOP/s**: the network's FLOPs (two per multiply-add of the convolutions,
  :meth:`clfza.denoisers.DnCNNWeights.flops`) over the device time;
* **numpy's float32 matrix multiply** (2048^2 @ 2048^2, BLAS) in GFLOP/s, measured in the same
  rounds, and the ratio: the issue's CPU target is >= 40 % of it for a 6-layer call at 512^2;
  its GPU target is <= 10 ms per 6-layer call at 512^2.

Every figure is a median over ``--rounds``. Which 64 -> 64 kernel ran (``cpu``: vectorised
over output channels; ``tiled``: through local memory) is recorded; ``--kernel auto`` chooses
by the device's kind.

Quality (skip with ``--no-quality``): scikit-image's camera at 256^2 in [0, 1] plus Gaussian
noise at each ``--sigmas`` (unclipped, seed 0): PSNR and SSIM of the noisy image, of TV
denoising (``skimage.restoration.denoise_tv_chambolle`` at the hindsight-best weight of a
log grid) and of DnCNN 6N and 17N at the true sigma, on the first device.

Writes ``<out>/dncnn_<machine>.json``, ``.md`` and ``.png``; ``<machine>`` names the GPU where
one was measured, else the CPU and the implementations.
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from clfza.benchmarks._machine import machine_record, machine_slug  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.cl import DeviceArray, get_runtime  # noqa: E402
from clfza.denoisers import DnCNNDevice, load_dncnn  # noqa: E402
from clfza.metrics import psnr, ssim  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
MATMUL_N = 2048
GPU_TARGET_MS = 10.0
CPU_TARGET_FRACTION = 0.40


def impl_tag(rt) -> str:
    """A short label of a device's implementation: intel, pocl31, nvidia, ..."""
    plat = rt.info.platform.lower()
    if "portable computing language" in plat:
        m = re.match(r"(\d+)\.(\d+)", rt.info.driver)
        return "pocl" + ("".join(m.groups()) if m else "")
    word = re.sub(r"\((r|tm)\)", "", plat).split()
    return re.sub(r"[^a-z0-9]+", "-", word[0] if word else "").strip("-") or "cl"


def matmul_gflops() -> float:
    rng = np.random.default_rng(0)
    a = rng.random((MATMUL_N, MATMUL_N), dtype=np.float32)
    b = rng.random((MATMUL_N, MATMUL_N), dtype=np.float32)
    t0 = time.perf_counter()
    a @ b
    return 2.0 * MATMUL_N ** 3 / (time.perf_counter() - t0) / 1e9


class Case:
    """One (device, size, variant): a resident denoiser and its device images."""

    def __init__(self, device: str, size: int, variant: str, kernel: str):
        self.rt = get_runtime(device)
        self.device, self.size, self.variant = device, size, variant
        self.net = DnCNNDevice(load_dncnn(variant), self.rt, kernel=kernel)
        rng = np.random.default_rng(1)
        self.x = np.clip(0.5 + 0.2 * rng.standard_normal((1, size, size)), 0, 1)
        self.net.buffers(1, size, size)
        self.img = DeviceArray.from_host(self.rt, self.x.astype(np.float32))
        self.out = DeviceArray.empty(self.rt, (1, size, size))
        self.flops = self.net.weights.flops(size, size)
        self.dev_t: list[float] = []
        self.host_t: list[float] = []
        self.net(self.x, 0.1)  # builds, allocates, warms
        self.device_call()

    def device_call(self) -> float:
        t0 = time.perf_counter()
        self.net.enqueue(self.img, self.out, 0.1)
        self.rt.finish()
        return time.perf_counter() - t0

    def host_call(self) -> float:
        t0 = time.perf_counter()
        self.net(self.x, 0.1)
        return time.perf_counter() - t0


def timing(devices, sizes, variants, rounds, kernel) -> tuple[list[dict], list[float]]:
    cases = [Case(d, s, v, kernel) for d in devices for s in sizes for v in variants]
    mm = []
    for _ in range(rounds):
        mm.append(matmul_gflops())
        for c in cases:
            c.dev_t.append(c.device_call())
            c.host_t.append(c.host_call())
    rows = []
    mm_med = statistics.median(mm)
    for c in cases:
        t = statistics.median(c.dev_t)
        g = c.flops / t / 1e9
        rows.append({
            "device": c.device, "device_name": c.rt.info.describe(), "impl": impl_tag(c.rt),
            "is_gpu": not c.rt.is_cpu, "kernel": c.net.kernel, "size": c.size,
            "variant": c.variant, "layers": c.net.layers, "gflop": c.flops / 1e9,
            "ms_device": 1e3 * t, "ms_host": 1e3 * statistics.median(c.host_t),
            "gflops": g, "fraction_of_matmul": g / mm_med,
            "ms_device_all": [1e3 * v for v in c.dev_t],
        })
    return rows, mm


def quality(device: str, sigmas, kernel: str) -> list[dict]:
    from skimage import data
    from skimage.restoration import denoise_tv_chambolle

    clean = data.camera()[::2, ::2].astype(np.float64) / 255.0
    rng = np.random.default_rng(0)
    nets = {v: DnCNNDevice(load_dncnn(v), get_runtime(device), kernel=kernel)
            for v in ("6N", "17N")}
    weights = np.geomspace(0.005, 1.0, 16)
    rows = []
    for s in sigmas:
        noisy = clean + s * rng.standard_normal(clean.shape)
        row = {"sigma": s, "noisy_psnr": psnr(noisy, clean, 1.0),
               "noisy_ssim": ssim(noisy, clean, 1.0)}
        tv = [(psnr(denoise_tv_chambolle(noisy, weight=w), clean, 1.0), w) for w in weights]
        best_p, best_w = max(tv)
        if best_w in (weights[0], weights[-1]):
            warnings.warn(f"TV's best weight {best_w:g} is at the end of the grid", stacklevel=2)
        row.update(tv_psnr=best_p, tv_weight=float(best_w),
                   tv_ssim=ssim(denoise_tv_chambolle(noisy, weight=best_w), clean, 1.0))
        for v, net in nets.items():
            out = net(noisy, s).astype(np.float64)
            row[f"dncnn{v}_psnr"] = psnr(out, clean, 1.0)
            row[f"dncnn{v}_ssim"] = ssim(out, clean, 1.0)
        rows.append(row)
    return rows


def markdown(res: dict) -> str:
    m = res["machine"]
    lines = [f"# DnCNN on OpenCL (issue 38): {res['label']}", "",
             f"Machine: {m['cpu_model']}, {m['cores_usable']} cores usable, load "
             f"{m['load_average']}; {m['date']}; clfza {res['commit']}.",
             f"Command: `{res['command']}`", "",
             f"numpy float32 matmul ({MATMUL_N}^2): median {res['matmul_gflops']:.1f} GFLOP/s "
             f"(rounds: {', '.join(f'{v:.1f}' for v in res['matmul_all'])}).", "",
             "| device | kernel | size | variant | GFLOP | ms/call (device) | ms/call (host) | "
             "GFLOP/s | of matmul |", "|---|---|---|---|---|---|---|---|---|"]
    for r in res["timing"]:
        lines.append(f"| {r['device']} {r['impl']} | {r['kernel']} | {r['size']}^2 | "
                     f"{r['variant']} | {r['gflop']:.1f} | {r['ms_device']:.1f} | "
                     f"{r['ms_host']:.1f} | {r['gflops']:.1f} | "
                     f"{100 * r['fraction_of_matmul']:.0f} % |")
    lines += ["", "Targets, 6-layer call at 512^2: CPU >= 40 % of the matmul rate; GPU <= 10 ms."]
    for t in res["targets"]:
        lines.append(f"- {t}")
    if res["quality"]:
        q = res["quality"]
        lines += ["", f"Denoising scikit-image's camera at 256^2 (Gaussian noise, seed 0) on "
                  f"{res['quality_device']}: PSNR dB (SSIM).", "",
                  "| sigma | noisy | TV (best weight) | DnCNN 6N | DnCNN 17N |",
                  "|---|---|---|---|---|"]
        for r in q:
            lines.append(
                f"| {r['sigma']:g} | {r['noisy_psnr']:.2f} ({r['noisy_ssim']:.3f}) | "
                f"{r['tv_psnr']:.2f} ({r['tv_ssim']:.3f}, w={r['tv_weight']:.3g}) | "
                f"{r['dncnn6N_psnr']:.2f} ({r['dncnn6N_ssim']:.3f}) | "
                f"{r['dncnn17N_psnr']:.2f} ({r['dncnn17N_ssim']:.3f}) |")
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2 if res["quality"] else 1, figsize=(12, 4.5), squeeze=False)
    ax = axes[0][0]
    rows = res["timing"]
    labels = [f"{r['impl']} {r['kernel']}\n{r['variant']} {r['size']}" for r in rows]
    ax.bar(range(len(rows)), [r["gflops"] for r in rows], color="tab:blue")
    ax.axhline(res["matmul_gflops"], color="k", ls="--", label="numpy float32 matmul")
    ax.axhline(CPU_TARGET_FRACTION * res["matmul_gflops"], color="tab:red", ls=":",
               label="40 % of it (CPU target)")
    ax.set_xticks(range(len(rows)), labels, fontsize=7)
    ax.set_ylabel("GFLOP/s (device time)")
    ax.set_title("DnCNN call, median over rounds")
    ax.legend(fontsize=8)
    if res["quality"]:
        ax = axes[0][1]
        q = res["quality"]
        s = [r["sigma"] for r in q]
        for key, lab in (("noisy_psnr", "noisy"), ("tv_psnr", "TV, best weight"),
                         ("dncnn6N_psnr", "DnCNN 6N"), ("dncnn17N_psnr", "DnCNN 17N")):
            ax.plot(s, [r[key] for r in q], "o-", label=lab)
        ax.set_xscale("log")
        ax.set_xlabel("noise sigma (image in [0, 1])")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title("camera 256^2")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def targets(rows: list[dict]) -> list[str]:
    out = []
    for r in rows:
        if r["layers"] != 6 or r["size"] != 512:
            continue
        if r["is_gpu"]:
            ok = r["ms_device"] <= GPU_TARGET_MS
            out.append(f"{r['device']} {r['impl']} ({r['kernel']}): {r['ms_device']:.1f} ms "
                       f"(target <= {GPU_TARGET_MS:g} ms): {'met' if ok else 'NOT met'}")
        else:
            ok = r["fraction_of_matmul"] >= CPU_TARGET_FRACTION
            out.append(f"{r['device']} {r['impl']} ({r['kernel']}): "
                       f"{100 * r['fraction_of_matmul']:.0f} % of the matmul rate (target >= "
                       f"40 %): {'met' if ok else 'NOT met'}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", nargs="+", default=None,
                    help="OpenCL device(s) P:D (default: the default device)")
    ap.add_argument("--sizes", nargs="+", type=int, default=[256, 512])
    ap.add_argument("--variants", nargs="+", default=["6N", "17N"])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--kernel", default="auto", choices=["auto", "cpu", "tiled"])
    ap.add_argument("--sigmas", nargs="+", type=float, default=[0.02, 0.05, 0.1, 0.2])
    ap.add_argument("--no-quality", action="store_true")
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    devices = args.device or [get_runtime().info.index]
    rows, mm = timing(devices, args.sizes, args.variants, args.rounds, args.kernel)
    for r in rows:
        print(f"{r['device']} {r['impl']:8s} {r['kernel']:5s} {r['size']}^2 {r['variant']:3s} "
              f"{r['ms_device']:9.2f} ms (host {r['ms_host']:9.2f}) {r['gflops']:8.1f} GFLOP/s "
              f"= {100 * r['fraction_of_matmul']:.0f} % of matmul", flush=True)
    print(f"numpy float32 matmul: {statistics.median(mm):.1f} GFLOP/s", flush=True)
    q = [] if args.no_quality else quality(devices[0], args.sigmas, args.kernel)
    for r in q:
        print(f"sigma {r['sigma']:g}: noisy {r['noisy_psnr']:.2f} TV {r['tv_psnr']:.2f} "
              f"6N {r['dncnn6N_psnr']:.2f} 17N {r['dncnn17N_psnr']:.2f} dB", flush=True)
    machine = machine_record(devices[0])
    gpus = [r for r in rows if r["is_gpu"]]
    if gpus:
        name = get_runtime(gpus[0]["device"]).info.name
        label = re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-") + "_gpu"
    else:
        label = machine_slug(machine) + "_" + "-".join(dict.fromkeys(r["impl"] for r in rows))
    try:
        import subprocess

        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, cwd=Path(__file__).parent).stdout.strip() or "?"
    except OSError:
        commit = "?"
    res = {"label": label, "machine": machine, "commit": commit,
           "command": "python bench/bench_dncnn.py " + " ".join(sys.argv[1:] if argv is None
                                                                else argv),
           "matmul_gflops": statistics.median(mm), "matmul_all": mm, "timing": rows,
           "targets": targets(rows), "quality": q, "quality_device": devices[0]}
    for t in res["targets"]:
        print(t)
    paths = write_result_files(Path(args.out) / f"dncnn_{label}", res, markdown(res), plot)
    print("wrote", ", ".join(str(p) for p in paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
