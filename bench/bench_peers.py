"""clfza's defaults against other libraries' solvers on the paper's own simulation (issue 33's
peer comparison): time to reach each PSNR level, measured in one run.

The case: the ``simulation`` preset (the paper's Fig. 7 camera, 512^2, no aperture), the
scikit-image camera scene 20 mm wide, simulated by :func:`clfza.simulate` (the exact model),
noise-free and with the paper's Gaussian noise of variance 0.01 on ``y``. Error: PSNR after
the affine fit of :func:`clfza.metrics.compare` (``a x + b`` fitted to the truth: the model
loses the DC and the scale), the same for every tool.

Contenders, each given the same frame and the same forward operator as arrays:

* ``clfza default``: ``clfza.reconstruct(y, cam)``, no options (the planner's method, model,
  tau and stop); wall time of the whole call after a warm-up call (kernel builds and FFT plans
  excluded), median of ``--repeats`` calls. One point per case.
* ``scico ADMM (Eq. 17)``: scico's ``ADMM`` on ``1/2 ||y - A x||^2 + lam ||D x||_{2,1}``
  with ``A`` the transfer-function model (Eq. 17) as a ``CircularConvolve`` (its DFT given),
  ``D`` circular finite differences, and scico's ``CircularConvolveSolver`` for the x-step
  (its fastest path, exact per iteration): the same problem as clfza's Eq. 17 ADMM.
* ``scico ADMM (exact)``: the same with the exact model ``A x = P C (h * E x)`` (embed,
  convolve on the padded grid, crop, remove the mean: :class:`clfza.models.ExactModel`), whose
  x-step has no closed form: scico's ``LinearSubproblemSolver`` (conjugate gradients,
  ``--cg-iters``), warm-started.
* ``pyproximal PDHG (Eq. 17)``: pyproximal's ``PrimalDual`` (Chambolle-Pock) on the same Eq. 17
  problem, ``K = [A; grad]``, the dual of the data term by ``L2``'s conjugate and ``L21`` for TV,
  step sizes ``tau = mu = 0.95 / ||K||``.
* ``LenslessPiCam ADMM``: LenslessPiCam's ``ADMM`` (l1 of the gradient, non-negativity, its
  default penalties) on its own model (pad, convolve, crop) with the exact model's kernel cut to
  the sensor's size (a kernel wider than the sensor is what its model cannot hold), unit L2
  norm, the frame scaled to a maximum of 1; ``tau`` swept over 4 decades. It runs in its own
  environment (``.venv-lensless``: it pins numpy 1.26) through
  ``bench/peer_lensless_worker.py``; skipped when that environment is missing.
* ``scikit-image Wiener``: ``skimage.restoration.wiener`` with the Eq. 17 PSF, ``balance``
  swept; one shot, median of ``--repeats``.

"Best tuned" is in hindsight, per level: for each PSNR level, a tool's time is the least over
its swept settings (``lam`` a factor 16 around clfza's own ``tau="auto"`` choice on Eq. 17,
converted to scico's scale ``lam = tau / 2``; ADMM penalties ``rho = {1, 10, 100} lam``;
Wiener's ``balance`` over 10 values). The table also gives each tool's number of swept runs and
their total seconds: what finding that setting costs a user without the truth; clfza's
default pays for its own choice (the tau search) inside its one call. Iteration times exclude
the checkpoint evaluations (PSNR is computed with the clock stopped) and the first call's
compilation (a two-iteration warm-up of each configuration; JAX compiles at the first step).

Writes ``bench/results/peers_<machine>.{json,md,png}``. The environment: the peers live in a
bench-only virtual environment, never in clfza's dependencies::

    python3 -m venv .venv-peers
    .venv-peers/bin/pip install "scico==0.0.7" "jax[cpu]" pyproximal
    .venv-peers/bin/pip install -e ".[pocl,intel]" && .venv-peers/bin/python -m clfza.cl.intel_icd
    python3 -m venv .venv-lensless && .venv-lensless/bin/pip install lensless
    .venv-peers/bin/python bench/bench_peers.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import clfza  # noqa: E402
from clfza.benchmarks._machine import machine_record, machine_slug  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.metrics import compare  # noqa: E402
from clfza.models import camera_model, transfer_function  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
CASES = {"fig7": 0.01, "clean": 0.0}
LEVELS = {"fig7": [20.0, 24.0, 27.0, 28.0, 28.5], "clean": [30.0, 34.0, 38.0, 40.0, 43.0]}
LAM_FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0)
RHO_FACTORS = (1.0, 10.0, 100.0)
DC_RHO = 1e-3  # the identity term's penalty, relative to rho
BALANCES = (1e-3, 3e-3, 1e-2, 3e-2, 1e-1, 3e-1, 1.0, 3.0, 10.0, 30.0)


def checkpoints(iters: int) -> list[int]:
    pts = [1, 2, 3, 5, 7, 10, 15, 20, 30, 40, 50, 70, 100, 150, 200, 300, 400, 600, 800]
    return sorted({k for k in pts if k < iters} | {iters})


def psnr(x, truth) -> float:
    return float(compare(np.asarray(x, dtype=np.float64), truth)["psnr"])


def make_case(noise_var: float):
    from skimage import data

    cam = clfza.Camera.preset("simulation")
    noise = clfza.Noise(gaussian_var=noise_var, seed=1) if noise_var else None
    meas = clfza.simulate(data.camera() / 255.0, cam, object_width=20.0, noise=noise)
    y = meas.y - meas.y.mean()
    return cam, y, meas.truth


# ---------------------------------------------------------------------------------------
# clfza
# ---------------------------------------------------------------------------------------
def run_clfza_default(y, cam, truth, repeats: int) -> dict:
    clfza.reconstruct(y, cam)  # warm-up: kernel builds, FFT plans, tuning
    walls, rec = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        rec = clfza.reconstruct(y, cam)
        walls.append(time.perf_counter() - t0)
    info = rec.info
    return {"tool": "clfza default", "setting": {"method": info.method,
                                                 "model": info.params.get("model"),
                                                 "tau": info.params.get("tau")},
            "trace": [{"iteration": int(getattr(info, "iterations", 0) or 0),
                       "time_s": statistics.median(walls), "psnr": psnr(rec.image, truth)}],
            "walls_s": walls}


def clfza_auto_tau(y, cam) -> float:
    rec = clfza.reconstruct(y, cam, "admm", model="tf", tau="auto")
    return float(rec.info.params["tau"])


# ---------------------------------------------------------------------------------------
# scico
# ---------------------------------------------------------------------------------------
def _scico_trace(solver, iters: int, truth, to_image) -> list[dict]:
    import jax

    for _ in range(2):  # compile
        solver.step()
    jax.block_until_ready(solver.x)
    marks, out, clock, it = checkpoints(iters), [], 0.0, 0
    for k in marks:
        t0 = time.perf_counter()
        while it < k:
            solver.step()
            it += 1
        jax.block_until_ready(solver.x)
        clock += time.perf_counter() - t0
        out.append({"iteration": k, "time_s": clock,
                    "psnr": psnr(to_image(np.asarray(solver.x)), truth)})
    return out


def run_scico_tf(y, cam, truth, lam: float, rho: float, iters: int) -> list[dict]:
    import jax.numpy as jnp
    from scico import functional, linop, loss
    from scico.optimize.admm import ADMM, CircularConvolveSolver

    H = transfer_function(cam.shape, cam.pitch, cam.r1p, half=False)
    A = linop.CircularConvolve(jnp.asarray(H, dtype=jnp.complex64), cam.shape,
                               h_is_dft=True)
    f = loss.SquaredL2Loss(y=jnp.asarray(y, dtype=jnp.float32), A=A)
    D = linop.FiniteDifference(input_shape=cam.shape, circular=True)
    g = lam * functional.L21Norm()
    # A and D both annihilate the DC, so the x-step's (A^T A + rho D^T D) is singular there
    # (scico's solver divides by zero: NaN from the first step); a zero functional on the
    # identity with a small penalty closes it, as a scico user does
    solver = ADMM(f=f, g_list=[g, functional.ZeroFunctional()],
                  C_list=[D, linop.Identity(cam.shape)], rho_list=[rho, DC_RHO * rho],
                  x0=A.adj(f.y).real, maxiter=iters,
                  subproblem_solver=CircularConvolveSolver())
    return _scico_trace(solver, iters, truth, lambda x: x)


def run_scico_exact(y, cam, truth, lam: float, rho: float, iters: int, cg_iters: int
                    ) -> list[dict]:
    import jax.numpy as jnp
    from scico import functional, linop, loss
    from scico.optimize.admm import ADMM, LinearSubproblemSolver

    model = camera_model(cam)
    grid, sensor = model.shape, model.sensor
    Hs = jnp.asarray(model.Hs, dtype=jnp.complex64)
    (r0, c0), (sy, sx) = model.geom.offset, sensor
    r1, c1 = r0 + sy, c0 + sx

    def fwd(x):  # x on the sensor window -> P C (h * E x)
        g = jnp.zeros(grid, dtype=jnp.float32).at[r0:r1, c0:c1].set(x)
        v = jnp.fft.irfft2(jnp.fft.rfft2(g) * Hs, s=grid)[r0:r1, c0:c1]
        return v - v.mean()

    A = linop.LinearOperator(input_shape=sensor, output_shape=sensor, eval_fn=fwd,
                             input_dtype=jnp.float32)
    f = loss.SquaredL2Loss(y=jnp.asarray(y, dtype=jnp.float32), A=A)
    D = linop.FiniteDifference(input_shape=sensor, circular=True)
    g = lam * functional.L21Norm()
    solver = ADMM(f=f, g_list=[g], C_list=[D], rho_list=[rho], x0=A.adj(f.y),
                  maxiter=iters,
                  subproblem_solver=LinearSubproblemSolver(cg_kwargs={"maxiter": cg_iters}))
    return _scico_trace(solver, iters, truth, lambda x: x)


# ---------------------------------------------------------------------------------------
# pyproximal
# ---------------------------------------------------------------------------------------
def run_pyproximal_tf(y, cam, truth, lam: float, iters: int) -> list[dict]:
    import pylops
    import pyproximal
    import scipy.fft

    H = transfer_function(cam.shape, cam.pitch, cam.r1p)  # real, half spectrum
    shape = cam.shape

    def apply(v):
        return scipy.fft.irfft2(scipy.fft.rfft2(v.reshape(shape)) * H, s=shape).ravel()

    n = int(np.prod(shape))
    A = pylops.FunctionOperator(apply, apply, n, n)  # K is symmetric (H real)
    grad = pylops.Gradient(dims=shape, edge=False, kind="forward", dtype="float64")
    K = pylops.VStack([A, grad])
    norm = float(np.sqrt(np.max(np.abs(H)) ** 2 + 8.0))
    step = 0.95 / norm
    proxf = pyproximal.Box(lower=-np.inf, upper=np.inf)
    proxg = pyproximal.VStack([pyproximal.L2(b=y.ravel()),
                               pyproximal.L21(ndim=2, sigma=lam)], nn=[n, 2 * n])
    marks = checkpoints(iters)
    state = {"t": 0.0, "t0": None, "it": 0, "out": []}

    def callback(x):
        state["it"] += 1
        if state["it"] in marks:
            state["t"] += time.perf_counter() - state["t0"]
            state["out"].append({"iteration": state["it"], "time_s": state["t"],
                                 "psnr": psnr(x.reshape(shape), truth)})
            state["t0"] = time.perf_counter()

    x0 = np.zeros(n)
    pyproximal.optimization.primaldual.PrimalDual(proxf, proxg, K, x0=x0, tau=step, mu=step,
                                                  niter=2, show=False)  # warm-up
    state["t0"] = time.perf_counter()
    pyproximal.optimization.primaldual.PrimalDual(proxf, proxg, K, x0=x0, tau=step, mu=step,
                                                  niter=iters, callback=callback, show=False)
    return state["out"]


# ---------------------------------------------------------------------------------------
# scikit-image
# ---------------------------------------------------------------------------------------
def run_skimage_wiener(y, cam, truth, balance: float, repeats: int) -> list[dict]:
    from skimage import restoration

    H = transfer_function(cam.shape, cam.pitch, cam.r1p, half=False)
    psf = np.fft.fftshift(np.real(np.fft.ifft2(H)))
    restoration.wiener(y, psf, balance, clip=False)
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        x = restoration.wiener(y, psf, balance, clip=False)
        walls.append(time.perf_counter() - t0)
    return [{"iteration": 1, "time_s": statistics.median(walls), "psnr": psnr(x, truth)}]


# ---------------------------------------------------------------------------------------
# LenslessPiCam (its own environment: bench/peer_lensless_worker.py)
# ---------------------------------------------------------------------------------------
LENSLESS_PY = Path(__file__).resolve().parent.parent / ".venv-lensless" / "bin" / "python"
LENSLESS_TAUS = (1e-5, 1e-4, 1e-3)
LENSLESS_ITERS = 100  # ~0.25 s per iteration at 512^2 on 2 cores


def run_lensless(y, cam, truth, iters: int) -> list[dict]:
    """LenslessPiCam's ADMM (l1 of the gradient, non-negativity, its default penalties) with
    the exact model's kernel cut to the sensor (its model: pad, convolve, crop), unit L2 norm,
    and the frame scaled to a maximum of 1, as its loaders do; ``tau`` swept."""
    import subprocess
    import tempfile

    model = camera_model(cam)
    k, (h, w) = model.kernel, cam.shape
    cy, cx = k.shape[0] // 2, k.shape[1] // 2
    psf = np.zeros((h, w))
    ky, kx = min(h, k.shape[0]), min(w, k.shape[1])
    psf[h // 2 - ky // 2:h // 2 - ky // 2 + ky, w // 2 - kx // 2:w // 2 - kx // 2 + kx] = \
        k[cy - ky // 2:cy - ky // 2 + ky, cx - kx // 2:cx - kx // 2 + kx]
    psf /= np.linalg.norm(psf)
    marks = checkpoints(iters)
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(src, psf=psf, y=y / np.abs(y).max(), taus=np.array(LENSLESS_TAUS),
                 marks=np.array(marks))
        subprocess.run([str(LENSLESS_PY), str(Path(__file__).with_name(
            "peer_lensless_worker.py")), str(src), str(dst)], check=True)
        out = np.load(dst)
        images, times = out["images"], out["times"]
    runs = []
    for i, tau in enumerate(LENSLESS_TAUS):
        runs.append({"setting": {"tau": tau}, "trace": [
            {"iteration": k, "time_s": float(times[i, j]), "psnr": psnr(images[i, j], truth)}
            for j, k in enumerate(marks)]})
    return runs


# ---------------------------------------------------------------------------------------
def time_to_levels(runs: list[dict], levels: list[float]) -> dict:
    """Per level: the least time over a tool's runs at which its PSNR first reached it."""
    out = {}
    for lv in levels:
        best = None
        for run in runs:
            for p in run["trace"]:
                if p["psnr"] >= lv:
                    if best is None or p["time_s"] < best[0]:
                        best = (p["time_s"], run["setting"])
                    break
        out[str(lv)] = None if best is None else {"time_s": best[0], "setting": best[1]}
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    p.add_argument("--iters", type=int, default=200, help="ADMM iterations (PDHG: 2x)")
    p.add_argument("--exact-iters", type=int, default=60)
    p.add_argument("--cg-iters", type=int, default=8)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--quick", action="store_true", help="3 lam, 1 rho, 50 iterations")
    p.add_argument("--tools", nargs="+", default=["clfza", "scico", "scico-exact",
                                                  "pyproximal", "lensless", "wiener"])
    p.add_argument("--out", default=str(RESULTS))
    p.add_argument("--tag", default="")
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    lam_f = (0.5, 1.0, 2.0) if a.quick else LAM_FACTORS
    rho_f = (10.0,) if a.quick else RHO_FACTORS
    iters = 50 if a.quick else a.iters
    res = {"machine": machine_record(), "load_start": os.getloadavg(), "cases": {},
           "versions": versions(), "iters": iters}
    for case in a.cases:
        cam, y, truth = make_case(CASES[case])
        tau0 = clfza_auto_tau(y, cam)
        lam0 = tau0 / 2
        print(f"== {case}: clfza's Eq. 17 tau='auto' = {tau0:.4g} (lam0 = {lam0:.4g})",
              flush=True)
        tools: dict[str, list[dict]] = {}
        if "clfza" in a.tools:
            r = run_clfza_default(y, cam, truth, a.repeats)
            tools["clfza default"] = [r]
            print(f"  clfza default: {r['trace'][0]['psnr']:.2f} dB in "
                  f"{r['trace'][0]['time_s']:.2f} s ({r['setting']})", flush=True)
        if "scico" in a.tools:
            tools["scico ADMM (Eq. 17)"] = runs = []
            for lf in lam_f:
                for rf in rho_f:
                    lam, rho = lam0 * lf, lam0 * lf * rf
                    tr = run_scico_tf(y, cam, truth, lam, rho, iters)
                    runs.append({"setting": {"lam": lam, "rho": rho}, "trace": tr})
                    print(f"  scico tf lam {lam:.3g} rho {rho:.3g}: {tr[-1]['psnr']:.2f} dB "
                          f"in {tr[-1]['time_s']:.2f} s", flush=True)
        if "scico-exact" in a.tools:
            tools["scico ADMM (exact)"] = runs = []
            for lf in ((0.25, 1.0) if case == "clean" else (1.0,)):
                lam = lam0 * lf
                rho = lam * 10
                tr = run_scico_exact(y, cam, truth, lam, rho, 20 if a.quick else a.exact_iters,
                                     a.cg_iters)
                runs.append({"setting": {"lam": lam, "rho": rho, "cg": a.cg_iters},
                             "trace": tr})
                print(f"  scico exact lam {lam:.3g}: {tr[-1]['psnr']:.2f} dB in "
                      f"{tr[-1]['time_s']:.2f} s", flush=True)
        if "pyproximal" in a.tools:
            tools["pyproximal PDHG (Eq. 17)"] = runs = []
            for lf in lam_f:
                lam = lam0 * lf
                tr = run_pyproximal_tf(y, cam, truth, lam, 2 * iters)
                runs.append({"setting": {"lam": lam}, "trace": tr})
                print(f"  pyproximal lam {lam:.3g}: {tr[-1]['psnr']:.2f} dB in "
                      f"{tr[-1]['time_s']:.2f} s", flush=True)
        if "lensless" in a.tools and LENSLESS_PY.exists():
            runs = run_lensless(y, cam, truth, min(iters, LENSLESS_ITERS))
            tools["LenslessPiCam ADMM"] = runs
            for r in runs:
                print(f"  lensless tau {r['setting']['tau']:.0e}: {r['trace'][-1]['psnr']:.2f} "
                      f"dB in {r['trace'][-1]['time_s']:.2f} s", flush=True)
        if "wiener" in a.tools:
            tools["scikit-image Wiener"] = runs = []
            for b in BALANCES:
                tr = run_skimage_wiener(y, cam, truth, b, a.repeats)
                runs.append({"setting": {"balance": b}, "trace": tr})
            best = max(runs, key=lambda r: r["trace"][0]["psnr"])
            print(f"  wiener best balance {best['setting']['balance']}: "
                  f"{best['trace'][0]['psnr']:.2f} dB", flush=True)
        res["cases"][case] = {
            "noise_var": CASES[case], "clfza_tau_auto_tf": tau0, "levels": LEVELS[case],
            "tools": tools,
            "time_to_level": {t: time_to_levels(r, LEVELS[case]) for t, r in tools.items()},
            "best_psnr": {t: max(p["psnr"] for run in r for p in run["trace"])
                          for t, r in tools.items()},
            # what finding the hindsight setting costs: every swept run to its end
            "sweep_s": {t: sum(run["trace"][-1]["time_s"] for run in r)
                        for t, r in tools.items()}}
    res["load_end"] = os.getloadavg()
    slug = machine_slug(res["machine"]) + (f"_{a.tag}" if a.tag else "")
    write_result_files(Path(a.out) / f"peers_{slug}", res, markdown(res), plot)
    print(markdown(res))
    return 0


