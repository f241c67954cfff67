"""The solve context: what one solve knows beyond the backend's arrays, passed explicitly from
:func:`clfza.solvers.run_solver` to the ``tau`` rules, the default start and the solvers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import Camera


@dataclass
class ChannelGroup:
    """One channel group's data as the solve sees it.

    Attributes
    ----------
    y : ndarray
        The measurement the backend was given, channels first ``(C, H, W)``, in the user's
        units (float64).
    sigma : float
        Standard deviation of the noise of ``y``, estimated on the frame as given (0 when no
        camera is known to estimate it with).
    sigma_method : str or None
        How ``sigma`` was estimated (:func:`clfza.solvers.estimate_noise`); a name starting
        with ``"Haar"`` marks an upper bound.
    """

    y: np.ndarray
    sigma: float = 0.0
    sigma_method: str | None = None


@dataclass
class SolveContext:
    """The context of one :func:`clfza.solvers.run_solver` call.

    Attributes
    ----------
    camera : Camera
        The camera the frame was taken with (before any model normalisation).
    scale2 : float
        Square of the backend's data scale: the solvers run on ``K / s`` with ``tau / s^2``
        (exact model; 1 on the transfer-function model), so a user-units value is the
        solver's value times ``scale2``.
    auto_tau : bool
        Whether ``tau`` is chosen from the data (``tau="auto"``).
    group : ChannelGroup or None
        The channel group being solved (set per group by the driver's caller).
    pilot_start : bool
        The start ``x0`` is a pilot estimate (the run control ``pilot``, e.g. a coarse solve's
        image): ``tau="auto"`` on the exact model reads the noise from its residual in place
        of pilot passes (:func:`clfza.solvers.exact_group`).

    Examples
    --------
    >>> import numpy as np
    >>> from clfza import Camera
    >>> ctx = SolveContext(Camera.preset("simulation"))
    >>> ctx.group = ChannelGroup(np.zeros((1, 8, 8)))
    >>> ctx.scale2, ctx.group.sigma
    (1.0, 0.0)
    """

    camera: Camera
    scale2: float = 1.0
    auto_tau: bool = False
    group: ChannelGroup | None = None
    pilot_start: bool = False

    def user_units(self, value: float) -> float:
        """A backend-units ``tau`` or ``lam`` in the user's units."""
        return value * self.scale2
