"""Issue 38: the DnCNN denoiser on OpenCL: time per call, FLOP rate, and denoising PSNR.

Usage::

    python bench/bench_dncnn.py [--device P:D [P:D ...]] [--sizes 256 512]
                                [--variants 6N 17N] [--rounds 3] [--kernel auto [...]]
                                [--pixels 4 [...]]
                                [--sigmas 0.02 0.05 0.1 0.2] [--no-quality] [--out bench/results]
    python bench/bench_dncnn.py --quality-pnp 128 [--scenes natural text usaf face]
                                [--noises none gauss0.01 poisson1e7] [--device P:D]
                                [--pnp-variants 6N [17N]] [--tag TAG]
    python bench/bench_dncnn.py --quality-exact 160 [--scenes ...] [--noises ...]
    python bench/bench_dncnn.py --quality-levers 128 [--levers default 17N iters30 ...]
                                [--select natural text]
    python bench/bench_dncnn.py --solve-time 256 --device 0:0 1:0 2:0 [--rounds 3]
    python bench/bench_dncnn.py --quality-psf 96 [--psf-scenes camera face]
                                [--photons 2000 20000] [--exact-ratios 1 3 10]
                                [--cg-iters 5 10 40]

``--quality-pnp N`` runs only issue 38's quality benchmark (:func:`quality_pnp`): reg='dncnn'
against ADMM-TV at its hindsight-best tau, 4 scenes x 3 noises on the simulation preset at
N^2; it writes ``<out>/dncnn_quality_<machine>_<impl>_<N>[_<tag>].json``, ``.md`` and
``.png``. Its second table is reg='dncnn' at the ``tau`` ADMM-TV's ``tau="auto"`` picks against
its hindsight-best tau of the same grid (issue 38: the case for and against ``tau="auto"``).

``--quality-exact N`` runs only :func:`quality_exact`: the same 4 scenes x 3 noises on
``Camera.preset("experiment")`` binned to N^2 through the exact model (reg='dncnn' against the
crop-split ADMM-TV at its hindsight-best tau); it writes
``<out>/dncnn_quality_experiment_<machine>_<impl>_<N>[_<tag>].*``.

``--quality-levers N`` runs only :func:`quality_levers`: reg='dncnn' at ADMM-TV's
hindsight-best tau with each lever of ``--levers`` (17N, PNP_ITERS, the sigma schedule,
PNP_TAU_PER_TV), chosen on ``--select`` scenes, the others held out; it writes
``<out>/dncnn_quality_levers_<machine>_<impl>_<N>[_<tag>].*``.

``--solve-time N`` runs only :func:`solve_time`: seconds per reg='dncnn' solve (and per
ADMM-TV solve) at N^2 on each ``--device``, interleaved over ``--rounds``, with the load
average; it writes ``<out>/dncnn_solve_<machine>_<impls>_<N>[_<tag>].*``.

``--quality-psf N`` runs only :func:`quality_psf`: reg='dncnn' on the exact model with a
measured PSF against the crop-split ADMM-TV at the same tau; it writes
``<out>/dncnn_quality_psf_<machine>_<impl>_<N>[_<tag>].*``.

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
import functools
import json
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


def noise_sigma(y: np.ndarray) -> float:
    """The frame's white-noise standard deviation from the finest Haar diagonal band (MAD)."""
    hh = (y[0::2, 0::2] - y[0::2, 1::2] - y[1::2, 0::2] + y[1::2, 1::2]) / 2.0
    return float(np.median(np.abs(hh)) / 0.6745)


def scene_frame(name: str, noise: str, cam, width: float) -> tuple[np.ndarray, np.ndarray]:
    """The quality benchmarks' frame and truth: a built-in scene of clfza.benchmarks, or
    ``"face"`` (scikit-image's astronaut in grey), simulated on ``cam`` at a noise of
    clfza.benchmarks' NOISES."""
    from skimage import color, data

    import clfza
    from clfza.benchmarks import _scenes as scenes_mod
    from clfza.benchmarks._timeerror import NOISES

    if name == "face":
        m = clfza.simulate(color.rgb2gray(data.astronaut()), cam, object_width=width,
                           noise=NOISES[noise])
    else:
        m = scenes_mod.measurement(name, cam, NOISES[noise]).measurement
    return m.y, m.truth


def score(img: np.ndarray, truth: np.ndarray) -> dict:
    """PSNR and SSIM after the affine fit (clfza.metrics.compare), rounded for the tables."""
    from clfza.metrics import compare

    c = compare(img, truth)
    return {"psnr": round(c["psnr"], 2), "ssim": round(c["ssim"], 4)}


def quality_pnp(device: str, n: int, scenes, noises, variants=("6N",)) -> dict:
    """Issue 38's quality benchmark, scaled: each scene x noise on the simulation preset at
    n^2 (bench_solvers' camera: the Eq. 17 transfer-function model; the exact model and
    measured PSFs: :func:`quality_psf`). ADMM-TV (200 iterations) at tau='auto' and over the grid
    tau_auto x {1/4 .. 16} (hindsight-best: the grid's best PSNR); reg='dncnn' with its
    defaults (its TV pre-solve from the Wiener start, then the denoiser) over the same taus
    (``pnp_grid``; ``pnp``: at the tau TV's tau='auto' chose and at TV's hindsight-best tau)
    and ``pnp_auto``: what tau='auto' by TV's rule in the pre-solve gives (PnP at the tau TV's
    tau='auto' chose), per variant. PSNR/SSIM
    after the affine fit (clfza.metrics.compare)."""

    import clfza

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_solvers import camera

    cam = camera(n)
    width = 0.6 * cam.shape[1] * cam.pitch / (cam.magnification or 1.0)
    rows = []
    for name in scenes:
        for nk in noises:
            y, truth = scene_frame(name, nk, cam, width)
            sc = functools.partial(score, truth=truth)

            row = {"scene": name, "noise": nk}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = clfza.reconstruct(y, cam, "admm", model="tf", iters=200, device=device)
                ta = float(r.info.params["tau"])
                row["tv_auto"] = {"tau": ta, **sc(r.image)}
                grid = []
                best = None
                for f in (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0):
                    img = clfza.reconstruct(y, cam, "admm", model="tf", iters=200, tau=ta * f,
                                            device=device).image
                    q = {"tau": ta * f, "factor": f, **sc(img)}
                    grid.append(q)
                    if best is None or q["psnr"] > best["psnr"]:
                        best = q
                row["tv_grid"], row["tv_best"] = grid, best
                row["sigma_n"] = noise_sigma(y)
                row["pnp"], row["pnp_grid"], row["pnp_auto"] = [], [], []
                for variant in variants:
                    for g in grid:  # the same taus as TV's grid: PnP's hindsight-best tau
                        t0 = time.perf_counter()
                        p = clfza.reconstruct(y, cam, "admm", model="tf", reg="dncnn",
                                              tau=g["tau"], denoiser=variant, device=device)
                        q = {"variant": variant, "tau": g["tau"], "factor": g["factor"],
                             **sc(p.image), "iters": p.info.iterations,
                             "tv_iters": p.info.stats["tv_presolve_iters"],
                             "s": time.perf_counter() - t0}
                        row["pnp_grid"].append(q)
                        for start, f in (("tv_auto", 1.0), ("tv_best", best["factor"])):
                            if g["factor"] == f:
                                row["pnp"].append({"start": start, **q})
                    # tau='auto' by ADMM-TV's rule in the pre-solve (refused for reg='dncnn':
                    # this table is why) is PnP at the tau TV's tau='auto' chose: factor 1
                    a = next(q for q in row["pnp_grid"] if q["variant"] == variant
                             and q["factor"] == 1.0)
                    row["pnp_auto"].append({**a, "rule": "tv_auto_tau"})
            print(json.dumps(row), flush=True)
            rows.append(row)
    return {"size": n, "device": device, "variants": list(variants), "rows": rows}


