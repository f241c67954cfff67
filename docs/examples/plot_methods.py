"""
Back-propagation, TwIST and ADMM side by side
=============================================

The paper's simulation setup (``Camera.preset("simulation")``: 512^2 pixels of 10 um, a
zone plate with r1 = 0.23 mm, the object 20 mm in front of the mask and the sensor 3 mm
behind it) records scikit-image's *camera* image. Back-propagation (Eq. 12) is one
correlation with the mask: the image plus its twin. TwIST with total variation as the paper
runs it, and ADMM on the transfer-function model (Eq. 17), remove the twin. Each panel gives
the PSNR against the sensor-plane truth after an affine fit (:func:`clfza.metrics.compare`)
and the solve's time on this build's device.
"""

import matplotlib.pyplot as plt
from skimage import data

import clfza

cam = clfza.Camera.preset("simulation")
meas = clfza.simulate(data.camera(), cam, object_width=20.0)  # noise=clfza.Noise(...) adds noise

runs = [("back-propagation", "bp", {}),
        ("TwIST-TV (paper mode)", "twist", {"mode": "paper", "iters": 50}),
        ("ADMM-TV, Eq. 17", "admm", {"iters": 50, "model": "tf"})]
clfza.reconstruct(meas.y, cam, "admm", iters=1, model="tf")  # compile before the clocks
panels = [("truth (sensor plane)", meas.truth), ("raw frame y", meas.y)]
for label, method, opts in runs:
    image, info = clfza.reconstruct(meas.y, cam, method, **opts)
    psnr = clfza.metrics.compare(image, meas.truth)["psnr"]
    panels.append((f"{label}\n{psnr:.1f} dB, {info.timings['solve']:.2f} s", image))
    print(f"{label:24s} {psnr:6.2f} dB  {info.iterations:3d} iterations  on {info.device}")

fig, axes = plt.subplots(1, len(panels), figsize=(3 * len(panels), 3.4))
for ax, (title, img) in zip(axes, panels):
    ax.imshow(img, cmap="gray")
    ax.set_title(title, fontsize=9)
    ax.axis("off")
fig.tight_layout()
plt.show()
