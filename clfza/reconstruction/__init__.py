"""The reconstruction entry layer: :func:`reconstruct`, the default device's choice and the
planner (what a scene lets a solve skip, and why)."""

from __future__ import annotations

from ._reconstruct import reconstruct

__all__ = ["reconstruct"]
