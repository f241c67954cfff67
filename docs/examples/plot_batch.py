"""
A batch of frames on Dask
=========================

:func:`clfza.reconstruct_many` reconstructs a sequence of frames and keeps their order: in
this process, or on Dask workers (``workers=N`` starts a local cluster of N worker
processes; ``scheduler=`` or ``client=`` use an existing one; Dask comes with
``pip install -e ".[dask]"``). Here four raw frames of a scene moving to the right (the
simulation preset cropped to 256^2 pixels) are written to a folder as 16-bit TIFF files, as a
camera would, and reconstructed by one Dask worker: each worker reads its frames, keeps one
OpenCL context (the kernels compile on its first frame only) and writes each frame's image,
``.npy`` array and JSON record into ``out_dir``, the JSON last.

A script that starts worker processes needs the ``if __name__ == "__main__":`` guard of
Python's multiprocessing when run on its own (the workers import it); the command line
``clfza reconstruct frames/ --camera simulation --workers 1 --out out`` does the same.
ADMM, 30 iterations per frame on the transfer-function model; a few seconds in all, most of
them the worker's start.
"""

import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import tifffile
from skimage import data, transform

import clfza

if __name__ == "__main__":
    cam = clfza.Camera.preset("simulation").with_shape((256, 256))
    scene = transform.resize(data.camera() / 255.0, (256, 256))
    work = Path(tempfile.mkdtemp())  # the frames and outputs go into a new folder
    (work / "frames").mkdir()
    for k in range(4):  # the raw frames, as a sensor saves them
        m = clfza.simulate(np.roll(scene, 12 * k, axis=1), cam, object_width=10.0,
                           noise=clfza.Noise(photons=1e6, bit_depth=16, seed=k))
        tifffile.imwrite(work / f"frames/frame_{k}.tif", m.frame.astype(np.uint16))

    res = clfza.reconstruct_many(work / "frames", cam, "admm", iters=30, model="tf",
                                 workers=1, out_dir=work / "out", return_images=True)
    for r in res.results:  # in the frames' order
        t = r.record["timings_s"]
        print(f"{r.record['name']}: ok={r.ok}, compile {t['compile']:.3f} s, "
              f"solve {t['solve']:.3f} s, {r.record['iterations']} iterations")
    print(sorted(p.name for p in (work / "out").iterdir())[:3], "...")
    record = json.loads((work / "out" / "frame_0.json").read_text())
    print(f"frame_0.json: method {record['method']}, tau {record['parameters']['tau']:.4g}, "
          f"device {record['device']}")

    fig, axes = plt.subplots(1, len(res.results), figsize=(3 * len(res.results), 3.2))
    for ax, r in zip(axes, res.results, strict=True):
        ax.imshow(r.image, cmap="gray")
        ax.set_title(f"frame {r.index}", fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    plt.show()
