"""Issue 33: the default route's speed on Eq. 17, one setting against another in one run.

Usage::

    python bench/bench_eq17_route.py [--compare final_stop|refine] [--n 512]
                                     [--scenes camera astronaut text brick] [--rounds 2]
                                     [--device SPEC] [--out bench/results]

On the ``simulation`` preset (the paper's Fig. 7 camera) at ``--n``^2, each scene at Gaussian
noise variance 1e-3 and 1e-2 and at 1e3 and 1e4 photons (the frames where the default route
takes Eq. 17), ``clfza.reconstruct(y, cam)`` (ADMM, ``tau="auto"``) as it is against one
other setting (``--compare``):

* ``final_stop``: the final solve's stop after the discrepancy search (the spread of the
  objective over ``FINAL_STOP_WINDOW`` iterations at ``FINAL_TOL``,
  :func:`clfza.solvers._tau.final_options`) against ``tol=1e-6``, the one-step objective rule
  it used before;
* ``refine``: the search's refinement stages of ``REFINE_FACTOR`` x the search's stage length
  (clfza.solvers._tau) against 3x, the factor before.

The two run interleaved per case and round, the order alternating. Reported: PSNR against the
truth (the affine fit of :func:`clfza.metrics.compare`), the chosen tau, the iterations of
the search's stages and of the final solve, and the wall seconds of the call (medians over
the rounds) and their ratio. Writes ``bench/results/eq17_route_<compare>_<machine>.json`` /
``.md`` / ``.png``.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_tau import revision  # noqa: E402

import clfza  # noqa: E402
from clfza.benchmarks._machine import machine_record, machine_slug  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.io import write_figure  # noqa: E402
from clfza.metrics import compare  # noqa: E402
from clfza.solvers import _tau  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
NOISES = {"gauss1e-3": {"gaussian_var": 1e-3}, "gauss1e-2": {"gaussian_var": 1e-2},
          "photons1e3": {"photons": 1e3}, "photons1e4": {"photons": 1e4}}
#: --compare: (the setting it is measured against: its label, the options it passes, the
#: clfza.solvers._tau constants it patches; what the current setting is)
COMPARISONS = {
    "final_stop": ("one-step 1e-6", {"tol": 1e-6}, {},
                   lambda: f"the spread of the objective over {_tau.FINAL_STOP_WINDOW} "
                           f"iterations at {_tau.FINAL_TOL:g}"),
    "refine": ("refine 3x", {}, {"REFINE_FACTOR": 3},
               lambda: f"refinement stages of {_tau.REFINE_FACTOR}x the stage length"),
}


def scene(name: str) -> np.ndarray:
    from skimage import color, data

    img = getattr(data, name)()
    return color.rgb2gray(img) if img.ndim == 3 else img / 255.0


@contextlib.contextmanager
def patched(constants: dict):
    """clfza.solvers._tau's ``constants`` set for the block, restored after."""
    saved = {k: getattr(_tau, k) for k in constants}
    try:
        for k, v in constants.items():
            setattr(_tau, k, v)
        yield
    finally:
        for k, v in saved.items():
            setattr(_tau, k, v)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--compare", choices=sorted(COMPARISONS), default="final_stop")
    p.add_argument("--n", type=int, default=512)
    p.add_argument("--scenes", nargs="+", default=["camera", "astronaut", "text", "brick"])
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--device", default=None, help="OpenCL device spec (default: clfza's)")
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    if a.rounds < 1 or a.n < 16:
        p.error(f"--rounds must be >= 1 and --n >= 16, got {a.rounds} and {a.n}")
    warnings.simplefilter("ignore")
    other, options, constants, describe = COMPARISONS[a.compare]
    variants = {"default": ({}, {}), other: (options, constants)}
    cam = clfza.Camera.preset("simulation")
    if a.n != cam.shape[0]:
        cam = cam.with_shape((a.n, a.n))
    cases = []
    for sc in a.scenes:
        for nz, kw in NOISES.items():
            m = clfza.simulate(scene(sc), cam, object_width=20.0, noise=clfza.Noise(**kw, seed=1))
            cases.append({"scene": sc, "noise": nz, "meas": m, "runs": {v: [] for v in variants}})
    clfza.reconstruct(cases[0]["meas"].y, cam, device=a.device)  # warm-up: kernel builds
    for rnd in range(a.rounds):
        for i, c in enumerate(cases):
            order = list(variants) if (rnd + i) % 2 == 0 else list(variants)[::-1]
            for v in order:
                opts, consts = variants[v]
                with patched(consts):
                    t0 = time.perf_counter()
                    rec = clfza.reconstruct(c["meas"].y, cam, device=a.device, **opts)
                    wall = time.perf_counter() - t0
                auto = rec.info.stats.get("tau_auto", {})
                c["runs"][v].append({
                    "wall_s": wall, "psnr": compare(rec.image, c["meas"].truth)["psnr"],
                    "iterations": rec.info.iterations, "model": rec.info.params["model"],
                    "tau": rec.info.params["tau"], "stop_reason": rec.info.stop_reason,
                    "search_iterations": auto.get("stage_iterations_total"),
                    "search_s": rec.info.timings.get("tau_search", 0.0),
                    "solve_s": rec.info.timings.get("solve", 0.0)})
            print(f"round {rnd}: {c['scene']:10s} {c['noise']:11s} " + "  ".join(
                f"{v}: {c['runs'][v][-1]['psnr']:.2f} dB {c['runs'][v][-1]['iterations']:3d} it "
                f"{c['runs'][v][-1]['wall_s']:.3f} s" for v in variants), flush=True)
    rows = []
    for c in cases:
        r = {"scene": c["scene"], "noise": c["noise"], "runs": c["runs"]}
        for v in variants:
            runs = c["runs"][v]
            r[v] = {k: runs[-1][k] for k in ("psnr", "iterations", "model", "tau",
                                              "search_iterations")}
            r[v].update({k: statistics.median(x[k] for x in runs)
                         for k in ("wall_s", "search_s", "solve_s")})
        rows.append(r)
    res = {"machine": machine_record(a.device), "revision": revision(), "n": a.n,
           "rounds": a.rounds, "compare": a.compare, "other": other,
           "default_setting": describe(), "other_setting": {**options, **constants},
           "rows": rows}
    text = markdown(res)
    write_result_files(Path(a.out) / f"eq17_route_{a.compare}_{machine_slug(res['machine'])}",
                       res, text, plot)
    print(text)
    return 0


def markdown(res: dict) -> str:
    m, o = res["machine"], res["other"]
    d = [r["default"]["psnr"] - r[o]["psnr"] for r in res["rows"]]
    wr = [r["default"]["wall_s"] / r[o]["wall_s"] for r in res["rows"]]
    it = [r["default"]["iterations"] / r[o]["iterations"] for r in res["rows"]]
    st = [(r["default"]["search_iterations"] or 0) / max(r[o]["search_iterations"] or 0, 1)
          for r in res["rows"]]
    other = ", ".join(f"{k}={v:g}" for k, v in res["other_setting"].items())
    lines = [
        f"# The default route on Eq. 17: {res['compare']} ({res['n']}^2 simulation preset)", "",
        f"{m.get('cpu_model', '')}, {(m.get('device') or {}).get('describe', '')}; "
        f"{m.get('date', '')}; revision {(res['revision']['commit'] or '?')[:7]}"
        f"{' (clfza modified)' if res['revision']['clfza_modified'] else ''}; "
        f"{res['rounds']} interleaved rounds, wall medians. `default`: "
        f"{res['default_setting']}; `{o}`: {other}. Produced by "
        f"`bench/bench_eq17_route.py --compare {res['compare']}`.", "",
        f"PSNR change mean {np.mean(d):+.3f} dB, worst {min(d):+.3f} dB; search iterations "
        f"x{np.mean(st):.2f}, final iterations x{np.mean(it):.2f} (mean ratios); wall "
        f"x{statistics.median(wr):.2f} (median ratio, range {min(wr):.2f}-{max(wr):.2f}).", "",
        f"| scene | noise | model | PSNR default | PSNR {o} | tau ratio | search its | final its "
        f"default | final its {o} | wall default | wall {o} | ratio |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r, ratio in zip(res["rows"], wr, strict=True):
        a, b = r["default"], r[o]
        lines.append(f"| {r['scene']} | {r['noise']} | {a['model']} | {a['psnr']:.2f} | "
                     f"{b['psnr']:.2f} | {a['tau'] / b['tau']:.3f} | "
                     f"{a['search_iterations']} / {b['search_iterations']} | "
                     f"{a['iterations']} | {b['iterations']} | {a['wall_s']:.3f} | "
                     f"{b['wall_s']:.3f} | {ratio:.2f} |")
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    o = res["other"]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for k, nz in enumerate(NOISES):
        rs = [r for r in res["rows"] if r["noise"] == nz]
        ax.plot([r["default"]["wall_s"] / r[o]["wall_s"] for r in rs],
                [r["default"]["psnr"] - r[o]["psnr"] for r in rs], "o", color=f"C{k}",
                label=nz)
    ax.axhline(0, color="grey", lw=1)
    ax.axvline(1, color="grey", lw=1)
    ax.set_xlabel(f"wall time, default / {o}")
    ax.set_ylabel("PSNR change (dB)")
    ax.set_title(f"{res['compare']}: {res['default_setting']}", fontsize=9)
    ax.legend(fontsize=8)
    write_figure(path, fig, force=True)  # atomically, the layout fitted
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
