"""clfza: OpenCL-accelerated reconstruction for Fresnel-zone-aperture lensless cameras.

Equation numbers in docstrings refer to Wu et al., Light Sci. Appl. 9, 53 (2020).

The public names below load on first use (PEP 562), so ``import clfza`` and the command line
start without importing scipy's signal tools, scikit-image or pyopencl.
"""

from __future__ import annotations

__version__ = "0.1.0"  # first: modules that import clfza.__version__ may load before the rest

import importlib  # noqa: E402

from .camera import Camera
from .errors import ClfzaError, DeviceError
from .simulation import Measurement, Noise, simulate

_LAZY = {
    "ReconInfo": "solvers", "Reconstruction": "solvers", "reconstruct": "reconstruction",
    "NumpyOperator": "models", "back_propagate": "models", "transfer_function": "models",
    "reconstruct_many": "distributed",
}
_SUBMODULES = ("backends", "benchmarks", "camera", "cl", "cli", "distributed", "fft", "focus",
               "io", "metrics", "models", "reconstruction", "regularizers", "solvers")

__all__ = ["Camera", "ClfzaError", "DeviceError", "Measurement", "Noise", "simulate",
           "__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'clfza' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | set(_SUBMODULES))
