"""Reconstructions at chosen or found depths: a focal stack over a list of object distances,
and a reconstruction at the depth :func:`clfza.focus.autofocus` finds."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError, positive
from ..focus import FastBP, autofocus, central_mask, sharpness
from ..solvers import (
    DEFAULT_BACKEND,
    DEFAULT_METHOD,
    SEARCH_METHOD,
    MethodOptions,
    Reconstruction,
)
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
def focal_stack(y: np.ndarray, camera: Camera, depths: Sequence[float],
                method: str | MethodOptions = SEARCH_METHOD, *, metric: str = "mix",
                **options) -> FocalStack:
    """Reconstructions of one measurement at a list of object distances (a 3-D scene).

    Each slice is ``clfza.reconstruct(y, camera.at_depth(z), method, **options)``; for
    ``"bp"`` that is ``K_z^T y`` (Eqs. 11-12), for an iterative method the solution of Eq. 19
    with ``K_z``. ``sharpness`` holds ``metric`` of the pre-processed fast back-propagation
    at each depth (:class:`clfza.focus.FastBP` on the solves' backend and device, central
    70 %), the same score :func:`clfza.focus.autofocus` uses, so the slices of different
    methods are ranked alike.

    Examples
    --------
    >>> st = focal_stack(y, camera, [12.0, 20.0, 40.0], "bp")  # doctest: +SKIP
    >>> best_depth, best_image = st.best()  # doctest: +SKIP
    """

    ds = [positive("depth", d) for d in depths]
    if not ds:
        raise ClfzaError("focal_stack needs at least one depth")
    eng = FastBP(y, camera, backend=options.get("backend", DEFAULT_BACKEND),
                 device=options.get("device"))
    mask = central_mask(eng.shape)
    imgs, infos, sh = [], [], []
    for z in ds:
        rec = reconstruct(y, camera.at_depth(z), method, **options)
        imgs.append(rec.image)
        infos.append(rec.info)
        sh.append(sharpness(eng.image(z), metric, mask))
    return FocalStack(depths=ds, images=np.stack(imgs), infos=infos, sharpness=sh)


def reconstruct_autofocus(y: np.ndarray, camera: Camera,
                          method: str | MethodOptions = DEFAULT_METHOD, *,
                          z_range: Sequence[float] = (10.0, 1000.0), metric: str = "mix",
                          search: str = "golden", focus_backend: str | None = None,
                          **options) -> Reconstruction:
    """Autofocus with fast back-propagation, then run ``method`` at the best depth.

    Parameters
    ----------
    y : array (H, W) or (H, W, 3)
        DC-free observation.
    camera : Camera
        The camera; its ``z1`` is replaced by the depth found.
    method : str or options instance
        Reconstruction method at that depth, as for :func:`clfza.reconstruct`.
    z_range : (zmin, zmax)
        Search interval in mm.
    metric : str
        Sharpness metric (:data:`clfza.focus.METRICS`).
    search : {"golden", "grid"}
        The depth search's strategy (:func:`clfza.focus.autofocus`).
    focus_backend : {"opencl", "numpy"}, optional
        Where the search's fast back-propagation runs; default the solve's ``backend``
        (itself :data:`clfza.solvers.DEFAULT_BACKEND` unless given).
    **options
        Passed to :func:`clfza.reconstruct` (``backend``, ``device``, ``tau``, ...).

    Returns
    -------
    Reconstruction
        Unpacks as ``image, info``, like :func:`clfza.reconstruct`'s; ``info.focus`` is the
        search's :class:`clfza.focus.FocusResult`, ``info.params["z1_autofocus"]`` the
        depth found, and ``info.notes`` records it with the search's cost and evidence.

    Examples
    --------
    >>> image, info = reconstruct_autofocus(y, camera, "admm", z_range=(10, 60))  # doctest: +SKIP
    >>> info.focus.z1_best, info.focus.confident  # doctest: +SKIP
    """

    backend = focus_backend or options.get("backend", DEFAULT_BACKEND)
    fr = autofocus(y, camera, z_range, metric=metric, search=search, backend=backend,
                   device=options.get("device"))
    rec = reconstruct(y, camera.at_depth(fr.z1_best), method, **options)
    rec.info.notes.append(
        f"autofocus: z1 = {fr.z1_best:.4g} mm (r1' = {fr.r1p_best:.5g} mm, metric {metric}, "
        f"{fr.timings['evaluations']} depths in {fr.timings['total'] * 1e3:.0f} ms; depth "
        f"of focus +/- {fr.depth_resolution:.3g} mm; "
        f"{'evidence' if fr.confident else 'NOT RELIABLE'}: {fr.evidence.get('reason', '')})")
    rec.info.params["z1_autofocus"] = fr.z1_best
    rec.info.focus = fr
    return rec
