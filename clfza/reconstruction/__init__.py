"""The reconstruction entry layer: :func:`reconstruct` (one frame), :func:`focal_stack` and
:func:`reconstruct_autofocus` (depths), the planner (:func:`make_plan`,
:func:`reconstruct_planned`: what a scene lets a solve skip, and why), and the default OpenCL
device's choice by measurement."""

from __future__ import annotations

from ._autofocus import FocalStack, focal_stack, reconstruct_autofocus
from ._device_choice import install as install_device_choice
from ._device_choice import usable_devices
from ._plan import make_plan, reconstruct_planned
from ._reconstruct import reconstruct

__all__ = [
    "FocalStack",
    "focal_stack",
    "install_device_choice",
    "make_plan",
    "reconstruct",
    "reconstruct_autofocus",
    "reconstruct_planned",
    "usable_devices",
]
