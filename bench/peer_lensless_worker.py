"""LenslessPiCam's ADMM on a frame, for ``bench/bench_peers.py`` (run in the bench-only
``.venv-lensless``: LenslessPiCam pins numpy 1.26, so it cannot share clfza's environment).

    .venv-lensless/bin/python bench/peer_lensless_worker.py IN.npz OUT.npz

``IN.npz``: ``psf`` (H, W), ``y`` (H, W), ``taus`` (its l1-of-gradient weights), ``marks``
(checkpoint iterations). ``OUT.npz``: ``images`` (taus, marks, H, W) and ``times`` (taus,
marks): the cumulative seconds of ``apply`` up to each checkpoint (a one-iteration warm-up
first, not timed). The caller scores the images.
"""

import sys
import time

import numpy as np


def main(src: str, dst: str) -> int:
    from lensless.recon.admm import ADMM

    d = np.load(src)
    psf, y, taus, marks = d["psf"], d["y"], d["taus"], [int(k) for k in d["marks"]]
    images = np.zeros((len(taus), len(marks)) + y.shape, dtype=np.float32)
    times = np.zeros((len(taus), len(marks)))
    for i, tau in enumerate(taus):
        rec = ADMM(psf[None, :, :, None].astype(np.float32), tau=float(tau))
        rec.set_data(y[None, :, :, None].astype(np.float32))
        rec.apply(n_iter=1, disp_iter=None, plot=False, reset=True)  # warm-up
        done, t = 0, 0.0
        for j, k in enumerate(marks):
            t0 = time.perf_counter()
            img = rec.apply(n_iter=k - done, disp_iter=None, plot=False, reset=done == 0)
            t += time.perf_counter() - t0
            done = k
            images[i, j] = np.asarray(img).reshape(y.shape)
            times[i, j] = t
    np.savez(dst, images=images, times=times)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
