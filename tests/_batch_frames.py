"""Frames for the batch tests (tests/test_batch*.py), and what their Oclgrind children share:
pytest puts this folder on ``sys.path`` (and a child run as a script has it as its own), so
they import it as ``_batch_frames``."""

from __future__ import annotations

import re

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


# ----- the batched solvers under Oclgrind (tests/test_batch_*_oclgrind.py) -----------------
OCLGRIND_ERRORS = re.compile(r"Invalid (read|write)|data race|out of bounds", re.IGNORECASE)


def assert_oclgrind_clean(p) -> None:
    """A child run by conftest's ``oclgrind`` fixture exited 0 on Oclgrind's device, and
    Oclgrind reported no invalid access and no data race."""
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-4000:]
    assert "device: Oclgrind" in p.stdout, p.stdout
    reports = [ln for ln in p.stderr.splitlines() if OCLGRIND_ERRORS.search(ln)]
    assert not reports, "\n".join(reports[:40])


def oclgrind_frames():
    """In an Oclgrind child: the runtime (its device printed for the parent), a seeded
    generator, a 32^2 camera and three DC-free frames of it with their own tau."""
    from clfza.cl import get_runtime

    rt = get_runtime()
    print(f"device: {rt.info.name} ({rt.info.kind})", flush=True)
    rng = np.random.default_rng(5)
    cam = clfza.Camera(pitch=0.01, shape=(32, 32), r1=0.16, z1=100.0, z2=3.0, mask="gzp")
    y = clfza.simulate(rng.random((32, 32)), cam, object_width=cam.shape[1] * cam.pitch).y
    frames = np.stack([y, 0.5 * y[::-1], y[:, ::-1]])
    return rt, rng, cam, frames - frames.mean(axis=(1, 2), keepdims=True), [0.005, 0.01, 0.02]
