"""Autofocus, depth finding and focal stacks: the operator ``K`` depends on the object distance.

A point at distance ``z1`` casts the mask's shadow magnified by ``1 + z2/z1``, so the shadow
constant is ``r1' = (1 + z2/z1) r1`` (docs/design.md s.1). Refocusing a single measurement is
choosing ``r1'`` in ``H_T = sin(pi r1'^2 rho^2)`` (Eq. 17): back-propagation (Eqs. 11-12) with
the right ``r1'`` is sharp, with a wrong one every point spreads as a chirp ("numerical
focusing for 3D scenes", text after Eq. 18). This package searches ``z1`` for the sharpest fast
back-propagation.

The fast path
-------------
``FFT(y)`` is computed once; each trial depth costs one pointwise multiply by
``H_T(r1'(z1))`` and one inverse real FFT. ``backend="opencl"`` (the default,
:data:`clfza.solvers.DEFAULT_BACKEND`, as for every entry point) keeps ``FFT(y)`` in device
memory and makes ``H_T`` by a kernel: one multiply kernel and one inverse FFT per depth;
``backend="numpy"`` does the same on the host with float32 ``scipy.fft`` on all cores
(docs/design.md s.6). Nothing is built per depth. The back-propagation is
:func:`clfza.models.back_propagate`'s, with the spectrum kept (:class:`FastBP`).

Before back-propagating, the shadows' slowly varying envelope (a Gaussian blur of
``envelope_sigma`` pixels) is subtracted from the measurement and the result apodised with a
Tukey window (``taper``): the TF model is periodic, and the jump at the wrapped sensor border
otherwise dominates every sharpness metric. Metrics are evaluated on the central region
(``border_fraction``, default 0.15 of each side cut: the central 70 %).

Names: ``search`` is the depth search's strategy ("golden", "grid"), never ``method`` (the
reconstruction method of :func:`clfza.reconstruct`); ``border_fraction`` is a fraction of the
frame, ``margin`` (the exact model's extra object pixels) a number of pixels;
``envelope_sigma`` is a Gaussian's standard deviation in pixels, ``highpass`` (ADMM's option
on the exact model) a box half-width in pixels.

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
(:func:`autofocus`, :func:`find_depths`) in :mod:`clfza.focus._search`, and which PSF of a
measured stack fits a frame in :mod:`clfza.focus._psf_depth` (the scale search of
:mod:`clfza.focus._psf_scale`, over the stack). Focal stacks and reconstructions
at the depth found are entry points: :func:`clfza.reconstruction.focal_stack` and
:func:`clfza.reconstruction.reconstruct_autofocus`.
"""

from __future__ import annotations

from ._fastbp import FastBP, depth_resolution
from ._metrics import METRICS, central_mask, sharpness, tamura
from ._psf_depth import PSFDepthResult, PSFDepthWarning, back_project, select_psf_depth
from ._psf_scale import (
    PSFScaleResult,
    PSFScaleWarning,
    default_scale_range,
    find_psf_scale,
    score_psf_stack,
)
from ._search import (
    SEARCHES,
    DepthsResult,
    FocusResult,
    FocusWarning,
    autofocus,
    find_depths,
    focus_confidence,
)

__all__ = [
    "DepthsResult",
    "FastBP",
    "FocusResult",
    "FocusWarning",
    "METRICS",
    "PSFDepthResult",
    "PSFDepthWarning",
    "PSFScaleResult",
    "PSFScaleWarning",
    "SEARCHES",
    "autofocus",
    "back_project",
    "central_mask",
    "default_scale_range",
    "depth_resolution",
    "find_depths",
    "focus_confidence",
    "find_psf_scale",
    "score_psf_stack",
    "select_psf_depth",
    "sharpness",
    "tamura",
]
