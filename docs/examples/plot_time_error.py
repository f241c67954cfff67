"""
Time against error
==================

How fast does each method reach a given quality? :func:`clfza.reconstruct` records the error
along the way when given the truth and the iterations to check (the run controls ``truth=``
and ``checkpoints=``): each entry of ``info.checkpoints`` holds the iteration, the solve's
time so far (the clock pauses while the error is computed) and the PSNR and SSIM against the
truth after an affine fit, as :func:`clfza.metrics.compare` computes them.

The scene is the paper's Fig. 7 case on the simulation preset (512^2 pixels, Gaussian noise
of variance 0.01 on ``y``); each iterative method runs with ``tau="auto"``, and its curve's
times include the search for tau (``info.timings["tau_search"]``), which runs before the
solve. The kernels are compiled once before any clock starts. Back-propagation and the
Wiener solve are one step each: one point. ``clfza bench`` runs the same measurement over
scenes, noises, sizes and backends; its results are on the performance pages.
"""

import matplotlib.pyplot as plt
from skimage import data

import clfza

cam = clfza.Camera.preset("simulation")
meas = clfza.simulate(data.camera(), cam, object_width=20.0,
                      noise=clfza.Noise(gaussian_var=0.01, seed=0))
clfza.reconstruct(meas.y, cam, "admm", iters=1, model="tf")  # compile the kernels first

checkpoints = [1, 2, 3, 5, 10, 20, 30, 50, 100]
curves = {"TwIST-TV (paper mode)": ("twist", {"mode": "paper", "iters": 100}),
          "FISTA-TV": ("fista", {"iters": 100}),
          "ADMM-TV, Eq. 17": ("admm", {"iters": 100, "model": "tf"})}
fig, ax = plt.subplots(figsize=(6.4, 4.2))
for label, (method, opts) in curves.items():
    image, info = clfza.reconstruct(meas.y, cam, method, tau="auto", truth=meas.truth,
                                    checkpoints=checkpoints, **opts)
    search = info.timings.get("tau_search", 0.0)  # choosing tau comes before the solve
    t = [search + c["time"] for c in info.checkpoints]
    psnr = [c["psnr"] for c in info.checkpoints]
    ax.plot(t, psnr, "o-", ms=3, label=label)
    print(f"{label:24s} {psnr[-1]:6.2f} dB after {info.checkpoints[-1]['iteration']} "
          f"iterations, {t[-1]:.2f} s")

for label, method in (("back-propagation", "bp"), ("Wiener", "wiener")):
    image, info = clfza.reconstruct(meas.y, cam, method)
    psnr = clfza.metrics.compare(image, meas.truth)["psnr"]
    ax.plot([info.timings["solve"]], [psnr], "s", ms=7, label=label)
    print(f"{label:24s} {psnr:6.2f} dB in {info.timings['solve']:.3f} s")

ax.set_xscale("log")
ax.set_xlabel(f"solve time (s) on {info.device}")
ax.set_ylabel("PSNR against the truth (dB)")
ax.set_title("512^2, Gaussian noise of variance 0.01 (the paper's Fig. 7)", fontsize=10)
ax.grid(True, which="both", alpha=0.3)
ax.legend(fontsize=8)
fig.tight_layout()
plt.show()