def quality_markdown(res: dict) -> str:
    import clfza.solvers._pnp as pnp

    q = res["quality_pnp"]
    m = res["machine"]
    lines = [f"# DnCNN plug-and-play quality (issue 38): {res['label']}", "",
             f"Machine: {m['cpu_model']}, {m['cores_usable']} cores usable, load "
             f"{m['load_average']}; {m['date']}; clfza {res['commit']}; device {q['device']}.",
             f"Command: `{res['command']}`", "",
             f"Simulation preset at {q['size']}^2 (bench_solvers' camera; the Eq. 17 "
             "transfer-function model; the exact model: --quality-psf). PSNR dB "
             "(SSIM) after the affine fit. TV: ADMM-TV, 200 iterations, tau='auto' and the "
             "hindsight-best of tau_auto x {1/4 .. 16}. PnP: reg='dncnn' with its defaults (a "
             "200-iteration ADMM-TV pre-solve at tau from the Wiener start, then half-quadratic "
             f"splitting with DnCNN, sigma {pnp.PNP_SIGMA_MAX:g} -> {pnp.PNP_SIGMA_MIN:g} over "
             f"{pnp.PNP_ITERS} iterations, tau' = {pnp.PNP_TAU_PER_TV:g} tau) at "
             "TV-auto's tau and at TV's hindsight-best tau, the variant(s) "
             f"{q['variants']} (the better shown). delta: PnP at the best tau minus TV at it.",
             "", "| scene | noise | TV auto | TV best (tau/auto) | PnP at auto's tau | "
             "PnP at best tau | delta |", "|---|---|---|---|---|---|---|"]
    deltas = []
    for r in q["rows"]:
        def best_of(start, r=r):
            c = [p for p in r["pnp"] if p["start"] == start]
            return max(c, key=lambda p: p["psnr"])

        def f(d):
            return f"{d['psnr']:.2f} ({d['ssim']:.3f})"
        pb = best_of("tv_best")
        d = pb["psnr"] - r["tv_best"]["psnr"]
        deltas.append((r["scene"], r["noise"], d))
        v = f" {pb['variant']}" if len(q["variants"]) > 1 else ""
        lines.append(f"| {r['scene']} | {r['noise']} | {f(r['tv_auto'])} | {f(r['tv_best'])} "
                     f"x{r['tv_best']['factor']:g} | {f(best_of('tv_auto'))} | "
                     f"{f(pb)}{v} | {d:+.2f} |")
    nat = [d for s, nz, d in deltas if s == "natural" and nz == "gauss0.01"]
    worst = min(deltas, key=lambda t: t[2])
    lines += ["", "Targets (issue 38): natural scene at Fig. 7 noise >= +1.5 dB over best-tau "
              f"TV: {nat[0]:+.2f} dB ({'met' if nat and nat[0] >= 1.5 else 'NOT met'}; "
              "with the hindsight-best TV as PnP's start); never worse than TV by > 0.5 dB: "
              f"worst {worst[2]:+.2f} dB ({worst[0]}, {worst[1]}): "
              f"{'met' if worst[2] >= -0.5 else 'NOT met'}."]
    if q["rows"] and q["rows"][0].get("pnp_auto"):
        lines += auto_markdown(q)
    return "\n".join(lines) + "\n"


def auto_summary(q: dict, variant: str) -> dict:
    """tau='auto' of reg='dncnn' (``variant``) per row: its gap to the PnP grid's best tau,
    PnP(auto) - TV(auto), and TV's own gap; means and worsts."""
    rows = []
    for r in q["rows"]:
        a = next(p for p in r["pnp_auto"] if p["variant"] == variant)
        g = [p for p in r["pnp_grid"] if p["variant"] == variant]
        b = max(g, key=lambda p: p["psnr"])
        rows.append({"scene": r["scene"], "noise": r["noise"], "auto": a, "best": b,
                     "gap": b["psnr"] - a["psnr"], "vs_tv_auto": a["psnr"] - r["tv_auto"]["psnr"],
                     "tv_gap": r["tv_best"]["psnr"] - r["tv_auto"]["psnr"]})
    gaps = [x["gap"] for x in rows]
    tvg = [x["tv_gap"] for x in rows]
    vs = [x["vs_tv_auto"] for x in rows]
    return {"variant": variant, "rows": rows, "gap_mean": float(np.mean(gaps)),
            "gap_worst": float(max(gaps)), "tv_gap_mean": float(np.mean(tvg)),
            "tv_gap_worst": float(max(tvg)), "vs_tv_auto_mean": float(np.mean(vs)),
            "vs_tv_auto_worst": float(min(vs))}


def auto_markdown(q: dict) -> list[str]:
    lines = ["", "## tau='auto' for reg='dncnn'", "",
             "reg='dncnn' with tau='auto' by ADMM-TV's own rule in the TV pre-solve, tau' = "
             "0.03 x the chosen tau: PnP at TV-auto's tau (a run with that rule, commit "
             "4f18eb5, gave the same PSNR in every row). gap: PnP at its hindsight-best tau of the "
             "grid tau_auto(TV) "
             "x {1/4 .. 16} minus PnP(auto) (a best at the grid's edge (x1/4, x16) is a lower "
             "bound of the gap); TV gap: the same for ADMM-TV; PnP(auto) - TV(auto).", "",
             "| scene | noise | variant | tau auto | PnP auto | PnP best (x) | gap | TV gap | "
             "PnP(auto) - TV(auto) |", "|---|---|---|---|---|---|---|---|---|"]
    for v in q["variants"]:
        a = auto_summary(q, v)
        for x in a["rows"]:
            lines.append(f"| {x['scene']} | {x['noise']} | {v} | {x['auto']['tau']:.3g} | "
                         f"{x['auto']['psnr']:.2f} | {x['best']['psnr']:.2f} "
                         f"(x{x['best']['factor']:g}) | {x['gap']:.2f} | {x['tv_gap']:.2f} | "
                         f"{x['vs_tv_auto']:+.2f} |")
        ok = a["gap_mean"] <= 1.0 and a["gap_worst"] <= 3.0
        lines += ["", f"{v}: gap mean {a['gap_mean']:.2f} dB, worst {a['gap_worst']:.2f} dB "
                  f"(issue 33's target for tau='auto': mean <= 1, worst <= 3: "
                  f"{'met' if ok else 'NOT met'}); ADMM-TV's tau='auto' on the same rows: mean "
                  f"{a['tv_gap_mean']:.2f}, worst {a['tv_gap_worst']:.2f} dB; PnP(auto) - "
                  f"TV(auto): mean {a['vs_tv_auto_mean']:+.2f}, worst "
                  f"{a['vs_tv_auto_worst']:+.2f} dB.", ""]
    return lines


