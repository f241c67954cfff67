"""The forward models ``y = K o``: the transfer function (Eq. 17; :class:`NumpyOperator`
and :class:`OpenCLOperator`), the exact finite-aperture, cropped-sensor model
(:class:`ExactModel`), its box high-pass view, the model chosen for a camera
(:func:`choose_model`), and measured PSFs (:func:`load_psf`)."""

from __future__ import annotations

from ._device_operator import OpenCLOperator, device_transfer_function, make_fft_engine
from ._exact import NORM_SAFETY, ExactModel, binned_model, box_bin, camera_model, choose_model
from ._highpass import default_halfwidth, highpass_frame, highpass_model, noise_gain
from ._psf import (
    PSF,
    PSFStack,
    check_depths,
    crop_to_support,
    load_psf,
    load_psf_stack,
    magnify,
    scale_psf,
)
from ._transfer import NumpyOperator, apply_spectrum, back_propagate, transfer_function

__all__ = [
    "ExactModel",
    "NORM_SAFETY",
    "NumpyOperator",
    "OpenCLOperator",
    "PSF",
    "PSFStack",
    "apply_spectrum",
    "back_propagate",
    "binned_model",
    "box_bin",
    "camera_model",
    "check_depths",
    "choose_model",
    "default_halfwidth",
    "device_transfer_function",
    "highpass_frame",
    "highpass_model",
    "load_psf",
    "load_psf_stack",
    "crop_to_support",
    "magnify",
    "make_fft_engine",
    "noise_gain",
    "scale_psf",
    "transfer_function",
]
