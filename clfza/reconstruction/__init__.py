"""The reconstruction entry layer: :func:`reconstruct` (one frame), :func:`focal_stack` and
:func:`reconstruct_autofocus` (depths), the planner (:func:`make_plan`,
:func:`reconstruct_planned`: what a scene lets a solve skip, and why), and the default OpenCL
device's choice by measurement.

Each entry point for one frame returns a :class:`~clfza.solvers.Reconstruction` that unpacks
as ``image, info``: :func:`reconstruct`, :func:`reconstruct_planned` (the plan on
``info.plan``) and :func:`reconstruct_autofocus` (the depth search on ``info.focus``).
"""

from __future__ import annotations

from ._autofocus import FocalStack, focal_stack, reconstruct_autofocus
from ._balance import DEFAULT_WHITE_BALANCE, WHITE_BALANCES, psf_gains, white_balance_image
from ._device_choice import install as install_device_choice
from ._device_choice import usable_devices
from ._plan import PlanWarning, make_plan, reconstruct_planned
from ._plan_record import Plan
from ._reconstruct import reconstruct

__all__ = [
    "DEFAULT_WHITE_BALANCE",
    "WHITE_BALANCES",
    "FocalStack",
    "Plan",
    "PlanWarning",
    "focal_stack",
    "install_device_choice",
    "make_plan",
    "psf_gains",
    "reconstruct",
    "reconstruct_autofocus",
    "reconstruct_planned",
    "usable_devices",
    "white_balance_image",
]