def quality_plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["quality_pnp"]["rows"]
    labels = [f"{r['scene']}\n{r['noise']}" for r in rows]
    series = [("TV auto", [r["tv_auto"]["psnr"] for r in rows]),
              ("TV best tau", [r["tv_best"]["psnr"] for r in rows])]
    for start, lab in (("tv_auto", "PnP at auto's tau"), ("tv_best", "PnP at best tau")):
        series.append((lab, [max(p["psnr"] for p in r["pnp"] if p["start"] == start)
                             for r in rows]))
    if rows and rows[0].get("pnp_auto"):
        series.append(("PnP tau='auto'", [max(p["psnr"] for p in r["pnp_auto"]) for r in rows]))
        series.append(("PnP own best tau", [max(p["psnr"] for p in r["pnp_grid"])
                                            for r in rows]))
    fig, ax = plt.subplots(figsize=(13, 4.5))
    w = 0.8 / len(series)
    for i, (lab, v) in enumerate(series):
        ax.bar(np.arange(len(rows)) + i * w, v, w, label=lab)
    ax.set_xticks(np.arange(len(rows)) + 0.4 - w / 2, labels, fontsize=7)
    ax.set_ylabel("PSNR (dB, affine fit)")
    ax.set_title(f"reg='dncnn' against ADMM-TV, simulation preset "
                 f"{res['quality_pnp']['size']}^2")
    ax.legend(fontsize=7, ncol=5)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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


def git_commit() -> str:
    import subprocess

    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=Path(__file__).parent).stdout.strip() or "?"
    except OSError:
        return "?"


PSF_TAUS = (1e-4, 3e-4, 1e-3, 3e-3, 1e-2)


def quality_psf(device: str, n: int, scenes, photons, ratios, cg_iters=(None,)) -> dict:
    """reg='dncnn' on the exact model with a measured PSF against the crop-split ADMM-TV at
    the same tau: clfza.simulation.simulate_psf_capture of each scene at n^2 (scene and PSF
    at 400 mm, tests/test_tau_psf.py's sensor: read noise 2, 8 bits, exposure 0.9, at each
    photon count), the PSF through clfza.models.load_psf; tau over PSF_TAUS; PnP at each
    tau' / tau of ``ratios`` (PnpExactSolver.tau_per_tv) and, when several are given, each
    CG length of ``cg_iters`` (clfza.solvers._pnp.PNP_CG_ITERS; None: the default).
    PSNR/SSIM after the affine fit."""
    from skimage import color, data

    import clfza
    import clfza.solvers._pnp as pnp
    from clfza.metrics import compare
    from clfza.models import load_psf
    from clfza.simulation import Noise, simulate_psf_capture
    from clfza.solvers._pnp import PnpExactSolver

    images = {"camera": data.camera, "face": lambda: color.rgb2gray(data.astronaut()),
              "text": data.text, "coffee": lambda: color.rgb2gray(data.coffee())}
    default, default_cg = PnpExactSolver.tau_per_tv, pnp.PNP_CG_ITERS
    keys = [(r, c, f"{r:g}" if len(cg_iters) == 1 else f"{r:g}/cg{c or default_cg}")
            for r in ratios for c in cg_iters]
    rows = []
    try:
        for name in scenes:
            for ph in photons:
                noise = Noise(photons=ph, read_noise=2.0, bit_depth=8, exposure=0.9, seed=1)
                cap = simulate_psf_capture(images[name](), shape=(n, n), scene_z1=400.0,
                                           psf_z1=400.0, noise=noise)
                psf = load_psf(cap.psf, background="border", center="centroid")
                for tau in PSF_TAUS:
                    row = {"scene": name, "photons": ph, "tau": tau, "pnp": {}}
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        t0 = time.perf_counter()
                        tv = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, tau=tau,
                                               device=device)
                        c = compare(tv.image, cap.truth)
                        row["tv"] = {"psnr": round(c["psnr"], 2), "ssim": round(c["ssim"], 4),
                                     "s": time.perf_counter() - t0}
                        for ratio, cg, key in keys:
                            PnpExactSolver.tau_per_tv = ratio
                            pnp.PNP_CG_ITERS = cg or default_cg
                            t0 = time.perf_counter()
                            p = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, tau=tau,
                                                  reg="dncnn", device=device)
                            c = compare(p.image, cap.truth)
                            row["pnp"][key] = {
                                "psnr": round(c["psnr"], 2), "ssim": round(c["ssim"], 4),
                                "cg_iters": p.info.stats["cg_iters"],
                                "s": time.perf_counter() - t0}
                    print(json.dumps(row), flush=True)
                    rows.append(row)
    finally:
        PnpExactSolver.tau_per_tv, pnp.PNP_CG_ITERS = default, default_cg
    return {"size": n, "device": device, "ratios": [k for _, _, k in keys],
            "default_ratio": f"{default:g}", "taus": list(PSF_TAUS), "rows": rows}


def psf_markdown(res: dict) -> str:
    q = res["quality_psf"]
    m = res["machine"]
    lines = [f"# DnCNN plug-and-play on a measured PSF (issue 38): {res['label']}", "",
             f"Machine: {m['cpu_model']}, {m['cores_usable']} cores usable, load "
             f"{m['load_average']}; {m['date']}; clfza {res['commit']}; device {q['device']}.",
             f"Command: `{res['command']}`", "",
             f"clfza.simulation.simulate_psf_capture at {q['size']}^2 (exact model, measured "
             "PSF). PSNR dB after the affine fit. TV: the crop-split ADMM-TV (its defaults) at "
             "tau; PnP: reg='dncnn' (the crop-split ADMM-TV pre-solve at tau, then HQS with "
             "DnCNN 6N and a CG x-update) at tau' = r tau for each r.", "",
             "| scene | photons | tau | TV | " + " | ".join(f"PnP r={r}" for r in q["ratios"])
             + " |", "|---|---|---|---|" + "---|" * len(q["ratios"])]
    for r in q["rows"]:
        lines.append(f"| {r['scene']} | {r['photons']:g} | {r['tau']:g} | {r['tv']['psnr']:.2f} | "
                     + " | ".join(f"{r['pnp'][k]['psnr']:.2f}" for k in q["ratios"]) + " |")
    lines += ["", "Per case (scene x photons): best over tau of TV and of PnP at each r, and "
              "PnP at TV's best tau minus TV there (mean over the taus of PnP - TV at the same "
              "tau in brackets).", "",
              "| scene | photons | TV best (tau) | " + " | ".join(
                  f"PnP r={r}: best / at TV's best tau - TV (mean same-tau delta)"
                  for r in q["ratios"]) + " |", "|---|---|---|" + "---|" * len(q["ratios"])]
    cases = {}
    for r in q["rows"]:
        cases.setdefault((r["scene"], r["photons"]), []).append(r)
    summary = {k: [] for k in q["ratios"]}
    for (name, ph), rs in cases.items():
        b = max(rs, key=lambda r: r["tv"]["psnr"])
        cells = []
        for k in q["ratios"]:
            best = max(r["pnp"][k]["psnr"] for r in rs)
            at = b["pnp"][k]["psnr"] - b["tv"]["psnr"]
            mean = float(np.mean([r["pnp"][k]["psnr"] - r["tv"]["psnr"] for r in rs]))
            summary[k].append((best - b["tv"]["psnr"], at, mean))
            cells.append(f"{best:.2f} / {at:+.2f} ({mean:+.2f})")
        lines.append(f"| {name} | {ph:g} | {b['tv']['psnr']:.2f} ({b['tau']:g}) | "
                     + " | ".join(cells) + " |")
    lines += [""]
    for k in q["ratios"]:
        v = np.array(summary[k])
        lines.append(f"- r={k}{' (default)' if k == q['default_ratio'] else ''}: best PnP - best "
                     f"TV mean {v[:, 0].mean():+.2f} dB (worst {v[:, 0].min():+.2f}); at TV's "
                     f"best tau mean {v[:, 1].mean():+.2f} (worst {v[:, 1].min():+.2f}); "
                     f"same-tau mean {v[:, 2].mean():+.2f}.")
    return "\n".join(lines) + "\n"


