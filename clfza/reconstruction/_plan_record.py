"""The planner's record and its application to arrays (:mod:`clfza.reconstruction._plan` makes the
plan).

:class:`Plan` holds the decisions (:class:`Decision`) with their reasons; :func:`apply_plan`
turns a measurement into the observation the plan solves (binned with an ideal anti-alias
filter, :func:`bin_measurement`; grey channels combined) and :func:`finish_plan` undoes that on
the reconstruction (:func:`upsample_image`). :class:`DiscrepancyStop` is the solver callback of
Morozov's discrepancy principle. :mod:`clfza.reconstruction._plan` re-exports everything here.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError
from ..models import binned_model, box_bin


@dataclass
class Decision:
    """One planner decision: its value, whether it changes the work, why, and the saving."""

    name: str
    value: Any
    active: bool
    reason: str
    saving: float = 0.0  # estimated fraction of the solve's work removed (0..1)

    def line(self) -> str:
        tag = "SKIP" if self.active else "keep"
        sv = f" [saves ~{100 * self.saving:.0f}% of the work]" if self.saving > 0 else ""
        return f"  {tag} {self.name:<12} {self.value!s:<24} {self.reason}{sv}"


@dataclass
class Plan:
    """The planner's decisions for one measurement (see the module docstring).

    Attributes
    ----------
    camera, method
        What was planned for.
    bin : int
        Bin factor (1 = none); ``work_camera`` is the camera of the grid actually solved.
    frame_state : {"ok", "empty", "flat", "saturated"}
        Non-"ok" states skip the solve.
    grey : bool
        A grey scene in an RGB frame (solve once); ``gains`` per channel.
    sigma : float
        Estimated noise std of ``y`` per sensor pixel (``sigma_method`` says how).
    discrepancy_target : float or None
        ``tau_d N sigma^2`` on the work grid (None without noise estimate or for "bp").
    dtype : str
        "float32" or "float64".
    fov : (row0, row1, col0, col1)
        Sensor region the scene covers (``fov_source`` says how it was found).
    decisions : list of Decision
    warnings : list of str
    """

    camera: Camera
    method: str
    shape: tuple
    channels: int
    bin: int
    work_camera: Camera
    frame_state: str
    saturated_fraction: float
    grey: bool
    gains: np.ndarray | None
    sigma: float
    sigma_method: str
    discrepancy_target: float | None
    tau_d: float
    dtype: str
    fov: tuple[int, int, int, int]
    fov_source: str
    decisions: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    @property
    def skip_solve(self) -> bool:
        """True for empty, flat and saturated frames."""
        return self.frame_state != "ok"

    @property
    def work_fraction(self) -> float:
        """Estimated remaining fraction of the unplanned solve's work (product of savings)."""
        f = 1.0
        for d in self.decisions:
            if d.active:
                f *= 1.0 - d.saving
        return f

    def explain(self) -> str:
        """The plan as text, one line per decision with its reason (``--explain``)."""
        cam = self.camera
        head = [f"plan for {cam.name} {self.shape[0]}x{self.shape[1]}"
                f"{'x' + str(self.channels) if self.channels > 1 else ''}, method "
                f"{self.method}: r1' = {cam.r1p:.4g} mm, rho_c = R'/r1'^2 = "
                f"{cam.band_limit:.4g} cyc/mm, Nyquist 1/(2p) = {0.5 / cam.pitch:.4g} "
                f"cyc/mm, sampling ratio {cam.regime.ratio:.3g} ({cam.regime.name})"]
        lines = head + [d.line() for d in self.decisions]
        lines.append(f"  estimated work: {100 * self.work_fraction:.1f}% of the unplanned "
                     "solve")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def notes(self) -> list[str]:
        """The active decisions as one-line notes (for ``ReconInfo.notes``)."""
        return [f"plan: {d.name} = {d.value}: {d.reason}" for d in self.decisions if d.active]

    def to_dict(self) -> dict:
        return {
            "method": self.method, "shape": list(self.shape), "channels": self.channels,
            "bin": self.bin, "work_shape": list(self.work_camera.shape),
            "work_pitch_mm": self.work_camera.pitch, "frame_state": self.frame_state,
            "saturated_fraction": self.saturated_fraction, "grey": self.grey,
            "gains": None if self.gains is None else [float(g) for g in self.gains],
            "sigma": self.sigma, "sigma_method": self.sigma_method,
            "discrepancy_target": self.discrepancy_target, "tau_d": self.tau_d,
            "dtype": self.dtype, "fov": list(self.fov), "fov_source": self.fov_source,
            "work_fraction": self.work_fraction,
            "decisions": [{"name": d.name, "value": str(d.value), "active": d.active,
                           "reason": d.reason, "saving": d.saving} for d in self.decisions],
            "warnings": list(self.warnings), "timings": dict(self.timings),
        }


