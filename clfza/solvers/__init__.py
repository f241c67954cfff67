"""The solvers of Eq. 19, written once against the backend's core interface: TwIST (as the
paper runs it), FISTA, ADMM (with the crop split on the exact model) and the direct Wiener
solve, one iteration loop (:func:`run_solver`), their options, the ``tau="auto"`` rules, the
noise estimate, and the result type (:class:`Reconstruction`, :class:`ReconInfo`)."""

from __future__ import annotations

from ._admm_ops import AdmmOps, FourierSolve
from ._fista_ops import FistaOps
from ._noise import (
    encoded_band_energy,
    estimate_noise,
    freq_radius,
    haar_mad_sigma,
    out_of_band_mask,
)
from ._result import ReconInfo, Reconstruction
from ._run import (
    METHODS,
    ClfzaWarning,
    check_options,
    default_iters,
    option_names,
    options_class,
    run_solver,
)
from ._tau import AUTO_METHODS
from ._twist_ops import TwistOps

__all__ = [
    "AUTO_METHODS",
    "AdmmOps",
    "ClfzaWarning",
    "FistaOps",
    "FourierSolve",
    "METHODS",
    "ReconInfo",
    "Reconstruction",
    "TwistOps",
    "check_options",
    "default_iters",
    "encoded_band_energy",
    "estimate_noise",
    "freq_radius",
    "haar_mad_sigma",
    "option_names",
    "options_class",
    "out_of_band_mask",
    "run_solver",
]
