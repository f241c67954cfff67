"""Frames for the batch tests (tests/test_batch*.py): pytest puts this folder on ``sys.path``,
so they import it as ``_batch_frames``."""

from __future__ import annotations

import numpy as np

import clfza

N = 48  # the frames' side


def frames(cam, k: int, colour: bool = False, seed: int = 0) -> np.ndarray:
    """``k`` different DC-free measurements of random ``N x N`` scenes with noise of
    growing variance: their stopping rules fire, and their monotone steps reject, at different
    iterations."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(k):
        scene = rng.random((N, N, 3) if colour else (N, N))
        noise = clfza.Noise(gaussian_var=1e-3 * (i + 1), seed=seed * 10 + i)
        y = clfza.simulate(scene, cam, object_width=N * cam.pitch, noise=noise).y
        out.append(y - y.mean(axis=(0, 1)))
    return np.stack(out)
