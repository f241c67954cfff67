"""
Every method side by side
=========================

The paper's simulation setup (``Camera.preset("simulation")``: 512^2 pixels of 10 um, a
zone plate with r1 = 0.23 mm, the object 20 mm in front of the mask and the sensor 3 mm
behind it) records scikit-image's *camera* image with the paper's Fig. 7 noise (Gaussian,
variance 0.01 on ``y``). Every method of :func:`clfza.reconstruct` then runs on it:

* back-propagation (``"bp"``, Eqs. 11-12): one correlation with the mask, the image plus
  its twin;
* the direct Wiener/Tikhonov solve (``"wiener"``): one FFT pair, its weight from the noise;
* TwIST with total variation as the paper runs it (``"twist"``, ``mode="paper"``, Eqs.
  19-21);
* FISTA with total variation (``"fista"``);
* ADMM with total variation (``"admm"``) on the transfer-function model (Eq. 17).

The three iterative methods choose their ``tau`` from the frame (``tau="auto"``, see the
user guide's page on choosing tau) and run 50 iterations each: enough for ADMM and FISTA,
not for TwIST as the paper runs it, which converges slowly (the time-against-error example
follows each method further). Each panel gives the PSNR against the sensor-plane truth
after an affine fit (:func:`clfza.metrics.compare`: a reconstruction is defined up to offset
and scale) and the solve's time on this build's OpenCL device, kernel compilation excluded
(``info.timings["solve"]``). Size: 512^2; a few seconds in all.
"""

import matplotlib.pyplot as plt
from skimage import data

import clfza

cam = clfza.Camera.preset("simulation")
meas = clfza.simulate(data.camera(), cam, object_width=20.0,
                      noise=clfza.Noise(gaussian_var=0.01, seed=0))

runs = [("back-propagation", "bp", {}),
        ("Wiener", "wiener", {}),
        ("TwIST-TV (paper mode)", "twist", {"mode": "paper", "iters": 50, "tau": "auto"}),
        ("FISTA-TV", "fista", {"iters": 50, "tau": "auto"}),
        ("ADMM-TV, Eq. 17", "admm", {"iters": 50, "model": "tf", "tau": "auto"})]
clfza.reconstruct(meas.y, cam, "admm", iters=1, model="tf")  # compile the kernels first
panels = [("truth (sensor plane)", meas.truth), ("raw frame y", meas.y)]
for label, method, opts in runs:
    image, info = clfza.reconstruct(meas.y, cam, method, **opts)
    psnr = clfza.metrics.compare(image, meas.truth)["psnr"]
    panels.append((f"{label}\n{psnr:.1f} dB, {info.timings['solve']:.2f} s", image))
    print(f"{label:24s} {psnr:6.2f} dB  {info.iterations:3d} iterations  on {info.device}")

fig, axes = plt.subplots(2, 4, figsize=(11, 6.2))
for ax in axes.flat:
    ax.axis("off")
for ax, (title, img) in zip(axes.flat, panels, strict=False):
    ax.imshow(img, cmap="gray")
    ax.set_title(title, fontsize=9)
fig.tight_layout()
plt.show()