def psf_plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    q = res["quality_psf"]
    cases = {}
    for r in q["rows"]:
        cases.setdefault((r["scene"], r["photons"]), []).append(r)
    fig, axes = plt.subplots(1, len(cases), figsize=(4 * len(cases), 3.6), squeeze=False)
    for ax, ((name, ph), rs) in zip(axes[0], cases.items(), strict=True):
        taus = [r["tau"] for r in rs]
        ax.semilogx(taus, [r["tv"]["psnr"] for r in rs], "k-o", label="ADMM-TV")
        for k in q["ratios"]:
            ax.semilogx(taus, [r["pnp"][k]["psnr"] for r in rs], "-s", label=f"PnP r={k}")
        ax.set_title(f"{name}, {ph:g} photons", fontsize=9)
        ax.set_xlabel("tau")
    axes[0][0].set_ylabel("PSNR (dB, affine fit)")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main_psf(args, devices, argv) -> int:
    """``--quality-psf N``: reg='dncnn' on a measured PSF against ADMM-TV."""
    q = quality_psf(devices[0], args.quality_psf, args.psf_scenes, args.photons,
                    args.exact_ratios, args.cg_iters or (None,))
    machine = machine_record(devices[0])
    label = f"{machine_slug(machine)}_{impl_tag(get_runtime(devices[0]))}_{args.quality_psf}"
    if args.tag:
        label += f"_{args.tag}"
    res = {"label": label, "machine": machine, "commit": git_commit(),
           "command": "python bench/bench_dncnn.py " + " ".join(sys.argv[1:] if argv is None
                                                                else argv),
           "quality_psf": q}
    md = psf_markdown(res)
    print(md)
    paths = write_result_files(Path(args.out) / f"dncnn_quality_psf_{label}", res, md,
                               psf_plot)
    print("wrote", ", ".join(str(p) for p in paths))
    return 0


EXACT_TAUS = tuple(float(t) for t in 10.0 ** (np.arange(-8, 2) / 2))  # 1e-4 .. 3.16
EXACT_FINE = (10.0 ** -0.25, 10.0 ** 0.25)


def experiment_camera(n: int):
    """Camera.preset("experiment") (2400^2, 3.75 um) binned to n^2: the same sensor width at
    pitch 0.00375 x 2400 / n mm."""
    import clfza

    cam = clfza.Camera.preset("experiment")
    return cam.with_shape((n, n), cam.pitch * cam.shape[0] / n)


def quality_exact(device: str, n: int, scenes, noises, ratios=(None,)) -> dict:
    """Issue 38's quality benchmark on the experiment preset through the exact model
    (:class:`~clfza.solvers._pnp.PnpExactSolver` against the crop-split ADMM-TV, both with
    their defaults), binned to n^2 (:func:`experiment_camera`). ADMM-TV over EXACT_TAUS (a
    half-decade grid), refined by a quarter decade either side of its best (hindsight-best:
    the best PSNR); also ADMM-TV's tau='auto' (its reported tau does not reproduce its image
    when passed back, hence the fixed grid). reg='dncnn' at TV's hindsight-best tau and half
    a decade either side (PnP's own best of the three), for each tau'/tau of ``ratios``
    (PnpExactSolver.tau_per_tv; None: the shipped PNP_TAU_PER_TV_EXACT). PSNR/SSIM after the
    affine fit."""

    import clfza
    from clfza.solvers._pnp import PnpExactSolver

    # the refused case measured (reg='dncnn' on a mask's shadow: PnpExactSolver's setup)
    PnpExactSolver.allow_mask_shadow = True
    default = PnpExactSolver.tau_per_tv
    keys = [f"{r if r is not None else default:g}" for r in ratios]
    cam = experiment_camera(n)
    width = 0.6 * cam.shape[1] * cam.pitch / (cam.magnification or 1.0)
    rows = []
    try:
        for name in scenes:
            for nk in noises:
                y, truth = scene_frame(name, nk, cam, width)
                sc = functools.partial(score, truth=truth)

                def tv(tau, y=y, sc=sc):
                    t0 = time.perf_counter()
                    r = clfza.reconstruct(y, cam, "admm", model="exact", tau=tau,
                                          device=device)
                    return {"tau": tau, **sc(r.image), "s": time.perf_counter() - t0}

                row = {"scene": name, "noise": nk}
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    r = clfza.reconstruct(y, cam, "admm", model="exact", device=device)
                    row["tv_auto"] = {"tau": float(r.info.params["tau"]), **sc(r.image)}
                    grid = [tv(t) for t in EXACT_TAUS]
                    best = max(grid, key=lambda q: q["psnr"])
                    grid += [tv(best["tau"] * f) for f in EXACT_FINE]
                    grid.sort(key=lambda q: q["tau"])
                    best = max(grid, key=lambda q: q["psnr"])
                    row["tv_grid"], row["tv_best"] = grid, best
                    row["pnp_grid"], row["pnp_at_tv_best"], row["pnp_best"] = [], {}, {}
                    for ratio, key in zip(ratios, keys, strict=True):
                        PnpExactSolver.tau_per_tv = default if ratio is None else ratio
                        g = []
                        for f in (10.0 ** -0.5, 1.0, 10.0 ** 0.5):
                            t0 = time.perf_counter()
                            p = clfza.reconstruct(y, cam, "admm", model="exact", reg="dncnn",
                                                  tau=best["tau"] * f, device=device)
                            g.append({"ratio": key, "tau": best["tau"] * f, "factor": f,
                                      **sc(p.image), "variant": p.info.stats["denoiser"],
                                      "cg_iters": p.info.stats["cg_iters"],
                                      "s": time.perf_counter() - t0})
                        row["pnp_grid"] += g
                        row["pnp_at_tv_best"][key] = g[1]
                        row["pnp_best"][key] = max(g, key=lambda q: q["psnr"])
                print(json.dumps(row), flush=True)
                rows.append(row)
    finally:
        PnpExactSolver.tau_per_tv = default
    return {"size": n, "pitch_mm": cam.pitch, "device": device, "taus": list(EXACT_TAUS),
            "ratios": keys, "default_ratio": f"{default:g}", "rows": rows}