def bin_measurement(y: np.ndarray, b: int) -> np.ndarray:
    """Resample an (H, W[, C]) image onto a grid ``b`` times coarser with an ideal
    anti-alias filter: keep the ``(H/b, W/b)`` lowest frequencies of the spectrum (Fourier
    resampling, ``scipy.signal.resample``, which splits the Nyquist bins of even sizes), so the
    values are the band-limited image sampled every ``b`` pixels. ``H`` and ``W`` must be
    multiples of ``b`` (see :func:`apply_plan`)."""
    a = np.asarray(y, dtype=np.float64)
    if a.ndim == 3:
        return np.stack([bin_measurement(a[..., c], b) for c in range(a.shape[2])], axis=-1)
    ny, nx = a.shape
    if ny % b or nx % b:
        raise ClfzaError(f"bin factor {b} does not divide the grid {a.shape}")
    # lazy: scipy.signal (and the scipy.stats it loads) would double the CLI's start-up
    from scipy.signal import resample

    out = resample(resample(a, ny // b, axis=0), nx // b, axis=1)
    return out


def upsample_image(x: np.ndarray, b: int, mode: str = "fourier") -> np.ndarray:
    """Back to the sensor grid: ``"fourier"`` zero-pads the spectrum (band-limited
    interpolation, the inverse of :func:`bin_measurement` on in-band images), ``"linear"``
    interpolates bilinearly (no ringing at TV edges)."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 3:
        return np.stack([upsample_image(a[..., c], b, mode) for c in range(a.shape[2])], -1)
    ny, nx = a.shape
    if mode == "fourier":
        # lazy: scipy.signal (and the scipy.stats it loads) would double the CLI's start-up
        from scipy.signal import resample

        return resample(resample(a, ny * b, axis=0), nx * b, axis=1)
    if mode == "linear":
        # lazy: scipy.ndimage takes ~0.25 s to import; only this resampling needs it
        from scipy.ndimage import map_coordinates

        # coarse sample k sits at fine index k*b (as in bin_measurement); periodic edges
        iy = np.arange(ny * b) / b
        ix = np.arange(nx * b) / b
        coords = np.meshgrid(iy, ix, indexing="ij")
        return map_coordinates(a, coords, order=1, mode="grid-wrap")
    raise ClfzaError(f"upsample mode must be 'fourier' or 'linear', got {mode!r}")


class DiscrepancyStop:
    """Solver callback for Morozov's discrepancy principle.

    Called once per iteration with a record (a mapping or an object) holding ``iteration``
    and one of ``residual_norm2`` / ``residual2`` (``||y - K x||^2``), ``data``
    (``1/2 ||y - K x||^2``, the data term of Eq. 19) or ``residual`` (``||y - K x||``);
    returns True (stop) at the first record with ``||y - K x||^2 <= target``.
    """

    def __init__(self, target: float):
        self.target = float(target)
        self.stopped_at: int | None = None
        self.last: float | None = None
        self.calls = 0

    @staticmethod
    def _get(rec, key):
        if isinstance(rec, dict):
            return rec.get(key)
        return getattr(rec, key, None)

    def residual2(self, rec) -> float | None:
        for key, f in (("residual_norm2", 1.0), ("residual2", 1.0), ("data", 2.0)):
            v = self._get(rec, key)
            if v is not None:
                return f * float(v)
        v = self._get(rec, "residual")
        return None if v is None else float(v) ** 2

    def __call__(self, rec) -> bool:
        self.calls += 1
        r2 = self.residual2(rec)
        if r2 is None:
            return False
        self.last = r2
        if r2 <= self.target:
            it = self._get(rec, "iteration")
            self.stopped_at = int(it) if it is not None else self.calls
            return True
        return False


def apply_plan(y: np.ndarray, plan: Plan, box: bool = False) -> np.ndarray:
    """The observation the plan solves: cropped to a multiple of the bin factor and binned
    (:func:`bin_measurement`; with ``box``, pixel binning for the exact model,
    :func:`clfza.models._exact.box_bin`), and, for a grey scene in RGB, the channels combined by
    least squares ``sum_c a_c y_c / sum_c a_c^2``."""
    a = np.asarray(y, dtype=np.float64)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if plan.grey and a.ndim == 3:
        g = plan.gains
        a = np.tensordot(a, g, axes=([2], [0])) / float(np.sum(g * g))
    b = plan.bin
    if b > 1:
        ny, nx = plan.shape
        cy, cx = (ny // b) * b, (nx // b) * b
        oy, ox = (ny - cy) // 2, (nx - cx) // 2
        a = a[oy:oy + cy, ox:ox + cx]
        if box:

            a = box_bin(a, b)
        else:
            a = bin_measurement(a, b)
    return a


def binned_exact_model(camera: Camera, plan: Plan):
    """The exact model for a frame that :func:`apply_plan` binned by pixel averaging: the
    camera cropped as the plan crops (the mask centre moves with the crop) and its kernel
    binned (:func:`clfza.models._exact.binned_model`)."""


    b = plan.bin
    ny, nx = plan.shape
    cy, cx = (ny // b) * b, (nx // b) * b
    oy, ox = (ny - cy) // 2, (nx - cx) // 2
    full = camera
    if (cy, cx) != (ny, nx):
        my, mx = camera.mask_center
        full = replace(camera, shape=(cy, cx), mask_center=(my + ny // 2 - oy - cy // 2,
                                                            mx + nx // 2 - ox - cx // 2))
    return binned_model(full, b)


def finish_plan(x: np.ndarray, plan: Plan, upsample: str | None = "fourier") -> np.ndarray:
    """Undo :func:`apply_plan` on a reconstruction: upsample to the sensor grid (``None``
    keeps the binned grid), pad a cropped border with edge values, replicate a grey
    solution into the channels with their gains."""
    a = np.asarray(x, dtype=np.float64)
    b = plan.bin
    if b > 1 and upsample is not None:
        a = upsample_image(a, b, upsample)
        ny, nx = plan.shape
        py, px = ny - a.shape[0], nx - a.shape[1]
        if py or px:
            pads = ((py // 2, py - py // 2), (px // 2, px - px // 2))
            a = np.pad(a, pads + (((0, 0),) if a.ndim == 3 else ()), mode="edge")
    if plan.grey and plan.gains is not None and a.ndim == 2:
        a = np.stack([g * a for g in plan.gains], axis=-1)
    return a
