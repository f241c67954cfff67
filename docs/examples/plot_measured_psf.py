"""
A measured PSF
==============

Any mask-based lensless camera can be described by its point-spread function: the frame a
point source records through the mask. This example makes the two captures a lab would make,
with :func:`clfza.simulation.simulate_psf_capture`: a point source photographed through a
finite-aperture zone plate (the PSF, 1.6 times larger than the frame, since the mask's shadow
reaches past the sensor), and a scene photographed through the same mask at the same depth,
both on a noisy 8-bit sensor. The PSF is written to a TIFF file as a camera would save it,
loaded back as a measured PSF (:func:`clfza.models.load_psf`: the black level from the
capture's border, the point centred, unit sum) and used as the operator of the
reconstruction (``psf=``), in place of a model of the mask.

Size: a 256^2 frame, a 410^2 PSF capture; back-propagation, and ADMM with ``tau="auto"``
(chosen from the frame's noise) and its default iterations; a few seconds in all. The
capture's shot and read noise and its 8 bits limit what any method recovers here.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import tifffile
from skimage import data

import clfza
from clfza.models import load_psf
from clfza.simulation import simulate_psf_capture

cap = simulate_psf_capture(data.camera(), shape=(256, 256), psf_z1=40.0, scene_z1=40.0)
work = Path(tempfile.mkdtemp())                 # a new folder for the files
tifffile.imwrite(work / "psf_capture.tif", cap.psf.astype("uint8"))    # what the lab saves
tifffile.imwrite(work / "scene_frame.tif", cap.frame.astype("uint8"))

psf = load_psf(work / "psf_capture.tif", background="border", center="centroid")
print("PSF", psf.array.shape, f"sum {psf.array.sum():.3f}")

frame, _ = clfza.io.read_frame(work / "scene_frame.tif")
y = frame - frame.mean()          # the DC-free frame (measured PSFs are scale-free)
cam = cap.camera                  # pitch, shape and depths; the PSF is the mask
panels = [("PSF capture (8-bit)", cap.psf), ("scene frame (8-bit)", frame)]
for label, method, opts in (("back-propagation", "bp", {}),
                            ("ADMM-TV, tau='auto'", "admm", {"tau": "auto"})):
    image, info = clfza.reconstruct(y, cam, method, psf=psf, **opts)
    psnr = clfza.metrics.compare(image, cap.truth)["psnr"]
    panels.append((f"{label}, measured PSF\n{psnr:.1f} dB", image))
    print(f"{label:18s} {psnr:6.2f} dB, {info.iterations} iterations; {info.notes[0]}")
panels.append(("truth (sensor plane)", cap.truth))

fig, axes = plt.subplots(1, 5, figsize=(14, 3.3))
for ax, (title, img) in zip(axes, panels, strict=True):
    ax.imshow(img, cmap="gray")
    ax.set_title(title, fontsize=9)
    ax.axis("off")
fig.tight_layout()
plt.show()