def exact_markdown(res: dict) -> str:
    q = res["quality_exact"]
    m = res["machine"]
    lines = [f"# DnCNN plug-and-play on the experiment preset, exact model (issue 38): "
             f"{res['label']}", "",
             f"Machine: {m['cpu_model']}, {m['cores_usable']} cores usable, load "
             f"{m['load_average']}; {m['date']}; clfza {res['commit']}; device {q['device']}.",
             f"Command: `{res['command']}`", "",
             f"Camera.preset('experiment') binned to {q['size']}^2 (pitch {q['pitch_mm']:.4g} mm, "
             "the same sensor), the exact model (mask shadow, finite aperture), scene filling "
             "60 % of the sensor width. PSNR dB (SSIM) after the affine fit. TV: the crop-split "
             "ADMM-TV with its defaults (400 iterations), tau='auto' and the hindsight-best tau "
             "of 1e-4 .. 3.16 by half-decades refined by a quarter decade either side (TV "
             "best). PnP: reg='dncnn' with its defaults (PnpExactSolver: the same ADMM-TV as "
             "pre-solve, then HQS with DnCNN 6N, CG x-update) at tau' = r tau (r = "
             f"{q['default_ratio']} shipped), at TV's best tau (at) and the best of TV's best "
             "tau x 10^{-1/2, 0, 1/2} (best of 3). delta: minus TV best.", "",
             "| scene | noise | TV auto | TV best (tau) | "
             + " | ".join(f"PnP r={k}: at / delta / best of 3 / delta" for k in q["ratios"])
             + " |", "|---|---|---|---|" + "---|" * len(q["ratios"])]
    d_at = {k: [] for k in q["ratios"]}
    d_best = {k: [] for k in q["ratios"]}
    for r in q["rows"]:
        cells = []
        for k in q["ratios"]:
            a = r["pnp_at_tv_best"][k]["psnr"] - r["tv_best"]["psnr"]
            b = r["pnp_best"][k]["psnr"] - r["tv_best"]["psnr"]
            d_at[k].append((r["scene"], r["noise"], a))
            d_best[k].append((r["scene"], r["noise"], b))
            cells.append(f"{r['pnp_at_tv_best'][k]['psnr']:.2f} / {a:+.2f} / "
                         f"{r['pnp_best'][k]['psnr']:.2f} / {b:+.2f}")
        lines.append(f"| {r['scene']} | {r['noise']} | {r['tv_auto']['psnr']:.2f} | "
                     f"{r['tv_best']['psnr']:.2f} ({r['tv_best']['tau']:.3g}) | "
                     + " | ".join(cells) + " |")
    lines += ["", "Targets (issue 38), at TV's best tau: natural scene at the Fig. 7 noise >= "
              "+1.5 dB; never worse than TV by > 0.5 dB on any scene."]
    vs_any = {k: [r["pnp_best"][k]["psnr"] - max(r["tv_best"]["psnr"], r["tv_auto"]["psnr"])
                  for r in q["rows"]] for k in q["ratios"]}
    for k in q["ratios"]:
        nat = [d for s, nz, d in d_at[k] if s == "natural" and nz == "gauss0.01"]
        worst = min(d_at[k], key=lambda t: t[2])
        worst_b = min(d_best[k], key=lambda t: t[2])
        tag = " (shipped)" if k == q["default_ratio"] else ""
        lines.append(
            f"- r={k}{tag}: natural, Fig. 7: {nat[0] if nat else float('nan'):+.2f} dB "
            f"({'met' if nat and nat[0] >= 1.5 else 'NOT met'}); worst {worst[2]:+.2f} "
            f"({worst[0]}, {worst[1]}): {'met' if worst[2] >= -0.5 else 'NOT met'}; mean "
            f"{np.mean([d for _, _, d in d_at[k]]):+.2f}; best of 3: mean "
            f"{np.mean([d for _, _, d in d_best[k]]):+.2f}, worst {worst_b[2]:+.2f} "
            f"({worst_b[0]}, {worst_b[1]}); against the better of TV's tau='auto' and TV "
            f"best (tau='auto' warm-starts from its pilots and can beat every cold-started "
            f"grid tau), best of 3: mean {np.mean(vs_any[k]):+.2f}, worst "
            f"{min(vs_any[k]):+.2f}.")
    s_pnp = statistics.median(p["s"] for r in q["rows"] for p in r["pnp_grid"])
    s_tv = statistics.median(t["s"] for r in q["rows"] for t in r["tv_grid"])
    lines += ["", f"Median seconds per solve (shared machine): PnP {s_pnp:.2f}, ADMM-TV "
              f"{s_tv:.2f}."]
    return "\n".join(lines) + "\n"


def exact_plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["quality_exact"]["rows"]
    labels = [f"{r['scene']}\n{r['noise']}" for r in rows]
    series = [("TV auto", [r["tv_auto"]["psnr"] for r in rows]),
              ("TV best tau", [r["tv_best"]["psnr"] for r in rows])]
    for k in res["quality_exact"]["ratios"]:
        series += [(f"PnP r={k} at TV's best tau",
                    [r["pnp_at_tv_best"][k]["psnr"] for r in rows]),
                   (f"PnP r={k} best of 3 taus", [r["pnp_best"][k]["psnr"] for r in rows])]
    fig, ax = plt.subplots(figsize=(13, 4.5))
    w = 0.8 / len(series)
    for i, (lab, v) in enumerate(series):
        ax.bar(np.arange(len(rows)) + i * w, v, w, label=lab)
    ax.set_xticks(np.arange(len(rows)) + 0.4 - w / 2, labels, fontsize=7)
    ax.set_ylabel("PSNR (dB, affine fit)")
    ax.set_title(f"reg='dncnn' against ADMM-TV, experiment preset (exact model) "
                 f"{res['quality_exact']['size']}^2")
    ax.legend(fontsize=7, ncol=4)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main_exact(args, devices, argv) -> int:
    """``--quality-exact N``: reg='dncnn' on the experiment preset (exact model)."""
    q = quality_exact(devices[0], args.quality_exact, args.scenes, args.noises,
                      args.exact_ratios if args.exact_ratios_given else (None,))
    machine = machine_record(devices[0])
    label = f"{machine_slug(machine)}_{impl_tag(get_runtime(devices[0]))}_{args.quality_exact}"
    if args.tag:
        label += f"_{args.tag}"
    res = {"label": label, "machine": machine, "commit": git_commit(),
           "command": "python bench/bench_dncnn.py " + " ".join(sys.argv[1:] if argv is None
                                                                else argv),
           "quality_exact": q}
    md = exact_markdown(res)
    print(md)
    paths = write_result_files(Path(args.out) / f"dncnn_quality_experiment_{label}", res, md,
                               exact_plot)
    print("wrote", ", ".join(str(p) for p in paths))
    return 0


