"""Issue 38: the DnCNN denoiser on OpenCL: time per call, FLOP rate, and denoising PSNR.

Usage::

    python bench/bench_dncnn.py [--device P:D [P:D ...]] [--sizes 256 512]
                                [--variants 6N 17N] [--rounds 3] [--kernel auto [...]]
                                [--pixels 4 [...]]
                                [--sigmas 0.02 0.05 0.1 0.2] [--no-quality] [--out bench/results]

Per device (default: the default device; several in one run are interleaved round by round,
so their ratios come from the same minutes of a shared machine), per image size and variant
(6 and 17 layers):

* **ms/call (device)**: every layer queued on images already on the device, until the queue
  drains: the denoiser's cost inside a solver whose iterate lives there;
* **ms/call (host)**: the same with the image copied in and the result read back;
* **GFLOP/s**: the network's FLOPs (two per multiply-add of the convolutions,
  :meth:`clfza.denoisers.DnCNNWeights.flops`) over the device time;
* **numpy's float32 matrix multiply** (2048^2 @ 2048^2, BLAS) in GFLOP/s, the better of two
  products measured right before each call, and the ratio of each call's rate to it (median
  over rounds): the issue's CPU target is >= 40 % for a 6-layer call at 512^2; its GPU target
  is <= 10 ms per 6-layer call at 512^2.

Every figure is a median over ``--rounds``. Which 64 -> 64 kernel ran (``cpu``: vectorised
over output channels; ``tiled``: through local memory) is recorded; ``--kernel auto`` chooses
by the device's kind.

Quality (skip with ``--no-quality``): scikit-image's camera at 256^2 in [0, 1] plus Gaussian
noise at each ``--sigmas`` (seed 0), clipped to [0, 1] as the networks' training images were
(``--no-clip``: unclipped; the noise-conditional networks then lose up to 3 dB at sigma 0.2):
PSNR and SSIM of the noisy image, of TV
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
from clfza.denoisers._opencl import CPU_PIXELS  # noqa: E402
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

    def __init__(self, device: str, size: int, variant: str, kernel: str, pixels: int):
        self.rt = get_runtime(device)
        self.device, self.size, self.variant = device, size, variant
        self.net = DnCNNDevice(load_dncnn(variant), self.rt, kernel=kernel, pixels=pixels)
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


def timing(devices, sizes, variants, rounds, kernels=("auto",), pixels=(CPU_PIXELS,)
           ) -> tuple[list[dict], list[float]]:
    """Round by round, each case's call right after the matmul rate it is compared with (the
    better of two products: the machine's rate at that moment, on a shared machine)."""
    cases = [Case(d, s, v, k, px) for d in devices for s in sizes for v in variants
             for k in kernels for px in pixels]
    mm = []
    ratio: dict[int, list[float]] = {i: [] for i in range(len(cases))}
    for _ in range(rounds):
        for i, c in enumerate(cases):
            m = max(matmul_gflops(), matmul_gflops())
            mm.append(m)
            t = c.device_call()
            c.dev_t.append(t)
            ratio[i].append(c.flops / t / 1e9 / m)
            c.host_t.append(c.host_call())
    rows = []
    for i, c in enumerate(cases):
        t = statistics.median(c.dev_t)
        g = c.flops / t / 1e9
        rows.append({
            "device": c.device, "device_name": c.rt.info.describe(), "impl": impl_tag(c.rt),
            "is_gpu": not c.rt.is_cpu, "kernel": c.net.kernel, "size": c.size,
            "pixels": c.net.pixels if c.net.kernel == "cpu" else None,
            "variant": c.variant, "layers": c.net.layers, "gflop": c.flops / 1e9,
            "ms_device": 1e3 * t, "ms_host": 1e3 * statistics.median(c.host_t),
            "gflops": g, "fraction_of_matmul": statistics.median(ratio[i]),
            "ms_device_all": [1e3 * v for v in c.dev_t],
            "fraction_of_matmul_all": ratio[i],
        })
    return rows, mm


