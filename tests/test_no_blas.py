"""The per-frame path makes no BLAS call. On a small CPU a BLAS call wakes OpenBLAS's threads,
which then spin beside PoCL's: one ``np.dot`` in the Wiener start made the next 512^2 ADMM
solve take 119 ms instead of 80 on 2 cores (clfza.solvers._wiener.wiener_lam). numpy's BLAS
entry points raise here while each method reconstructs a frame on the transfer-function
model (the model a frame stream runs on), its default start included."""

from __future__ import annotations

import numpy as np
import pytest

import clfza
from clfza import Camera

BLAS = ("dot", "vdot", "inner", "matmul", "tensordot")


def _frame():
    n, p = 64, 0.01
    cam = Camera(pitch=p, shape=(n, n), r1=np.sqrt(n) * p / (1 + 3.0 / 20.0), z1=20.0, z2=3.0,
                 R=None, mask="gzp")
    obj = np.zeros((16, 16))
    obj[4:12, 6:10] = 1.0
    return cam, clfza.simulate(obj, cam, object_width=2.0).y


@pytest.mark.parametrize("method, options", [
    ("admm", {}), ("fista", {}), ("twist", {"mode": "paper"}), ("wiener", {}), ("bp", {}),
    ("admm", {"tau": "auto"})])
def test_per_frame_path_calls_no_blas(rt, method, options):
    cam, y = _frame()
    clfza.reconstruct(y, cam, method, model="tf", **options)  # set-up outside the check
    with pytest.MonkeyPatch.context() as mp:
        for name in BLAS:
            mp.setattr(np, name, _forbidden(name))
        mp.setattr(np.linalg, "norm", _forbidden("linalg.norm"))
        rec = clfza.reconstruct(y, cam, method, model="tf", **options)
    assert np.isfinite(rec.image).all()


def _forbidden(name):
    def call(*args, **kwargs):
        raise AssertionError(f"np.{name} called on the per-frame path (BLAS)")
    return call
