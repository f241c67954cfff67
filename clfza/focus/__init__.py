"""Autofocus, depth finding and focal stacks: the operator ``K`` depends on the object distance.

A point at distance ``z1`` casts the mask's shadow magnified by ``1 + z2/z1``, so the shadow
constant is ``r1' = (1 + z2/z1) r1`` (docs/design.md s.1). Refocusing a single measurement is
choosing ``r1'`` in ``H_T = sin(pi r1'^2 rho^2)`` (Eq. 17): back-propagation (Eqs. 11-12) with
the right ``r1'`` is sharp, with a wrong one every point spreads as a chirp ("numerical
focusing for 3D scenes", text after Eq. 18). This module searches ``z1`` for the sharpest fast
back-propagation and then runs any solver at the best depth.

The fast path
-------------
``FFT(y)`` is computed once; each trial depth costs one pointwise multiply by
``H_T(r1'(z1))`` and one inverse real FFT (float32 ``scipy.fft`` with all cores, the fastest
FFT on the 2-core CPU this was written on, docs/design.md s.6; measured 1 ms per depth at
256^2). ``backend="opencl"`` does the same on a device: ``FFT(y)`` kept in device memory,
``H_T`` made by a kernel, one multiply kernel and one inverse FFT per depth (measured on the
2-core Xeon's CPU devices: 0.8 ms per depth at 256^2, 1.8 ms at 512^2, against 2.0 and 3.3 ms
when it built an operator per depth). The back-propagation is :func:`clfza.models._transfer.
back_propagate`'s, with the spectrum kept (:class:`FastBP`).

Before back-propagating, the measurement is high-passed (the slowly varying envelope of the
shadows is subtracted) and apodised with a Tukey window: the TF model is periodic, and the
jump at the wrapped sensor border otherwise dominates every sharpness metric. Metrics are
evaluated on the central region (default: 15 % margin cut on each side).

Depth sensitivity
-----------------
``r1'^2 = r1^2 (1 + z2/z1)^2`` changes with ``z1`` by
``d(r1'^2)/dz1 = -2 r1^2 (1 + z2/z1) z2 / z1^2``; the defocus phase at the band limit
``rho_c = R'/r1'^2`` is ``pi |Delta r1'^2| rho_c^2``. Allowing a quarter wave (``pi/2``) gives
the depth of focus ``dz = 1 / (2 rho_c^2 |d(r1'^2)/dz1|)`` (:func:`depth_resolution`). It grows
as ``z1^2 / z2``: the search is sharp for ``z1`` of a few ``z2`` (the paper's simulation:
z1 = 20 mm, z2 = 3 mm) and weak for ``z1 >> z2`` (the paper's experiment at 300 mm).

The work is split by job: the sharpness metrics in :mod:`clfza.focus._metrics`, the fast
back-propagation and depth geometry in :mod:`clfza.focus._fastbp`, the depth search
(:func:`autofocus`, :func:`find_depths`) in :mod:`clfza.focus._search`; this module keeps the
focal stacks and re-exports all of them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..camera._camera import Camera
from ..errors import ClfzaError, positive
from ..reconstruction._reconstruct import reconstruct
from ._fastbp import WORKERS, FastBP, depth_resolution, r1p_at  # noqa: F401  (re-exported)
from ._metrics import (  # noqa: F401  (re-exported)
    METRICS,
    central_mask,
    gradient_energy,
    laplacian_variance,
    mix_metric,
    sharpness,
    tamura,
)
from ._search import (  # noqa: F401  (re-exported)
    EVIDENCE_POINTS,
    MIN_PEAK_RATIO,
    DepthsResult,
    FocusResult,
    FocusWarning,
    autofocus,
    find_depths,
    focus_evidence,
    inverse_depth_grid,
)


@dataclass
class FocalStack:
    """Reconstructions at a list of depths: ``images[k]`` belongs to ``depths[k]``."""

    depths: list
    images: np.ndarray
    infos: list
    sharpness: list

    def best(self) -> tuple[float, np.ndarray]:
        """The depth with the highest sharpness and its image."""
        k = int(np.argmax(self.sharpness))
        return self.depths[k], self.images[k]



# ----------------------------------------------------------------------------------------
# focal stacks and refocused reconstructions
# ----------------------------------------------------------------------------------------
def focal_stack(y: np.ndarray, camera: Camera, depths: Sequence[float], method: str = "bp",
                *, metric: str = "mix", **options) -> FocalStack:
    """Reconstructions of one measurement at a list of object distances (a 3-D scene).

    Each slice is ``clfza.reconstruct(y, camera.at_depth(z), method, **options)``; for
    ``"bp"`` that is ``K_z^T y`` (Eqs. 11-12), for an iterative method the solution of Eq. 19
    with ``K_z``. ``sharpness`` holds ``metric`` of the pre-processed fast back-propagation
    at each depth (:class:`FastBP`, central 70 %), the same score :func:`autofocus` uses, so
    the slices of different methods are ranked alike.
    """

    ds = [positive("depth", d) for d in depths]
    if not ds:
        raise ClfzaError("focal_stack needs at least one depth")
    eng = FastBP(y, camera)
    mask = central_mask(eng.shape)
    imgs, infos, sh = [], [], []
    for z in ds:
        rec = reconstruct(y, camera.at_depth(z), method, **options)
        imgs.append(rec.image)
        infos.append(rec.info)
        sh.append(sharpness(eng.image(z), metric, mask))
    return FocalStack(depths=ds, images=np.stack(imgs), infos=infos, sharpness=sh)


def reconstruct_autofocus(y: np.ndarray, camera: Camera, method: str = "bp", *,
                          z_range: Sequence[float] = (10.0, 1000.0), metric: str = "mix",
                          search: str = "golden", focus_backend: str = "numpy", **options):
    """Autofocus with fast back-propagation, then run ``method`` at the best depth.

    Returns ``(Reconstruction, FocusResult)``; the reconstruction's ``info.notes`` records the
    depth found and the search's cost.
    """

    fr = autofocus(y, camera, z_range, metric=metric, method=search, backend=focus_backend)
    rec = reconstruct(y, camera.at_depth(fr.z1_best), method, **options)
    rec.info.notes.append(
        f"autofocus: z1 = {fr.z1_best:.4g} mm (r1' = {fr.r1p_best:.5g} mm, metric {metric}, "
        f"{fr.timings['evaluations']} depths in {fr.timings['total'] * 1e3:.0f} ms; depth "
        f"of focus +/- {fr.depth_resolution:.3g} mm; "
        f"{'evidence' if fr.confident else 'NOT RELIABLE'}: {fr.evidence.get('reason', '')})")
    rec.info.params["z1_autofocus"] = fr.z1_best
    return rec, fr
