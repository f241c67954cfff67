"""Issue 38: which plug-and-play scheme makes the DnCNN prior deliver (candidates, measured).

Usage::

    python bench/bench_pnp_candidates.py [--size 128] [--device 1:0]
                                         [--cases natural:gauss0.01 face:gauss0.01 ...]

On the simulation preset (bench_solvers' camera at ``--size``^2, the Eq. 17 transfer-function
model) each case (scene:noise, as in bench_dncnn.py ``--quality-pnp``) is reconstructed by
ADMM-TV (200 iterations) at tau='auto' and at the hindsight-best of tau_auto x {1/4 .. 16};
from each of the two TV images (and the Wiener estimate), these candidates, all in float64
numpy around the OpenCL DnCNN (the library's reg='dncnn' reproduces the ``hqs`` rows):

* ``admm-growth``: scaled PnP-ADMM, rho 0.1 growing 1.1x per iteration, 60 iterations,
  tau 0.01 (the first reg='dncnn', commit be69491);
* ``hqs``: half-quadratic splitting, sigma geometric 0.1 -> 0.005 over 20 iterations,
  rho = tau / (c sigma)^2 (DPIR), 6N; ``hqs-17N`` the same with 17N; ``hqs-0.05``: from
  sigma 0.05; ``hqs-40``: 40 iterations;
* ``pnp-fista``: FISTA with the denoiser as the prox (step 1 = 1 / ||K||^2, sigma on the same
  schedule, the prox's noise level in the image's units sqrt(tau));
* ``red``: regularisation by denoising, gradient steps on 1/2 ||y - Kx||^2 + lam/2 x^T (x -
  D(x)), step 1 / (1 + lam), sigma fixed at 0.02, 40 iterations.

tau of the PnP candidates = kappa * tau of the TV start (kappa in {0.01, 0.03, 0.1}), the best
kappa shown per candidate (for the Wiener start: the best TV's tau). The image's [0, 1] range
for the denoiser: the start's 0.1-99.9 percentiles. PSNR after the affine fit.
Writes ``bench/results/dncnn_quality_candidates_<machine>.json``, ``.md``, ``.png``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import scipy.fft as sfft

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import clfza  # noqa: E402
from clfza.benchmarks._machine import machine_record, machine_slug  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.cl import get_runtime  # noqa: E402
from clfza.denoisers import DnCNNDevice, load_dncnn  # noqa: E402
from clfza.metrics import compare  # noqa: E402
from clfza.models import transfer_function  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
KAPPAS = (0.01, 0.03, 0.1)


class Problem:
    def __init__(self, y, cam, nets):
        n = y.shape
        self.shape = n
        self.H = transfer_function(n, cam.pitch, cam.r1p)
        self.H2 = self.H ** 2
        self.Kty = self.K(y)
        self.y = y
        self.nets = nets

    def K(self, x):
        return sfft.irfft2(sfft.rfft2(x) * self.H, s=self.shape)

    def solve(self, v, rho):
        return sfft.irfft2(sfft.rfft2(self.Kty + rho * v) / (self.H2 + rho), s=self.shape)

    def D(self, x, lo, c, s, v="6N"):
        t = np.clip((x - lo) / c, 0.0, 1.0)
        return lo + c * np.asarray(self.nets[v](t, float(min(max(s, 1e-4), 0.3))), float)


def admm_growth(P, x0, lo, c, tau):
    x, z, u, rho = x0.copy(), x0.copy(), np.zeros_like(x0), 0.1
    for k in range(60):
        if k:
            rho *= 1.1
            u /= 1.1
        x = P.solve(z - u, rho)
        z = P.D(x + u, lo, c, np.sqrt(tau / rho) / c)
        u += x - z
    return x


def hqs(P, x0, lo, c, tau, smax=0.1, smin=0.005, iters=20, v="6N"):
    z = x0.copy()
    for s in np.geomspace(smax, smin, iters):
        rho = tau / (c * s) ** 2
        x = P.solve(z, rho)
        z = P.D(x, lo, c, s, v)
    return x


def pnp_fista(P, x0, lo, c, tau, iters=20):
    x, v, t = x0.copy(), x0.copy(), 1.0
    for s in np.geomspace(0.1, 0.005, iters):
        g = v - (P.K(P.K(v)) - P.Kty)
        xn = P.D(g, lo, c, s)
        tn = (1 + np.sqrt(1 + 4 * t * t)) / 2
        v = xn + (t - 1) / tn * (xn - x)
        x, t = xn, tn
    return x


def red(P, x0, lo, c, tau, iters=40, sigma=0.02):
    x = x0.copy()
    lam = tau / (c * sigma) ** 2
    mu = 1.0 / (1.0 + lam)
    for _ in range(iters):
        grad = P.K(P.K(x)) - P.Kty + lam * (x - P.D(x, lo, c, sigma))
        x = x - mu * grad
    return x


CANDIDATES = {
    "admm-growth": lambda P, x0, lo, c, tau: admm_growth(P, x0, lo, c, tau),
    "hqs": lambda P, x0, lo, c, tau: hqs(P, x0, lo, c, tau),
    "hqs-17N": lambda P, x0, lo, c, tau: hqs(P, x0, lo, c, tau, v="17N"),
    "hqs-0.05": lambda P, x0, lo, c, tau: hqs(P, x0, lo, c, tau, smax=0.05),
    "hqs-40": lambda P, x0, lo, c, tau: hqs(P, x0, lo, c, tau, iters=40),
    "pnp-fista": lambda P, x0, lo, c, tau: pnp_fista(P, x0, lo, c, tau),
    "red": lambda P, x0, lo, c, tau: red(P, x0, lo, c, tau),
}


def measurement(scene, noise_key, cam):
    from skimage import color, data

    from clfza.benchmarks import _scenes
    from clfza.benchmarks._timeerror import NOISES

    if scene == "face":
        width = 0.6 * cam.shape[1] * cam.pitch / (cam.magnification or 1.0)
        return clfza.simulate(color.rgb2gray(data.astronaut()), cam, object_width=width,
                              noise=NOISES[noise_key])
    return _scenes.measurement(scene, cam, NOISES[noise_key]).measurement


def run_case(case, cam, device, nets):
    scene, nk = case.split(":")
    m = measurement(scene, nk, cam)
    y, truth = m.y, m.truth

    def sc(x):
        return round(compare(x, truth)["psnr"], 2)

    row = {"case": case}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = clfza.reconstruct(y, cam, "admm", model="tf", iters=200, device=device)
        ta = float(r.info.params["tau"])
        grid = {f: clfza.reconstruct(y, cam, "admm", model="tf", iters=200, tau=ta * f,
                                     device=device).image
                for f in (0.25, 0.5, 1, 2, 4, 8, 16)}
    fb = max(grid, key=lambda f: sc(grid[f]))
    P = Problem(y, cam, nets)
    wien = sfft.irfft2(sfft.rfft2(P.Kty) / (P.H2 + 0.1), s=P.shape)
    row.update(tv_auto=sc(r.image), tv_best=sc(grid[fb]), tv_best_factor=fb, tau_auto=ta)
    starts = {"tv_auto": (r.image, ta), "tv_best": (grid[fb], ta * fb),
              "wiener": (wien, ta * fb)}
    row["runs"] = []
    for sname, (x0, tau_tv) in starts.items():
        lo, hi = np.percentile(x0, (0.1, 99.9))
        c = hi - lo
        for name, fn in CANDIDATES.items():
            best = None
            for kap in KAPPAS:
                t0 = time.perf_counter()
                x = fn(P, x0, lo, c, kap * tau_tv)
                res = {"start": sname, "candidate": name, "kappa": kap, "psnr": sc(x),
                       "s": round(time.perf_counter() - t0, 2)}
                if best is None or res["psnr"] > best["psnr"]:
                    best = res
            row["runs"].append(best)
    print(json.dumps(row), flush=True)
    return row


def markdown(res):
    m = res["machine"]
    lines = [f"# Plug-and-play candidates for reg='dncnn' (issue 38): {res['label']}", "",
             f"Machine: {m['cpu_model']}, {m['cores_usable']} cores usable; {m['date']}; "
             f"clfza {res['commit']}; denoiser on {res['device']}.",
             f"Command: `{res['command']}`", "",
             f"Simulation preset at {res['size']}^2 (Eq. 17 model). PSNR dB after the affine "
             "fit; each candidate at its best kappa (tau = kappa x the TV start's tau, kappa "
             f"in {list(KAPPAS)}); the start in brackets.", ""]
    names = list(CANDIDATES)
    lines += ["| case | start | TV (auto / best) | " + " | ".join(names) + " |",
              "|---|---|---|" + "---|" * len(names)]
    for row in res["rows"]:
        for sname in ("wiener", "tv_auto", "tv_best"):
            runs = {r["candidate"]: r for r in row["runs"] if r["start"] == sname}
            lines.append(f"| {row['case']} | {sname} | {row['tv_auto']} / {row['tv_best']} "
                         f"(x{row['tv_best_factor']:g}) | " + " | ".join(
                             f"{runs[n]['psnr']} (k{runs[n]['kappa']:g})" for n in names)
                         + " |")
    return "\n".join(lines) + "\n"


def plot(res, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(CANDIDATES)
    rows = [(row, s) for row in res["rows"] for s in ("tv_auto", "tv_best")]
    fig, ax = plt.subplots(figsize=(12, 4.5))
    w = 0.8 / (len(names) + 1)
    for i, (row, s) in enumerate(rows):
        runs = {r["candidate"]: r["psnr"] for r in row["runs"] if r["start"] == s}
        ax.bar(i, row["tv_best"], w, color="k", label="TV best tau" if i == 0 else None)
        for j, n in enumerate(names):
            ax.bar(i + (j + 1) * w, runs[n], w, color=f"C{j}", label=n if i == 0 else None)
    ax.set_xticks(np.arange(len(rows)) + 0.4, [f"{r['case']}\nfrom {s}" for r, s in rows],
                  fontsize=7)
    ax.set_ylabel("PSNR (dB, affine fit)")
    lo = min(min(r["psnr"] for r in row["runs"]) for row in res["rows"])
    ax.set_ylim(max(lo - 1, 0), None)
    ax.legend(fontsize=7, ncol=4)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--device", default=None)
    ap.add_argument("--cases", nargs="+",
                    default=["natural:gauss0.01", "face:gauss0.01", "natural:none",
                             "text:none"])
    ap.add_argument("--out", default=str(RESULTS))
    args = ap.parse_args(argv)
    from bench_dncnn import git_commit, impl_tag
    from bench_solvers import camera

    rt = get_runtime(args.device)
    nets = {v: DnCNNDevice(load_dncnn(v), rt) for v in ("6N", "17N")}
    cam = camera(args.size)
    rows = [run_case(c, cam, rt.info.index, nets) for c in args.cases]
    machine = machine_record(rt.info.index)
    label = f"{machine_slug(machine)}_{impl_tag(rt)}_{args.size}"
    res = {"label": label, "machine": machine, "commit": git_commit(), "size": args.size,
           "device": rt.info.index, "kappas": list(KAPPAS),
           "command": "python bench/bench_pnp_candidates.py " + " ".join(
               sys.argv[1:] if argv is None else argv), "rows": rows}
    md = markdown(res)
    print(md)
    paths = write_result_files(Path(args.out) / f"dncnn_quality_candidates_{label}", res, md,
                               plot)
    print("wrote", ", ".join(str(p) for p in paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
