"""The solvers of Eq. 19, written once against the backend's core interface: TwIST (as the
paper runs it), FISTA, ADMM (with the crop split on the exact model) and the direct Wiener
solve, one iteration loop (:func:`run_solver`), their options, the ``tau="auto"`` rules, the
noise estimate, and the result type (:class:`Reconstruction`, :class:`ReconInfo`).

The options classes (:class:`AdmmOptions`, :class:`FistaOptions`, :class:`TwistOptions`,
:class:`WienerOptions`; ``clfza.ADMM`` and the others at the top level) and the package's
defaults of a solve (:data:`DEFAULT_METHOD`, :data:`DEFAULT_BACKEND`) are public here."""

from __future__ import annotations

from ._admm import AdmmOptions
from ._admm_ops import AdmmOps, FourierSolve
from ._batch import BATCH_METHODS, batch_blocker, frames_per_solve_for, run_solver_batch
from ._fista import FistaOptions
from ._fista_ops import FistaOps
from ._noise import (
    encoded_band_energy,
    estimate_noise,
    freq_radius,
    haar_mad_sigma,
    out_of_band_mask,
)
from ._options import (
    DEFAULT_BACKEND,
    DEFAULT_METHOD,
    RUN_CONTROLS,
    SEARCH_METHOD,
    MethodOptions,
    resolve_method,
)
from ._result import ReconInfo, Reconstruction
from ._route import model_error, route_model
from ._run import (
    METHOD_NAMES,
    METHODS,
    ClfzaWarning,
    check_options,
    default_iters,
    method_model,
    option_names,
    options_class,
    run_solver,
)
from ._tau import AUTO_BY_DEFAULT, AUTO_METHODS, tau_auto_note
from ._tau_exact import colour_energy_support, energy_support, frame_energy_support
from ._twist import TwistOptions
from ._twist_ops import TwistOps
from ._wiener import WienerOptions

__all__ = [
    "AUTO_BY_DEFAULT",
    "AUTO_METHODS",
    "BATCH_METHODS",
    "AdmmOps",
    "AdmmOptions",
    "ClfzaWarning",
    "DEFAULT_BACKEND",
    "DEFAULT_METHOD",
    "FistaOps",
    "FistaOptions",
    "FourierSolve",
    "METHODS",
    "METHOD_NAMES",
    "MethodOptions",
    "RUN_CONTROLS",
    "SEARCH_METHOD",
    "ReconInfo",
    "Reconstruction",
    "TwistOps",
    "TwistOptions",
    "WienerOptions",
    "batch_blocker",
    "check_options",
    "default_iters",
    "method_model",
    "model_error",
    "encoded_band_energy",
    "estimate_noise",
    "frames_per_solve_for",
    "freq_radius",
    "haar_mad_sigma",
    "option_names",
    "options_class",
    "out_of_band_mask",
    "resolve_method",
    "route_model",
    "run_solver",
    "run_solver_batch",
    "tau_auto_note",
    "colour_energy_support",
    "energy_support",
    "frame_energy_support",
]