#: --quality-levers: name -> overrides of clfza.solvers._pnp's constants (``variant``: the
#: denoiser option); "default" is the shipped setting
LEVERS = {
    "default": {},
    "17N": {"variant": "17N"},
    "iters10": {"PNP_ITERS": 10},
    "iters30": {"PNP_ITERS": 30},
    "smax0.2": {"PNP_SIGMA_MAX": 0.2},
    "smin0.002": {"PNP_SIGMA_MIN": 0.002},
    "smin0.01": {"PNP_SIGMA_MIN": 0.01},
    "smin0.02": {"PNP_SIGMA_MIN": 0.02},
    "kappa0.015": {"PNP_TAU_PER_TV": 0.015},
    "kappa0.06": {"PNP_TAU_PER_TV": 0.06},
}


def parse_lever(spec: str) -> tuple[str, dict]:
    """``name`` of LEVERS, or ``name=KEY:VALUE,KEY:VALUE`` (KEY a PNP_* constant or variant)."""
    if "=" not in spec:
        return spec, LEVERS[spec]
    name, body = spec.split("=", 1)
    out: dict = {}
    for kv in body.split(","):
        k, v = kv.split(":")
        out[k] = v if k == "variant" else float(v) if "." in v or "e" in v else int(v)
    return name, out


def quality_levers(device: str, n: int, scenes, noises, levers, select) -> dict:
    """The quality levers of reg='dncnn' on the simulation preset at n^2 (the Eq. 17 model):
    per scene x noise, ADMM-TV's hindsight-best tau of tau_auto x {1/4 .. 16} (as
    :func:`quality_pnp`), then reg='dncnn' at that tau with each lever (``levers``: name ->
    overrides of clfza.solvers._pnp's PNP_ITERS, PNP_SIGMA_MAX, PNP_SIGMA_MIN, PNP_TAU_PER_TV
    and the denoiser ``variant``; restored after). ``select``: the scenes a choice is made on
    (the others are held out)."""

    import clfza
    import clfza.solvers._pnp as pnp

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_solvers import camera

    cam = camera(n)
    width = 0.6 * cam.shape[1] * cam.pitch / (cam.magnification or 1.0)
    keys = ("PNP_ITERS", "PNP_SIGMA_MAX", "PNP_SIGMA_MIN")
    saved = {k: getattr(pnp, k) for k in keys}
    saved_kappa = pnp.PnpAdmmSolver.tau_per_tv
    rows = []
    try:
        for name in scenes:
            for nk in noises:
                y, truth = scene_frame(name, nk, cam, width)
                sc = functools.partial(score, truth=truth)

                row = {"scene": name, "noise": nk, "selection": name in select, "pnp": {}}
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    r = clfza.reconstruct(y, cam, "admm", model="tf", iters=200,
                                          device=device)
                    ta = float(r.info.params["tau"])
                    grid = []
                    for f in (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0):
                        img = clfza.reconstruct(y, cam, "admm", model="tf", iters=200,
                                                tau=ta * f, device=device).image
                        grid.append({"tau": ta * f, "factor": f, **sc(img)})
                    best = max(grid, key=lambda q: q["psnr"])
                    row["tv_best"] = best
                    for lname, over in levers.items():
                        for k in keys:
                            setattr(pnp, k, over.get(k, saved[k]))
                        pnp.PnpAdmmSolver.tau_per_tv = over.get("PNP_TAU_PER_TV", saved_kappa)
                        t0 = time.perf_counter()
                        p = clfza.reconstruct(y, cam, "admm", model="tf", reg="dncnn",
                                              tau=best["tau"], device=device,
                                              denoiser=over.get("variant", "6N"))
                        row["pnp"][lname] = {**sc(p.image), "s": time.perf_counter() - t0}
                print(json.dumps(row), flush=True)
                rows.append(row)
    finally:
        for k in keys:
            setattr(pnp, k, saved[k])
        pnp.PnpAdmmSolver.tau_per_tv = saved_kappa
    return {"size": n, "device": device, "levers": levers, "select": list(select),
            "rows": rows}


def levers_summary(q: dict) -> dict:
    """Per lever: delta = PnP - TV-best per row; mean on the selection and held-out rows, the
    natural scene at the Fig. 7 noise, the worst row, and rows below TV by > 0.5 dB."""
    out = {}
    for lname in q["levers"]:
        d = [(r, r["pnp"][lname]["psnr"] - r["tv_best"]["psnr"]) for r in q["rows"]]
        sel = [v for r, v in d if r["selection"]]
        held = [v for r, v in d if not r["selection"]]
        nat = [v for r, v in d if r["scene"] == "natural" and r["noise"] == "gauss0.01"]
        worst = min(d, key=lambda t: t[1])
        out[lname] = {
            "select_mean": float(np.mean(sel)) if sel else None,
            "heldout_mean": float(np.mean(held)) if held else None,
            "all_mean": float(np.mean([v for _, v in d])),
            "natural_fig7": nat[0] if nat else None,
            "worst": worst[1], "worst_case": f"{worst[0]['scene']}/{worst[0]['noise']}",
            "below_0.5": sum(v < -0.5 for _, v in d),
            "s_median": statistics.median(r["pnp"][lname]["s"] for r in q["rows"])}
    return out


def levers_markdown(res: dict) -> str:
    q = res["quality_levers"]
    m = res["machine"]
    names = list(q["levers"])
    lines = [f"# reg='dncnn' quality levers (issue 38): {res['label']}", "",
             f"Machine: {m['cpu_model']}, {m['cores_usable']} cores usable, load "
             f"{m['load_average']}; {m['date']}; clfza {res['commit']}; device {q['device']}.",
             f"Command: `{res['command']}`", "",
             f"Simulation preset at {q['size']}^2 (Eq. 17 model). PSNR dB after the affine fit of "
             "reg='dncnn' at ADMM-TV's hindsight-best tau (tau_auto x {1/4 .. 16}, 200 "
             "iterations) minus TV there. Levers (overrides of clfza.solvers._pnp): "
             + "; ".join(f"{k}: {v or 'shipped'}" for k, v in q["levers"].items())
             + f". Chosen on {q['select']} (the selection rows, *); the rest held out.", "",
             "| scene | noise | TV best | " + " | ".join(names) + " |",
             "|---|---|---|" + "---|" * len(names)]
    for r in q["rows"]:
        star = "*" if r["selection"] else ""
        lines.append(f"| {r['scene']}{star} | {r['noise']} | {r['tv_best']['psnr']:.2f} | "
                     + " | ".join(f"{r['pnp'][k]['psnr'] - r['tv_best']['psnr']:+.2f}"
                                  for k in names) + " |")
    s = levers_summary(q)
    lines += ["", "| lever | selection mean | held-out mean | all mean | natural, Fig. 7 | "
              "worst (case) | rows < -0.5 | s/solve |", "|---|---|---|---|---|---|---|---|"]

    def fmt(v):
        return "-" if v is None else f"{v:+.2f}"

    for k, v in s.items():
        lines.append(f"| {k} | {fmt(v['select_mean'])} | {fmt(v['heldout_mean'])} | "
                     f"{fmt(v['all_mean'])} | {fmt(v['natural_fig7'])} | {v['worst']:+.2f} "
                     f"({v['worst_case']}) | {v['below_0.5']} | {v['s_median']:.1f} |")
    return "\n".join(lines) + "\n"


