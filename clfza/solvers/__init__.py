"""Iterative solvers (TwIST, FISTA, ADMM) written once against the backend interface."""

from __future__ import annotations

from ..errors import ClfzaError

METHODS: tuple[str, ...] = ("bp",)


def run_solver(y, camera, method, **kwargs):
    """Dispatch an iterative method (filled in by the solver modules)."""
    raise ClfzaError(f"unknown method {method!r}; available: {METHODS}")
