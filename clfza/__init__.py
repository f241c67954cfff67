"""clfza: OpenCL-accelerated reconstruction for Fresnel-zone-aperture lensless cameras.

Equation numbers in docstrings refer to Wu et al., Light Sci. Appl. 9, 53 (2020).
"""

from .api import ReconInfo, Reconstruction, reconstruct
from .camera import Camera
from .errors import ClfzaError, DeviceError
from .model import NumpyOperator, back_propagate, transfer_function
from .simulate import Measurement, Noise, simulate

__version__ = "0.1.0"

__all__ = ["Camera", "Measurement", "Noise", "ReconInfo", "Reconstruction", "reconstruct",
           "simulate", "ClfzaError", "DeviceError", "NumpyOperator", "back_propagate",
           "transfer_function", "__version__"]
