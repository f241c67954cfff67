"""Reconstructions at chosen or found depths: a focal stack over a list of object distances,
and a reconstruction at the depth :func:`clfza.focus.autofocus` finds."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError, positive
from ..focus import FastBP, autofocus, central_mask, sharpness
from ._reconstruct import reconstruct


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
