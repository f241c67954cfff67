"""Issue 33: which forward model the default route should take, by noise level.

Usage::

    python bench/bench_default_route.py [--n 512] [--scenes camera astronaut]
                                        [--noise 0 1e-5 1e-4 1e-3 1e-2] [--out bench/results]

On the ``simulation`` preset (the paper's Fig. 7 camera: no aperture, r1'^2/(N p^2) = 1.37, where
``model="auto"`` ran ADMM on the exact model whatever the noise), for each scene and Gaussian
noise variance on y: ADMM with ``tau="auto"`` on the transfer-function model (Eq. 17) and on
the exact model, their PSNR (after the affine fit of :func:`clfza.metrics.compare`) and solve
times, beside the two energies the routing rule compares (:func:`clfza.solvers.model_error`):
the noise's ``N sigma^2`` (sigma estimated from the frame) and the transfer-function model's
error on the frame's own Wiener estimate, ``||K_exact x - K_tf x||^2``. Writes
``bench/results/default_route_<machine>.json`` / ``.md`` / ``.png``.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import clfza  # noqa: E402
from clfza.benchmarks._machine import machine_record  # noqa: E402
from clfza.benchmarks._report import write_result_files  # noqa: E402
from clfza.metrics import compare  # noqa: E402
from clfza.solvers import estimate_noise, model_error  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def scene(name: str) -> np.ndarray:
    from skimage import color, data

    img = getattr(data, name)()
    return color.rgb2gray(img) if img.ndim == 3 else img / 255.0


def run(y, cam, truth, model: str) -> dict:
    t0 = time.perf_counter()
    rec = clfza.reconstruct(y, cam, "admm", model=model, tau="auto")
    wall = time.perf_counter() - t0
    return {"psnr": compare(rec.image, truth)["psnr"], "wall_s": wall,
            "solve_s": rec.info.timings.get("solve", 0.0) + rec.info.timings.get(
                "tau_search", 0.0), "tau": rec.info.params.get("tau"),
            "iterations": rec.info.iterations}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=512)
    p.add_argument("--scenes", nargs="+", default=["camera", "astronaut"])
    p.add_argument("--noise", type=float, nargs="+", default=[0.0, 1e-5, 1e-4, 1e-3, 1e-2])
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    cam = clfza.Camera.preset("simulation")
    if a.n != cam.shape[0]:
        cam = cam.with_shape((a.n, a.n))
    rows = []
    for sc in a.scenes:
        for v in a.noise:
            meas = clfza.simulate(scene(sc), cam, object_width=20.0,
                                  noise=clfza.Noise(gaussian_var=v, seed=1))
            y, truth = meas.y, meas.truth
            sigma = estimate_noise(y, cam)[0]
            err = model_error(y, cam)
            row = {"scene": sc, "noise_var": v, "sigma_est": sigma,
                   "noise_energy": y.size * sigma**2, "tf_error_energy": err,
                   "y_energy": float(np.sum(y**2)),
                   "tf": run(y, cam, truth, "tf"), "exact": run(y, cam, truth, "exact")}
            rows.append(row)
            print(f"{sc:10s} var {v:7.0e}: N sigma^2 {row['noise_energy']:10.3g}, TF error "
                  f"{err:10.3g} (ratio {row['noise_energy'] / err:8.3g}); tf "
                  f"{row['tf']['psnr']:5.2f} dB {row['tf']['wall_s']:5.2f} s, exact "
                  f"{row['exact']['psnr']:5.2f} dB {row['exact']['wall_s']:5.2f} s", flush=True)
    res = {"machine": machine_record(), "n": a.n, "rows": rows}
    write_result_files(Path(a.out) / f"default_route_{a.n}", res, markdown(res), plot)
    print(markdown(res))
    return 0


def markdown(res: dict) -> str:
    lines = [f"# ADMM, tau='auto', by forward model and noise ({res['n']}^2 simulation preset)",
             "", f"{res['machine'].get('cpu', '')}; {res['machine'].get('date', '')}.", "",
             "| scene | noise var | N sigma^2 (est.) | TF model error | ratio | Eq. 17 PSNR | "
             "s | exact PSNR | s |", "|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {r['scene']} | {r['noise_var']:.0e} | {r['noise_energy']:.3g} | "
                     f"{r['tf_error_energy']:.3g} | "
                     f"{r['noise_energy'] / r['tf_error_energy']:.3g} | "
                     f"{r['tf']['psnr']:.2f} | {r['tf']['wall_s']:.2f} | "
                     f"{r['exact']['psnr']:.2f} | {r['exact']['wall_s']:.2f} |")
    return "\n".join(lines) + "\n"


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for sc in sorted({r["scene"] for r in res["rows"]}):
        rs = [r for r in res["rows"] if r["scene"] == sc]
        ratio = [r["noise_energy"] / r["tf_error_energy"] for r in rs]
        ax.semilogx(ratio, [r["tf"]["psnr"] - r["exact"]["psnr"] for r in rs], "o-", label=sc)
    ax.axhline(0, color="grey", lw=1)
    ax.set_xlabel("N sigma^2 / TF model error")
    ax.set_ylabel("PSNR(Eq. 17) - PSNR(exact), dB")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