def levers_plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    q = res["quality_levers"]
    rows, names = q["rows"], list(q["levers"])
    fig, ax = plt.subplots(figsize=(13, 4.5))
    w = 0.8 / len(names)
    for i, k in enumerate(names):
        ax.bar(np.arange(len(rows)) + i * w,
               [r["pnp"][k]["psnr"] - r["tv_best"]["psnr"] for r in rows], w, label=k)
    ax.axhline(0, color="k", lw=0.8)
    ax.axhline(-0.5, color="tab:red", ls=":", lw=0.8)
    ax.axhline(1.5, color="tab:green", ls=":", lw=0.8)
    ax.set_xticks(np.arange(len(rows)) + 0.4 - w / 2,
                  [f"{r['scene']}{'*' if r['selection'] else ''}\n{r['noise']}" for r in rows],
                  fontsize=7)
    ax.set_ylabel("PnP - TV-best (dB)")
    ax.set_title(f"reg='dncnn' levers at TV's best tau, simulation preset {q['size']}^2 "
                 "(* = selection scenes)")
    ax.legend(fontsize=7, ncol=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main_levers(args, devices, argv) -> int:
    """``--quality-levers N``: the lever comparison of reg='dncnn'."""
    levers = dict(parse_lever(s) for s in args.levers)
    q = quality_levers(devices[0], args.quality_levers, args.scenes, args.noises, levers,
                       args.select)
    machine = machine_record(devices[0])
    label = f"{machine_slug(machine)}_{impl_tag(get_runtime(devices[0]))}_{args.quality_levers}"
    if args.tag:
        label += f"_{args.tag}"
    res = {"label": label, "machine": machine, "commit": git_commit(),
           "command": "python bench/bench_dncnn.py " + " ".join(sys.argv[1:] if argv is None
                                                                else argv),
           "quality_levers": q, "summary": levers_summary(q)}
    md = levers_markdown(res)
    print(md)
    paths = write_result_files(Path(args.out) / f"dncnn_quality_levers_{label}", res, md,
                               levers_plot)
    print("wrote", ", ".join(str(p) for p in paths))
    return 0


def solve_time(devices, n: int, rounds: int, variants=("6N",)) -> dict:
    """Seconds per reg='dncnn' solve (and per ADMM-TV solve, the same tau and pre-solve
    length, for the ratio) on each device, the simulation preset's natural scene at n^2 with
    the Fig. 7 noise at tau = 4 x ADMM-TV's tau='auto' (its hindsight-best factor at 128^2).
    Round by round over the devices (one warm-up solve each first), so the ratios come from
    the same minutes of a shared machine; the load average is read before and after each
    round."""
    import os

    import clfza
    from clfza.benchmarks import _scenes as scenes_mod
    from clfza.benchmarks._timeerror import NOISES

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_solvers import camera

    cam = camera(n)
    y = scenes_mod.measurement("natural", cam, NOISES["gauss0.01"]).measurement.y
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tau = 4.0 * float(clfza.reconstruct(y, cam, "admm", model="tf", iters=200,
                                            device=devices[0]).info.params["tau"])
    cases = [(d, v) for d in devices for v in variants]
    times: dict = {c: {"pnp": [], "tv": [], "tv_presolve": []} for c in cases}
    stats: dict = {}
    loads = []

    def pnp(d, v):
        return clfza.reconstruct(y, cam, "admm", model="tf", reg="dncnn", tau=tau,
                                 denoiser=v, device=d)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for d, v in cases:  # warm-up: builds, caches
            pnp(d, v)
        for _ in range(rounds):
            load = [os.getloadavg()[0]]
            for c in cases:
                d, v = c
                t0 = time.perf_counter()
                r = pnp(d, v)
                times[c]["pnp"].append(time.perf_counter() - t0)
                times[c]["tv_presolve"].append(r.info.stats["tv_presolve_s"])
                stats[c] = {"denoiser_calls": r.info.stats["denoiser_calls"],
                            "tv_presolve_iters": r.info.stats["tv_presolve_iters"],
                            "iterations": r.info.iterations}
                t0 = time.perf_counter()
                clfza.reconstruct(y, cam, "admm", model="tf", iters=200, tau=tau, device=d)
                times[c]["tv"].append(time.perf_counter() - t0)
            load.append(os.getloadavg()[0])
            loads.append(load)
    rows = []
    base = None
    for c in cases:
        d, v = c
        t = {k: statistics.median(x) for k, x in times[c].items()}
        if base is None:
            base = t["pnp"]
        rows.append({"device": d, "device_name": get_runtime(d).info.describe(),
                     "impl": impl_tag(get_runtime(d)), "variant": v,
                     "s_pnp": t["pnp"], "s_tv_presolve": t["tv_presolve"],
                     "s_hqs": t["pnp"] - t["tv_presolve"], "s_tv": t["tv"],
                     "pnp_over_tv": t["pnp"] / t["tv"], "pnp_over_first": t["pnp"] / base,
                     "s_pnp_all": times[c]["pnp"], "s_tv_all": times[c]["tv"], **stats[c]})
    return {"size": n, "tau": tau, "rounds": rounds, "loads": loads, "rows": rows}


def solve_markdown(res: dict) -> str:
    q = res["solve_time"]
    m = res["machine"]
    lo = min(x for ld in q["loads"] for x in ld)
    hi = max(x for ld in q["loads"] for x in ld)
    lines = [f"# reg='dncnn' time per solve on each CPU implementation (issue 38): "
             f"{res['label']}", "",
             f"Machine: {m['cpu_model']}, {m['cores_usable']} cores usable (shared with other "
             f"jobs: 1-minute load {lo:.1f}-{hi:.1f} over the rounds, so ratios only); "
             f"{m['date']}; clfza {res['commit']}.", f"Command: `{res['command']}`", "",
             f"Simulation preset, natural scene at {q['size']}^2 with the Fig. 7 noise, tau "
             f"{q['tau']:.4g} (4 x ADMM-TV's tau='auto'). reg='dncnn' with its defaults (200 "
             "ADMM-TV iterations of pre-solve, then the HQS stage with one denoiser call per "
             "iteration) against ADMM-TV alone (200 iterations, same tau), per device; medians "
             f"over {q['rounds']} interleaved rounds after a warm-up solve each.", "",
             "| device | variant | s/solve | of it: TV pre-solve | HQS stage | denoiser calls | "
             "ADMM-TV s/solve | PnP / TV | PnP / first device |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in q["rows"]:
        lines.append(f"| {r['device']} {r['impl']} ({r['device_name']}) | {r['variant']} | "
                     f"{r['s_pnp']:.2f} | {r['s_tv_presolve']:.2f} | {r['s_hqs']:.2f} | "
                     f"{r['denoiser_calls']} | {r['s_tv']:.2f} | {r['pnp_over_tv']:.1f} | "
                     f"{r['pnp_over_first']:.2f} |")
    return "\n".join(lines) + "\n"


def solve_plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["solve_time"]["rows"]
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["s_tv_presolve"] for r in rows], 0.4, label="TV pre-solve")
    ax.bar(x - 0.2, [r["s_hqs"] for r in rows], 0.4, bottom=[r["s_tv_presolve"] for r in rows],
           label="HQS + DnCNN")
    ax.bar(x + 0.2, [r["s_tv"] for r in rows], 0.4, label="ADMM-TV alone")
    ax.set_xticks(x, [f"{r['device']} {r['impl']}\n{r['variant']}" for r in rows], fontsize=8)
    ax.set_ylabel("s per solve (median)")
    ax.set_title(f"reg='dncnn' per solve, {res['solve_time']['size']}^2 (shared machine)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main_solve(args, devices, argv) -> int:
    """``--solve-time N``: seconds per reg='dncnn' solve on each device."""
    q = solve_time(devices, args.solve_time, args.rounds, args.pnp_variants)
    machine = machine_record(devices[0])
    impls = "-".join(dict.fromkeys(r["impl"] for r in q["rows"]))
    label = f"{machine_slug(machine)}_{impls}_{args.solve_time}"
    if args.tag:
        label += f"_{args.tag}"
    res = {"label": label, "machine": machine, "commit": git_commit(),
           "command": "python bench/bench_dncnn.py " + " ".join(sys.argv[1:] if argv is None
                                                                else argv),
           "solve_time": q}
    md = solve_markdown(res)
    print(md)
    paths = write_result_files(Path(args.out) / f"dncnn_solve_{label}", res, md, solve_plot)
    print("wrote", ", ".join(str(p) for p in paths))
    return 0


def main_quality(args, devices, argv) -> int:
    """``--quality-pnp N``: the plug-and-play quality benchmark alone."""
    q = quality_pnp(devices[0], args.quality_pnp, args.scenes, args.noises,
                    args.pnp_variants)
    machine = machine_record(devices[0])
    label = f"{machine_slug(machine)}_{impl_tag(get_runtime(devices[0]))}_{args.quality_pnp}"
    if args.tag:
        label += f"_{args.tag}"
    res = {"label": label, "machine": machine, "commit": git_commit(),
           "command": "python bench/bench_dncnn.py " + " ".join(sys.argv[1:] if argv is None
                                                                else argv),
           "quality_pnp": q}
    md = quality_markdown(res)
    print(md)
    paths = write_result_files(Path(args.out) / f"dncnn_quality_{label}", res, md,
                               quality_plot)
    print("wrote", ", ".join(str(p) for p in paths))
    return 0


def pnp_set(specs) -> None:
    """Apply ``--pnp-set NAME=VALUE`` overrides to clfza.solvers._pnp (PNP_TAU_PER_TV and
    PNP_TAU_PER_TV_EXACT also on the solver classes that read them)."""
    import clfza.solvers._pnp as pnp

    for spec in specs:
        name, _, value = spec.partition("=")
        if not name.startswith("PNP_") or not hasattr(pnp, name):
            raise SystemExit(f"--pnp-set: no constant {name!r} in clfza.solvers._pnp")
        v = type(getattr(pnp, name))(float(value))
        setattr(pnp, name, v)
        if name == "PNP_TAU_PER_TV":
            pnp.PnpAdmmSolver.tau_per_tv = v
        elif name == "PNP_TAU_PER_TV_EXACT":
            pnp.PnpExactSolver.tau_per_tv = v
        print(f"clfza.solvers._pnp.{name} = {v!r}", flush=True)


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
    ap.add_argument("--quality-pnp", type=int, default=0, metavar="N",
                    help="only the plug-and-play quality benchmark (scenes x noises against "
                         "ADMM-TV at N^2, first device); writes dncnn_quality_<machine>.*")
    ap.add_argument("--pnp-variants", nargs="+", default=["6N"],
                    help="--quality-pnp: the denoiser variants of reg='dncnn'")
    ap.add_argument("--scenes", nargs="+", default=["natural", "text", "usaf", "face"])
    ap.add_argument("--noises", nargs="+", default=["none", "gauss0.01", "poisson1e7"])
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--tag", default="", help="--quality-pnp/-psf: a suffix of the files' label")
    ap.add_argument("--quality-psf", type=int, default=0, metavar="N",
                    help="only reg='dncnn' on a measured PSF against ADMM-TV (exact model, "
                         "N^2); writes dncnn_quality_psf_<machine>.*")
    ap.add_argument("--psf-scenes", nargs="+", default=["camera", "face"],
                    choices=["camera", "face", "text", "coffee"])
    ap.add_argument("--photons", nargs="+", type=float, default=[2000.0, 20000.0])
    ap.add_argument("--exact-ratios", nargs="+", type=float, default=None,
                    help="--quality-psf (default 1 3 10), --quality-exact (default the "
                         "shipped one): the tau'/tau of the exact model's PnP to compare")
    ap.add_argument("--cg-iters", nargs="+", type=int, default=None,
                    help="--quality-psf: CG iterations per x-update to compare (default: "
                         "PNP_CG_ITERS only)")
    ap.add_argument("--quality-exact", type=int, default=0, metavar="N",
                    help="only reg='dncnn' on the experiment preset binned to N^2 through the "
                         "exact model against ADMM-TV (4 scenes x 3 noises); writes "
                         "dncnn_quality_experiment_<machine>.*")
    ap.add_argument("--quality-levers", type=int, default=0, metavar="N",
                    help="only the lever comparison of reg='dncnn' at TV's best tau "
                         "(simulation preset, N^2); writes dncnn_quality_levers_<machine>.*")
    ap.add_argument("--levers", nargs="+", default=list(LEVERS),
                    help="--quality-levers: names of LEVERS or NAME=KEY:VALUE,... (KEY a "
                         "PNP_* constant or variant)")
    ap.add_argument("--select", nargs="+", default=["natural", "text"],
                    help="--quality-levers: the scenes a choice is made on (others held out)")
    ap.add_argument("--solve-time", type=int, default=0, metavar="N",
                    help="only seconds per reg='dncnn' solve at N^2 on each --device "
                         "(interleaved --rounds); writes dncnn_solve_<machine>.*")
    ap.add_argument("--pnp-set", nargs="+", default=[], metavar="PNP_NAME=VALUE",
                    help="override clfza.solvers._pnp's constants for this run (PNP_ITERS, "
                         "PNP_SIGMA_MAX, PNP_SIGMA_MIN, PNP_CG_ITERS, ...; the command line "
                         "in the result files records them)")
    args = ap.parse_args(argv)
    pnp_set(args.pnp_set)
    args.exact_ratios_given = args.exact_ratios is not None
    if args.exact_ratios is None:
        args.exact_ratios = [1.0, 3.0, 10.0]
    devices = args.device or [get_runtime().info.index]
    if args.quality_levers:
        return main_levers(args, devices, argv)
    if args.quality_exact:
        return main_exact(args, devices, argv)
    if args.solve_time:
        return main_solve(args, devices, argv)
    if args.quality_pnp:
        return main_quality(args, devices, argv)
    if args.quality_psf:
        return main_psf(args, devices, argv)
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
    commit = git_commit()
    res = {"label": label, "machine": machine, "commit": commit,
           "command": "python bench/bench_dncnn.py " + " ".join(sys.argv[1:] if argv is None
                                                                else argv),
           "matmul_gflops": statistics.median(mm), "matmul_all": mm, "timing": rows,
           "targets": targets(rows), "quality": q, "quality_device": devices[0]}
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