def quality(device: str, sigmas, kernel: str, clip: bool = True) -> list[dict]:
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
        if clip:
            noisy = np.clip(noisy, 0.0, 1.0)
        row = {"sigma": s, "clipped": clip, "noisy_psnr": psnr(noisy, clean, 1.0),
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


def pnp(device: str, n: int, iters: int) -> dict:
    """Plug-and-play ADMM (reg="dncnn") against ADMM-TV on the paper's Fig. 7 simulation
    (bench_solvers' camera at n^2, scikit-image's camera scene, Gaussian noise of variance
    0.01), PSNR after the affine fit (clfza.metrics.compare) of the returned image: TV at the
    hindsight-best tau of a log grid and tau="auto"; PnP over tau, rho and rho's growth."""
    from skimage import data, transform

    import clfza
    import clfza.solvers._pnp as pnp_module
    from clfza.metrics import compare

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_solvers import camera

    cam = camera(n)
    scene = transform.resize(data.camera().astype(float) / 255, (n, n), anti_aliasing=True)
    m = clfza.simulate(scene, cam, noise=clfza.Noise(gaussian_var=0.01))

    def score(r):
        return round(compare(r.image, m.truth)["psnr"], 2)

    out = {"size": n, "iters": iters, "tv": [], "pnp": []}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = clfza.reconstruct(m.y, cam, "admm", model="tf", iters=200, device=device)
        out["tv_auto"] = {"tau": r.info.params["tau"], "psnr": score(r)}
        for tau in np.geomspace(0.003, 1.0, 8):
            r = clfza.reconstruct(m.y, cam, "admm", model="tf", iters=200, tau=float(tau),
                                  device=device)
            out["tv"].append({"tau": float(tau), "psnr": score(r)})
        keep = pnp_module.PNP_RHO_GROWTH
        try:
            for growth in (1.0, 1.1):
                pnp_module.PNP_RHO_GROWTH = growth
                for rho in (0.1, 1.0):
                    for tau in (1e-3, 3e-3, 1e-2, 3e-2):
                        t0 = time.perf_counter()
                        r = clfza.reconstruct(m.y, cam, "admm", model="tf", reg="dncnn",
                                              tau=tau, rho=rho, iters=iters, stop="none",
                                              device=device)
                        row = {"growth": growth, "rho": rho, "tau": tau, "psnr": score(r),
                               "sigma_first": r.info.stats["sigma_first"],
                               "s": time.perf_counter() - t0}
                        out["pnp"].append(row)
                        print("pnp", row, flush=True)
        finally:
            pnp_module.PNP_RHO_GROWTH = keep
    out["tv_best"] = max(out["tv"], key=lambda r: r["psnr"])
    out["pnp_best"] = max(out["pnp"], key=lambda r: r["psnr"])
    return out


def markdown(res: dict) -> str:
    m = res["machine"]
    lines = [f"# DnCNN on OpenCL (issue 38): {res['label']}", "",
             f"Machine: {m['cpu_model']}, {m['cores_usable']} cores usable, load "
             f"{m['load_average']}; {m['date']}; clfza {res['commit']}.",
             f"Command: `{res['command']}`", "",
             f"numpy float32 matmul ({MATMUL_N}^2, the better of two right before each call): "
             f"median {res['matmul_gflops']:.1f} GFLOP/s, range "
             f"{min(res['matmul_all']):.1f}-{max(res['matmul_all']):.1f}; 'of matmul' is the "
             f"median over rounds of each call's rate over the one measured just before it.",
             "",
             "| device | kernel (pixels) | size | variant | GFLOP | ms/call (device) | "
             "ms/call (host) | GFLOP/s | of matmul |", "|---|---|---|---|---|---|---|---|---|"]
    for r in res["timing"]:
        px = f" ({r['pixels']})" if r.get("pixels") else ""
        lines.append(f"| {r['device']} {r['impl']} | {r['kernel']}{px} | {r['size']}^2 | "
                     f"{r['variant']} | {r['gflop']:.1f} | {r['ms_device']:.1f} | "
                     f"{r['ms_host']:.1f} | {r['gflops']:.1f} | "
                     f"{100 * r['fraction_of_matmul']:.0f} % |")
    lines += ["", "Targets, 6-layer call at 512^2: CPU >= 40 % of the matmul rate; GPU <= 10 ms."]
    for t in res["targets"]:
        lines.append(f"- {t}")
    if res["quality"]:
        q = res["quality"]
        clip = "clipped to [0, 1]" if q[0].get("clipped") else "unclipped"
        lines += ["", f"Denoising scikit-image's camera at 256^2 (Gaussian noise, seed 0, {clip})"
                  f" on {res['quality_device']}: PSNR dB (SSIM).", "",
                  "| sigma | noisy | TV (best weight) | DnCNN 6N | DnCNN 17N |",
                  "|---|---|---|---|---|"]
        for r in q:
            lines.append(
                f"| {r['sigma']:g} | {r['noisy_psnr']:.2f} ({r['noisy_ssim']:.3f}) | "
                f"{r['tv_psnr']:.2f} ({r['tv_ssim']:.3f}, w={r['tv_weight']:.3g}) | "
                f"{r['dncnn6N_psnr']:.2f} ({r['dncnn6N_ssim']:.3f}) | "
                f"{r['dncnn17N_psnr']:.2f} ({r['dncnn17N_ssim']:.3f}) |")
    if res.get("pnp"):
        p = res["pnp"]
        lines += ["", f"Plug-and-play ADMM (reg='dncnn', 6N, {p['iters']} iterations) against "
                  f"ADMM-TV (200 iterations) on the Fig. 7 simulation at {p['size']}^2 "
                  "(camera scene, noise variance 0.01), PSNR dB after the affine fit:", "",
                  f"- TV, tau='auto' ({p['tv_auto']['tau']:.3g}): {p['tv_auto']['psnr']}; "
                  f"hindsight-best tau {p['tv_best']['tau']:.3g}: {p['tv_best']['psnr']}",
                  f"- PnP best: {p['pnp_best']['psnr']} (tau {p['pnp_best']['tau']:g}, rho "
                  f"{p['pnp_best']['rho']:g}, growth {p['pnp_best']['growth']:g})", "",
                  "| rho growth | rho | tau | sigma (first) | PSNR | s |",
                  "|---|---|---|---|---|---|"]
        for r in p["pnp"]:
            lines.append(f"| {r['growth']:g} | {r['rho']:g} | {r['tau']:g} | "
                         f"{r['sigma_first']:.3g} | {r['psnr']} | {r['s']:.1f} |")
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2 if res["quality"] else 1, figsize=(12, 4.5), squeeze=False)
    ax = axes[0][0]
    rows = res["timing"]
    labels = [f"{r['impl']} {r['kernel']}{r.get('pixels') or ''}\n{r['variant']} {r['size']}"
              for r in rows]
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
    ap.add_argument("--kernel", nargs="+", default=["auto"], choices=["auto", "cpu", "tiled"],
                    help="the 64 -> 64 layers' kernel(s) (several: compared in one run)")
    ap.add_argument("--pixels", nargs="+", type=int, default=[CPU_PIXELS],
                    help="the CPU kernel's pixels per work-item (several: compared in one run)")
    ap.add_argument("--sigmas", nargs="+", type=float, default=[0.02, 0.05, 0.1, 0.2])
    ap.add_argument("--no-quality", action="store_true")
    ap.add_argument("--no-clip", action="store_true", help="quality: unclipped noisy images")
    ap.add_argument("--pnp", type=int, default=0, metavar="N",
                    help="also plug-and-play ADMM against ADMM-TV on the Fig. 7 simulation at "
                         "N^2 (first device)")
    ap.add_argument("--pnp-iters", type=int, default=60)
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    devices = args.device or [get_runtime().info.index]
    rows, mm = timing(devices, args.sizes, args.variants, args.rounds, args.kernel,
                      args.pixels)
    quality_kernel = args.kernel[0]
    for r in rows:
        print(f"{r['device']} {r['impl']:8s} {r['kernel']:5s} px {r['pixels']} {r['size']}^2 "
              f"{r['variant']:3s} "
              f"{r['ms_device']:9.2f} ms (host {r['ms_host']:9.2f}) {r['gflops']:8.1f} GFLOP/s "
              f"= {100 * r['fraction_of_matmul']:.0f} % of matmul", flush=True)
    print(f"numpy float32 matmul: {statistics.median(mm):.1f} GFLOP/s", flush=True)
    q = []
    if not args.no_quality:
        try:
            q = quality(devices[0], args.sigmas, quality_kernel, clip=not args.no_clip)
        except ImportError as exc:  # a bare GPU machine: the timings still count
            print(f"quality skipped: {exc}", flush=True)
    for r in q:
        print(f"sigma {r['sigma']:g}: noisy {r['noisy_psnr']:.2f} TV {r['tv_psnr']:.2f} "
              f"6N {r['dncnn6N_psnr']:.2f} 17N {r['dncnn17N_psnr']:.2f} dB", flush=True)
    pnp_res = pnp(devices[0], args.pnp, args.pnp_iters) if args.pnp else None
    machine = machine_record(devices[0])
    gpus = [r for r in rows if r["is_gpu"]]
    if gpus:
        name = get_runtime(gpus[0]["device"]).info.name
        label = re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-") + "_gpu"
    else:
        label = machine_slug(machine) + "_" + "-".join(dict.fromkeys(r["impl"] for r in rows))
    if args.kernel != ["auto"]:
        label += "_" + "-".join(args.kernel) + "-kernel"
    if args.pixels != [CPU_PIXELS]:
        label += "_pixels"
    if args.pnp:
        label += "_pnp"
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
           "targets": targets(rows), "quality": q, "quality_device": devices[0],
           "pnp": pnp_res}
    for t in res["targets"]:
        print(t)
    def plot_or_skip(result, path):
        try:
            plot(result, path)
        except ImportError as exc:
            print(f"no plot: {exc}", flush=True)

    paths = write_result_files(Path(args.out) / f"dncnn_{label}", res, markdown(res),
                               plot_or_skip)
    print("wrote", ", ".join(str(p) for p in paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
