"""The DnCNN denoiser's public entry points: the variant for a noise level, and denoising."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..cl import get_runtime
from ..errors import ClfzaError, is_real
from ._opencl import DnCNNDevice
from ._reference import dncnn_reference
from ._weights import BLIND_SIGMA, CONDITIONAL_RANGE, check_variant, load_dncnn

BACKENDS = ("auto", "numpy", "opencl")
# the blind variants' bands: each covers the noise levels nearer its training level than any
# other's (the midpoints 0.08 and 0.15), H up to the top of the training data (0.2)
BLIND_BANDS = {"L": (0.0, 0.08), "M": (0.08, 0.15), "H": (0.15, CONDITIONAL_RANGE[1])}


class DnCNNRangeWarning(UserWarning):
    """sigma outside the training range of the DnCNN variant that denoises it."""


@dataclass(frozen=True)
class VariantChoice:
    """The DnCNN variant that denoises at ``sigma``, and a note when sigma leaves its training
    range (None when inside)."""

    variant: str
    sigma: float
    note: str | None


def _check_sigma(sigma, conditional: bool) -> float | None:
    if sigma is None:
        if conditional:
            raise ClfzaError("sigma (the noise standard deviation, image in [0, 1]) is "
                             "required by the noise-conditional DnCNN variants")
        return None
    if not is_real(sigma) or not math.isfinite(float(sigma)) or float(sigma) < 0:
        raise ClfzaError(f"sigma must be a finite number >= 0 (the noise standard deviation, "
                         f"image in [0, 1]), got {sigma!r}")
    return float(sigma)


def select_variant(sigma: float | None, variant: str | None = None,
                   layers: int = 6) -> VariantChoice:
    """The DnCNN variant for noise standard deviation ``sigma`` (image in [0, 1]).

    Parameters
    ----------
    sigma : float or None
        The noise standard deviation; None only with a blind variant.
    variant : str, optional
        None (default): the noise-conditional ``"{layers}N"`` (trained on sigma in [0, 0.2]).
        ``"blind"``: the blind variant whose band holds sigma (``L`` trained at 0.06 for
        sigma < 0.08, ``M`` at 0.10 up to 0.15, ``H`` at 0.20 above). A variant name
        (``"6N"``, ``"6L"``, ...) is used as given.
    layers : {6, 17}
        The depth for ``None`` and ``"blind"`` (only 17N of the 17-layer ones is shipped).

    Returns
    -------
    VariantChoice
        With a ``note`` when sigma leaves the variant's training range (the ``N`` ones: above
        0.2; a blind one: outside its band), which then names the variant covering it.

    Examples
    --------
    >>> from clfza.denoisers import select_variant
    >>> select_variant(0.05).variant
    '6N'
    >>> select_variant(0.12, "blind").variant
    '6M'
    >>> select_variant(0.3).note is not None
    True
    """
    if layers not in (6, 17) or isinstance(layers, bool):
        raise ClfzaError(f"DnCNN layers must be 6 or 17, got {layers!r}")
    if variant is None:
        variant = f"{layers}N"
    elif variant == "blind":
        s = _check_sigma(sigma, True)
        level = next((k for k, (lo, hi) in BLIND_BANDS.items() if lo <= s < hi), "H")
        variant = f"{layers}{level}"
    v = check_variant(variant)
    s = _check_sigma(sigma, v.endswith("N"))
    note = None
    if v.endswith("N"):
        lo, hi = CONDITIONAL_RANGE
        if s > hi:
            note = (f"sigma {s:.4g} is above the training range [{lo:g}, {hi:g}] of every DnCNN "
                    f"variant; {v} extrapolates")
    elif s is not None:
        lo, hi = BLIND_BANDS[v[-1]]
        if not lo <= s <= hi:
            better = "N" if s <= CONDITIONAL_RANGE[1] else None
            cover = next((k for k, (a, b) in BLIND_BANDS.items() if a <= s < b), None)
            where = (f"; {v[:-1]}{better} (sigma input) or {v[:-1]}{cover} (blind) covers it"
                     if better and cover else "")
            note = (f"sigma {s:.4g} is outside the band [{lo:g}, {hi:g}] of {v} (trained at "
                    f"{BLIND_SIGMA[v[-1]]:g}){where}")
    return VariantChoice(v, 0.0 if s is None else s, note)


def _as_planes(x) -> tuple[np.ndarray, bool]:
    """(N, H, W) float64 planes of a grey (H, W) or colour (H, W, C) image, and whether it
    was colour."""
    if not isinstance(x, np.ndarray) and not isinstance(x, (list, tuple)):
        raise ClfzaError(f"the image must be an array, got {type(x).__name__}")
    a = np.asarray(x)
    if a.dtype.kind not in "biuf":
        raise ClfzaError(f"the image must be real-valued, got dtype {a.dtype}")
    if a.ndim == 2:
        planes, colour = a[None], False
    elif a.ndim == 3 and 1 <= a.shape[2] <= 4:
        planes, colour = np.moveaxis(a, 2, 0), True
    else:
        raise ClfzaError(f"the image must be grey (H, W) or colour (H, W, C) with C <= 4, got "
                         f"shape {a.shape}")
    if min(planes.shape[1:]) < 3:
        raise ClfzaError(f"the image must be at least 3x3 pixels, got {a.shape}")
    planes = planes.astype(np.float64)
    if not np.all(np.isfinite(planes)):
        raise ClfzaError("the image has NaN or infinite values")
    return planes, colour


class DnCNN:
    """A pretrained DnCNN denoiser held ready on one backend (its weights on the device).

    Parameters
    ----------
    variant : str
        ``"6N"`` (default), ``"17N"``, ``"6L"``, ``"6M"`` or ``"6H"`` (:func:`load_dncnn`).
    backend : {"auto", "numpy", "opencl"}
        ``numpy``: the float64 reference (:func:`dncnn_reference`); ``opencl``:
        ``kernels/dncnn.cl`` in float32 on ``device``; ``auto``: OpenCL.
    device : str, optional
        OpenCL device spec (:func:`clfza.cl.get_runtime`); default the default device.
    kernel : {"auto", "cpu", "tiled"}
        The OpenCL 64 -> 64 layers' kernel (``auto``: by the device's kind).

    Examples
    --------
    >>> import numpy as np
    >>> from clfza.denoisers import DnCNN
    >>> DnCNN("6N", backend="numpy")(np.full((8, 8), 0.5), sigma=0.05).shape
    (8, 8)
    """

    def __init__(self, variant: str = "6N", backend: str = "auto", device: str | None = None,
                 kernel: str = "auto"):
        if backend not in BACKENDS:
            raise ClfzaError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        self.weights = load_dncnn(check_variant(variant))
        self.variant = variant
        self.backend = "opencl" if backend == "auto" else backend
        self._dev = None
        if self.backend == "opencl":
            self._dev = DnCNNDevice(self.weights, get_runtime(device), kernel=kernel)

    @property
    def device(self):
        """The :class:`~clfza.denoisers.DnCNNDevice` (None on the numpy backend)."""
        return self._dev

    def __call__(self, x: np.ndarray, sigma: float | None = None) -> np.ndarray:
        """Denoise a grey (H, W) or colour (H, W, C) image (channels as a batch), in [0, 1]
        scale; returns float64 of ``x``'s shape. ``sigma`` is required by the ``N`` variants
        (their second input channel) and ignored by the blind ones."""
        planes, colour = _as_planes(x)
        s = _check_sigma(sigma, self.weights.conditional)
        s = 0.0 if s is None else s
        if self._dev is None:
            y = dncnn_reference(planes, self.weights, sigma=s)
        else:
            y = self._dev(planes, s).astype(np.float64)
        return np.moveaxis(y, 0, 2) if colour else y[0]


def denoise(x: np.ndarray, sigma: float, variant: str | None = None, *, layers: int = 6,
            backend: str = "auto", device: str | None = None,
            return_note: bool = False) -> np.ndarray | tuple[np.ndarray, str | None]:
    """Denoise an image with a pretrained DnCNN (Zhang et al. 2017; scico's weights).

    The network computes ``x - R(x)`` where ``R`` estimates the noise (residual learning):
    ``conv -> ReLU``, ``layers - 2`` blocks ``conv -> BatchNorm -> ReLU``, ``conv``, all 3x3
    with circular padding. It is the learned prior of plug-and-play reconstruction, where
    it replaces the proximal step of the regulariser (issue 38).

    Parameters
    ----------
    x : ndarray
        Grey (H, W) or colour (H, W, C) image with intensities in [0, 1] (the scale the
        networks were trained on); colour channels are denoised independently, as a batch.
    sigma : float
        Noise standard deviation in the same [0, 1] scale.
    variant : str, optional
        None: the noise-conditional ``"{layers}N"``; ``"blind"``: the blind variant whose band
        holds sigma; or a variant name (:func:`select_variant`).
    layers : {6, 17}
        Depth when ``variant`` is None or ``"blind"``.
    backend : {"auto", "numpy", "opencl"}
        ``numpy``: the float64 reference; ``opencl`` / ``auto``: ``kernels/dncnn.cl`` (float32).
    device : str, optional
        OpenCL device spec; default the default device.
    return_note : bool
        Also return the note (None when sigma is inside the variant's training range).

    Returns
    -------
    ndarray or (ndarray, str or None)
        The denoised image (float64, ``x``'s shape), and the note if asked for.

    Warns
    -----
    DnCNNRangeWarning
        When sigma leaves the chosen variant's training range (the note's text).

    Examples
    --------
    >>> import numpy as np
    >>> from clfza.denoisers import denoise
    >>> rng = np.random.default_rng(0)
    >>> y = np.clip(0.5 + 0.05 * rng.standard_normal((32, 32)), 0, 1)
    >>> d = denoise(y, 0.05, backend="numpy")
    >>> bool(np.std(d) < np.std(y))
    True
    """
    choice = select_variant(sigma, variant, layers)
    if choice.note:
        warnings.warn(choice.note, DnCNNRangeWarning, stacklevel=2)
    out = DnCNN(choice.variant, backend=backend, device=device)(x, choice.sigma)
    return (out, choice.note) if return_note else out