def versions() -> dict:
    out = {"clfza": clfza.__version__}
    for name in ("scico", "jax", "pyproximal", "pylops", "skimage", "numpy", "scipy"):
        try:
            out[name] = __import__(name).__version__
        except Exception:  # noqa: BLE001 - a missing peer is reported, not fatal
            out[name] = None
    return out


def markdown(res: dict) -> str:
    m = res["machine"]
    dev = m.get("device")
    dev = dev.get("name", dev) if isinstance(dev, dict) else dev
    lines = ["# clfza's defaults against peers: time to each PSNR level", "",
             f"{m.get('cpu_model', '')} ({m.get('cores_usable')} usable cores); "
             f"{m.get('date', '')}; clfza on {dev}; "
             f"versions {res['versions']}; load average {res['load_start']} -> "
             f"{res['load_end']}. Produced by `bench/bench_peers.py` (its docstring: the "
             "case, the operators, the hindsight tuning). Seconds; '-' = never reached in the "
             "budget.", ""]
    for case, c in res["cases"].items():
        lv = c["levels"]
        lines += [f"## {case} (noise variance {c['noise_var']})", "",
                  "| tool | best PSNR | runs (sweep s) | " + " | ".join(f"{x:g} dB" for x in lv)
                  + " |", "|---|---|---|" + "---|" * len(lv)]
        for tool, ttl in c["time_to_level"].items():
            cells = [("-" if ttl[str(x)] is None else f"{ttl[str(x)]['time_s']:.2f}")
                     for x in lv]
            lines.append(f"| {tool} | {c['best_psnr'][tool]:.2f} | {len(c['tools'][tool])} "
                         f"({c['sweep_s'][tool]:.1f}) | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(res["cases"])
    fig, axes = plt.subplots(1, len(cases), figsize=(6 * len(cases), 4.5), squeeze=False)
    for ax, case in zip(axes[0], cases, strict=True):
        c = res["cases"][case]
        for k, (tool, runs) in enumerate(c["tools"].items()):
            col = f"C{k}"
            for run in runs:
                t = [p["time_s"] for p in run["trace"]]
                q = [p["psnr"] for p in run["trace"]]
                if len(t) == 1:
                    ax.plot(t, q, "o" if tool.startswith("clfza") else ".", color=col,
                            ms=9 if tool.startswith("clfza") else 5)
                else:
                    ax.plot(t, q, "-", color=col, lw=0.8, alpha=0.6)
            ax.plot([], [], "-o", color=col, label=tool)
        ax.set_xscale("log")
        ax.set_xlabel("seconds")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(f"{case} (noise variance {c['noise_var']})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
