"""The kernels compile without warnings on the test device (issue 36).

A child process with empty program caches (PoCL's ``POCL_CACHE_DIR`` in a new folder,
pyopencl's cache off: a cached build may return an empty log) runs every method on the
transfer-function model with the host and the device FFT (line lengths of powers of two, of 3
and 5, and a prime: Bluestein) and on colour frames, ADMM on the exact model and on a batch of
frames, TwIST and ADMM in float64, and launches every hot kernel once
(:func:`clfza.cl.check.hot_ops`). It prints the build log of every program it built
(:attr:`clfza.cl.Runtime.build_logs`: the implementation's log and what its compiler printed on
stderr); no line of them may be a warning (:func:`clfza.cl.warning_lines`), and nothing may
reach the child's stderr. Marked ``agreement``: ``.ci/run`` reruns it on every further OpenCL
device, each with its own compiler (pip's PoCL 3.0, the distribution's PoCL 3.1, Intel's CPU
runtime).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from clfza.cl import warning_lines

pytestmark = pytest.mark.agreement

CHILD = r"""
import json, warnings
import numpy as np
import clfza
from clfza.cl import get_runtime
from clfza.cl.check import hot_ops, small_backend

warnings.simplefilter("ignore")
rt = get_runtime()
rng = np.random.default_rng(0)
cam = clfza.Camera(pitch=0.01, shape=(64, 64), r1=0.07, z1=20.0, z2=3.0, R=0.6)
y = rng.random(cam.shape)
for fft in ("auto", "device"):
    kw = dict(fft=fft)
    clfza.reconstruct(y, cam, "bp", **kw)
    clfza.reconstruct(y, cam, "twist", mode="paper", iters=2, **kw)
    clfza.reconstruct(y, cam, "fista", iters=2, **kw)
    clfza.reconstruct(y, cam, "admm", iters=2, model="tf", **kw)
    clfza.reconstruct(np.stack([y] * 3, -1), cam, "admm", iters=2, model="tf", **kw)
clfza.reconstruct(y, cam, "admm", iters=2, model="exact")
clfza.reconstruct(np.stack([y, y]), cam, "admm", iters=2, model="tf")
if rt.has_fp64:
    clfza.reconstruct(y, cam, "twist", iters=2, dtype=np.float64)
    clfza.reconstruct(y, cam, "admm", iters=2, model="tf", dtype=np.float64)
for shape in ((60, 90), (97, 128)):
    c = clfza.Camera(pitch=0.01, shape=shape, r1=0.07, z1=20.0, z2=3.0, R=0.6)
    clfza.reconstruct(rng.random(shape), c, "admm", iters=2, model="tf", fft="device")
B = small_backend()
for _name, fn in hot_ops(B):
    fn()
B.finish()
logs = dict(rt.build_logs)
logs.update({"hot_ops " + k: v for k, v in B.rt.build_logs.items()})
print("BUILD-LOGS " + json.dumps({"device": rt.info.describe(), "logs": logs}))
"""


def test_every_program_builds_without_warnings(rt, tmp_path):
    env = dict(os.environ, POCL_CACHE_DIR=str(tmp_path / "pocl"), PYOPENCL_NO_CACHE="1",
               PYOPENCL_CTX=os.environ.get("PYOPENCL_CTX") or rt.info.index)
    p = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True,
                       timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    line = next(ln for ln in p.stdout.splitlines() if ln.startswith("BUILD-LOGS "))
    got = json.loads(line[len("BUILD-LOGS "):])
    assert len(got["logs"]) >= 8, got  # every program of the solvers was built
    bad = {what: warning_lines(text) for what, text in got["logs"].items()
           if warning_lines(text)}
    assert not bad, f"compiler warnings on {got['device']}: {json.dumps(bad, indent=1)[:4000]}"
    assert p.stderr.strip() == "", f"the child printed on stderr:\n{p.stderr[-3000:]}"


def test_warning_lines_tell_warnings_from_intels_build_report():
    log = ("Compilation started\nCompilation done\nDevice build done\n"
           "remark: <unknown>:0:0: Kernel was 16-way vectorized\n"
           "Kernel \"triad\" was successfully vectorized (16)\nDone.")
    assert warning_lines(log) == []
    assert warning_lines("warning: kernel \"k\": Kernel can't be vectorized") != []
    assert warning_lines("/tmp/x.cl:168:9: warning: AVX vector argument") != []
    assert warning_lines("59 warnings generated.") == ["59 warnings generated."]
