"""Warnings about the sampling regime: the transfer-function model far from critical sampling.

The lowest layer that both :mod:`clfza.models._transfer` (the forward model and its operators) and
:mod:`clfza.models._exact` (the exact model, and the choice between the two) warn through, so
neither imports the other for it. :mod:`clfza.models._transfer` re-exports both names.
"""

from __future__ import annotations

import warnings

from ._camera import Camera
from ._optics import FAR_FROM_CRITICAL


class SamplingWarning(UserWarning):
    """The transfer-function model is used far from critical sampling."""


def check_regime(camera: Camera, model: str, stacklevel: int = 3) -> None:
    """Warn when the TF model runs far from critical sampling, naming the remedy.

    Parameters
    ----------
    camera : Camera
        The camera whose sampling regime (``camera.regime``) is checked.
    model : str
        The forward model in use; only ``"tf"`` warns.
    stacklevel : int
        Passed to ``warnings.warn`` (3: the caller of the function that checks).
    """
    reg = camera.regime
    if model == "tf" and abs(reg.ratio - 1.0) > FAR_FROM_CRITICAL:
        warnings.warn(
            f"r1'^2/(N p^2) = {reg.ratio:.2f} ({reg.name}): the transfer-function model differs "
            f"from the physical convolution here; {reg.advice}",
            SamplingWarning, stacklevel=stacklevel)
