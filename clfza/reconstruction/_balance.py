"""White balance of colour reconstructions (issue 34, item 4).

A colour sensor has a gain per channel, ``F_c = g_c (h * O_c)``; a measured PSF captured on
the same sensor from a white point source carries the same gains, ``PSF_c = g_c s h``. Its
channel sums (before normalisation, kept by :func:`clfza.models.load_psf` as
``info["channel_sums"]``) therefore give ``g_c`` up to one common factor, and dividing them
out gives the scene's colours: ``white_balance="psf"`` (the default). ``"grey"`` is
grey-world: each channel scaled so that the channels' means agree (their RMS about the mean
where a reconstruction has no reliable mean, e.g. Eq. 17's, which carries no DC). ``"none"``
keeps the sensor's colours.

Every mode starts from the image "in sensor units": the channels solved with PSFs of equal
sums (a PSF given as a raw array, whose channels sum to ``g_c``, already divides the gains
out in the solve; :func:`white_balance_image` puts them back first), then divides by the
chosen gains, normalised to mean 1 so that the overall scale is kept. The display scaling
(:func:`clfza.io.scale_to_uint16`) then maps all channels with one range.
"""

from __future__ import annotations

import numpy as np

from ..errors import ClfzaError
from ..models import ExactModel

WHITE_BALANCES = ("psf", "grey", "none")
DEFAULT_WHITE_BALANCE = "psf"
GREY_MEAN_MIN = 0.25
"""Grey-world uses the channels' means only where each is positive and at least this
fraction of the channel's RMS about its mean (a DC-free reconstruction's mean is noise);
otherwise their RMS about the mean."""


def check_white_balance(mode) -> str:
    """``mode`` validated: one of :data:`WHITE_BALANCES`."""
    if not isinstance(mode, str) or mode.lower() not in WHITE_BALANCES:
        raise ClfzaError(f"white_balance must be one of {WHITE_BALANCES}, got {mode!r}")
    return mode.lower()


def _psf_sums(psf) -> tuple[np.ndarray, np.ndarray] | None:
    """``(solved, raw)`` per-channel sums of a colour PSF: the sums of the array the solve
    used and the capture's sums before normalisation; None for no PSF or a grey one."""
    if psf is None or isinstance(psf, ExactModel):
        return None
    arr = np.asarray(getattr(psf, "array", psf), np.float64)
    if arr.ndim != 3 or arr.shape[2] == 1:
        return None
    solved = arr.sum(axis=(0, 1))
    raw = (getattr(psf, "info", None) or {}).get("channel_sums")
    raw = solved if raw is None else np.asarray(raw, np.float64).ravel()
    if raw.shape != solved.shape or not np.all(np.isfinite(raw)) or np.any(raw <= 0) \
            or np.any(solved <= 0):
        raise ClfzaError(f"the PSF's channel sums must be positive to white-balance by them, "
                         f"got {np.round(raw, 6).tolist()}")
    return solved, raw


def psf_gains(psf) -> np.ndarray | None:
    """The relative per-channel gains of a colour PSF (mean 1), from its channel sums before
    normalisation; None for no PSF, a grey PSF or the camera's own mask (colour-neutral).

    Examples
    --------
    >>> psf_gains(np.ones((5, 5, 3)) * [1.0, 0.8, 0.6]).round(3).tolist()
    [1.25, 1.0, 0.75]
    """
    sums = _psf_sums(psf)
    return None if sums is None else sums[1] / sums[1].mean()


def white_balance_image(image: np.ndarray, mode: str, psf=None) -> tuple[np.ndarray, dict | None]:
    """A colour reconstruction ``(..., H, W, 3)`` white-balanced; returns it and the record
    (None, and the image unchanged, for a grey image).

    Parameters
    ----------
    image : array (H, W, 3)
        The reconstruction, in the units of the PSF as solved (see :mod:`._balance`).
    mode : {"psf", "grey", "none"}
        ``"psf"``: divide the PSF's channel gains out (:func:`psf_gains`); without a colour
        PSF (the camera's mask passes every colour alike, so it tells no gains) grey-world
        instead, and the record says so. ``"grey"``: grey-world. ``"none"``: the sensor's
        colours.
    psf : array, clfza.models.PSF or None
        The PSF the image was solved with.

    Returns
    -------
    (image, record)
        ``record``: ``mode`` (asked), ``applied`` (psf, grey or none), ``gains`` (divided
        out, mean 1), ``statistic`` (grey: mean or rms) and ``reason``.

    Examples
    --------
    >>> img = np.ones((4, 4, 3)) * [2.0, 1.0, 1.0]
    >>> out, rec = white_balance_image(img, "grey")
    >>> out[0, 0].round(3).tolist(), rec["applied"]
    ([1.333, 1.333, 1.333], 'grey')
    """
    mode = check_white_balance(mode)
    a = np.asarray(image, np.float64)
    if a.ndim != 3 or a.shape[2] != 3:
        return a, None
    sums = _psf_sums(psf)
    to_sensor = np.ones(3) if sums is None else sums[0] / sums[0].mean()
    sensor = a * to_sensor
    rec: dict = {"mode": mode}
    if mode == "psf" and sums is not None:
        gains = sums[1] / sums[1].mean()
        rec.update(applied="psf", reason="the PSF's channel sums (the sensor's gains as the "
                   "point source saw them)")
    elif mode == "none":
        gains = np.ones(3)
        rec.update(applied="none", reason="the sensor's colours")
    else:
        gains, stat = _grey_gains(sensor)
        rec.update(applied="grey", statistic=stat,
                   reason=("grey-world (asked)" if mode == "grey" else
                           "no colour PSF (the camera's mask passes every colour alike): "
                           "grey-world instead") + f", on the channels' {stat}s")
    rec["gains"] = [float(g) for g in gains]
    return sensor / gains, rec


def _grey_gains(img: np.ndarray) -> tuple[np.ndarray, str]:
    """Grey-world gains (mean 1) of an ``(H, W, 3)`` image and the statistic used."""
    means = img.mean(axis=(0, 1))
    rms = np.sqrt(np.mean((img - means) ** 2, axis=(0, 1)))
    if np.all(means > 0) and np.all(means >= GREY_MEAN_MIN * rms):
        stat, v = "mean", means
    else:
        stat, v = "rms", rms
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        return np.ones(3), "flat"
    return v / v.mean(), stat
