"""Measured-PSF reconstruction: clfza's crop-split ADMM against LenslessPiCam's ADMM (PyPI
``lensless``) on the same PSF and measurement, in one run.

LenslessPiCam pins numpy 1.26 and pulls opencv, hydra and more, so it lives in a bench-only
environment, never in clfza's dependencies::

    python3 -m venv .venv-lensless
    .venv-lensless/bin/pip install lensless && .venv-lensless/bin/pip install -e ".[pocl]"
    .venv-lensless/bin/pip install "numpy==1.26.4"
    .venv-lensless/bin/python bench/bench_lensless.py

The camera: an FZA mask with a finite aperture (the ``experiment`` preset's geometry on an
``N x N`` sensor), its shadow cut to the frame as the "measured" PSF (both tools get the same
array, normalised to unit L2 norm as LenslessPiCam's loader does, and the frame normalised to a
maximum of 1). The measurement is the linear convolution of ``skimage.data.camera`` (on the
sensor) with that PSF, cropped to the sensor: LenslessPiCam's own forward model. Error:
PSNR after the affine fit of ``clfza.metrics.compare`` on the object's footprint. Time: wall
time of the iterations only (set-up, kernel compilation and FFT planning excluded for both),
median of ``--repeats`` runs; each tool runs with its own defaults (LenslessPiCam: mu1 = 1e-6,
mu2 = 1e-5, mu3 = 4e-5, tau = 1e-4; clfza: its defaults for tau and penalties).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
from skimage import data
from skimage.transform import resize

import clfza
from clfza import Camera
from clfza.metrics import compare
from clfza.models._exact import ExactModel, shadow_kernel

CHECKPOINTS = (5, 10, 20, 50, 100, 200, 300)


def setup(n: int):
    """PSF (n x n, centred, unit L2 norm), measurement (max 1), truth on the sensor."""
    cam0 = Camera.preset("experiment")
    cam = cam0.with_shape((n, n), cam0.pitch * 2400 / n)
    k = shadow_kernel(cam)
    c, h = k.shape[0] // 2, n // 2
    if k.shape[0] >= n:  # the shadow cut to the frame (centre at n // 2)
        psf = k[c - h:c - h + n, c - h:c - h + n]
    else:
        psf = np.pad(k, ((h - c, n - (h - c) - k.shape[0]),) * 2)
    psf = psf / np.linalg.norm(psf)
    truth = np.zeros((n, n))
    m = n // 3
    truth[m:2 * m, m:2 * m] = resize(data.camera() / 255.0, (m, m), anti_aliasing=True)
    model = ExactModel(psf, (n, n))
    y = model.crop(model.conv(model.geom.embed(truth)))  # C (h * o), no mean removal
    scale = y.max()
    return cam, psf, y / scale, truth, (slice(m, 2 * m), slice(m, 2 * m))


def run_lensless(psf, y, truth, fp, iters):
    from lensless.recon.admm import ADMM

    rec = ADMM(psf[None, :, :, None].astype(np.float32))
    rec.set_data(y[None, :, :, None].astype(np.float32))
    out, done, t = [], 0, 0.0
    for k in iters:
        t0 = time.perf_counter()
        img = rec.apply(n_iter=k - done, disp_iter=None, plot=False, reset=done == 0)
        t += time.perf_counter() - t0
        done = k
        img = np.asarray(img).reshape(y.shape)
        out.append((k, t, compare(img[fp], truth[fp])["psnr"]))
    return out


def run_clfza(cam, psf, y, truth, fp, iters):
    out = []
    for k in iters:
        img, info = clfza.reconstruct(y, cam.with_shape(y.shape), "admm", psf=psf, iters=k,
                                      stop="none")
        out.append((k, info.timings["solve"], compare(img[fp], truth[fp])["psnr"]))
    return out


def time_to(trace, target):
    """First time a trace reaches ``target`` dB, linearly interpolated; None if never."""
    prev = (0, 0.0, -np.inf)
    for k, t, p in trace:
        if p >= target:
            if prev[2] == -np.inf:
                return t
            return prev[1] + (t - prev[1]) * (target - prev[2]) / (p - prev[2])
        prev = (k, t, p)
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="256,512")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="bench/results")
    a = ap.parse_args()
    from clfza.cl import get_runtime

    rt = get_runtime()
    rows = []
    for n in (int(s) for s in a.sizes.split(",")):
        cam, psf, y, truth, fp = setup(n)
        clfza.reconstruct(y, cam.with_shape(y.shape), "admm", psf=psf, iters=2)  # warm-up
        runs_l = [run_lensless(psf, y, truth, fp, CHECKPOINTS) for _ in range(a.repeats)]
        runs_c = [run_clfza(cam, psf, y, truth, fp, CHECKPOINTS) for _ in range(a.repeats)]
        med = [lambda runs, i=i: (runs[0][i][0], float(np.median([r[i][1] for r in runs])),
                                  runs[0][i][2]) for i in range(len(CHECKPOINTS))]
        tl = [m(runs_l) for m in med]
        tc = [m(runs_c) for m in med]
        # a level both reach: 0.5 dB under LenslessPiCam's best in 300 iterations (its best
        # itself is a plateau it touches late, which would flatter the ratio)
        target = max(p for _, _, p in tl) - 0.5
        t_l, t_c = time_to(tl, target), time_to(tc, target)
        row = {"n": n, "lensless": tl, "clfza": tc, "target_psnr": round(target, 2),
               "lensless_time_to_target_s": t_l, "clfza_time_to_target_s": t_c,
               "speedup": None if not (t_l and t_c) else t_l / t_c,
               "ms_per_iteration": {"lensless": 1e3 * tl[-1][1] / tl[-1][0],
                                    "clfza": 1e3 * tc[-1][1] / tc[-1][0]}}
        rows.append(row)
        print(f"N = {n}: target {target:.2f} dB (LenslessPiCam's best in 300 its - 0.5 dB)")
        for (k, t1, p1), (_, t2, p2) in zip(tl, tc, strict=True):
            print(f"  {k:4d} it  lensless {t1:7.2f} s {p1:6.2f} dB   clfza {t2:7.2f} s "
                  f"{p2:6.2f} dB")
        print(f"  time to {target:.2f} dB: lensless {t_l}, clfza {t_c}; speed-up "
              f"{row['speedup']}")
    import lensless
    rec = {"benchmark": "measured_psf_vs_lensless", "rows": rows, "device": rt.info.name,
           "platform": rt.info.platform, "machine": platform.processor() or platform.machine(),
           "numpy": np.__version__, "lensless": getattr(lensless, "__version__", "1.0.8"),
           "clfza": clfza.__version__, "date": time.strftime("%Y-%m-%d"),
           "load_average": list(__import__("os").getloadavg()),
           "normalisation": "object footprint, affine fit (clfza.metrics.compare)"}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "lensless_vs_clfza.json").write_text(json.dumps(rec, indent=1))
    _plot(rows, out / "lensless_vs_clfza.png")


def _plot(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(rows), figsize=(5 * len(rows), 3.6), squeeze=False)
    for ax, row in zip(axes[0], rows, strict=True):
        for name in ("lensless", "clfza"):
            tr = row[name]
            ax.plot([t for _, t, _ in tr], [p for _, _, p in tr], "o-", label=name)
        ax.set_xscale("log")
        ax.set_xlabel("solve time (s)")
        ax.set_ylabel("footprint PSNR (dB)")
        ax.set_title(f"ADMM, measured PSF, {row['n']}^2")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
