"""clfza: OpenCL-accelerated reconstruction for Fresnel-zone-aperture lensless cameras.

Equation numbers in docstrings refer to Wu et al., Light Sci. Appl. 9, 53 (2020).

The public names below load on first use (PEP 562), so ``import clfza`` and the command line
start without importing scipy's signal tools, scikit-image or pyopencl; so do the subpackages
(``clfza.models``, ``clfza.focus``, ``clfza.reconstruction``, ``clfza.distributed``,
``clfza.io``, ``clfza.metrics``, ...), each reachable as an attribute after ``import clfza``.

The method options classes are here under short names, so that a call shows every option:
``clfza.reconstruct(y, cam, clfza.ADMM(tau=0.01, iters=100))`` (:class:`ADMM`,
:class:`FISTA`, :class:`TwIST`, :class:`Wiener`; back-propagation, the default method, has no
options).

Examples
--------
>>> import clfza
>>> clfza.ADMM(tau=0.01, iters=100).given()
{'tau': 0.01, 'iters': 100}
>>> clfza.focus.select_psf_depth.__name__
'select_psf_depth'
"""

from __future__ import annotations

__version__ = "0.1.0"  # first: modules that import clfza.__version__ may load before the rest

import importlib  # noqa: E402
from typing import TYPE_CHECKING

from .camera import Camera
from .errors import ClfzaError, DeviceError
from .simulation import Measurement, Noise, simulate

if TYPE_CHECKING:  # what the lazy names below are, for type checkers and IDEs
    from .distributed import reconstruct_many  # noqa: F401
    from .models import NumpyOperator, back_propagate, transfer_function  # noqa: F401
    from .reconstruction import reconstruct  # noqa: F401
    from .solvers import AdmmOptions as ADMM  # noqa: F401
    from .solvers import FistaOptions as FISTA  # noqa: F401
    from .solvers import ReconInfo, Reconstruction  # noqa: F401
    from .solvers import TwistOptions as TwIST  # noqa: F401
    from .solvers import WienerOptions as Wiener  # noqa: F401

#: public name -> (subpackage, its name there), loaded on first use
_LAZY = {
    "ReconInfo": ("solvers", "ReconInfo"), "Reconstruction": ("solvers", "Reconstruction"),
    "reconstruct": ("reconstruction", "reconstruct"),
    "NumpyOperator": ("models", "NumpyOperator"),
    "back_propagate": ("models", "back_propagate"),
    "transfer_function": ("models", "transfer_function"),
    "reconstruct_many": ("distributed", "reconstruct_many"),
    # the method options (clfza.solvers): short names for clfza.reconstruct's method=
    "ADMM": ("solvers", "AdmmOptions"), "FISTA": ("solvers", "FistaOptions"),
    "TwIST": ("solvers", "TwistOptions"), "Wiener": ("solvers", "WienerOptions"),
}
_SUBMODULES = ("backends", "benchmarks", "camera", "cl", "cli", "denoisers", "distributed", "fft",
               "focus", "io", "metrics", "models", "reconstruction", "regularizers", "solvers")

__all__ = ["Camera", "ClfzaError", "DeviceError", "Measurement", "Noise", "simulate",
           "__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        package, attribute = _LAZY[name]
        value = getattr(importlib.import_module(f".{package}", __name__), attribute)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'clfza' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | set(_SUBMODULES))
