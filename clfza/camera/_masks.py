"""Zone-plate masks: binary FZA (Eq. 1), Gabor zone plate (Eq. 9), phase offset, aperture.

All masks are sampled on a grid whose centre is at index ``(n // 2)`` along each axis (the
``fftshift`` convention), so ``numpy.fft.ifftshift`` moves the centre to index 0.
The float64 functions here are the reference for the OpenCL synthesis kernel in
``kernels/masks.cl``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from ..errors import ClfzaError, positive, shape2d

MaskKind = Literal["fza", "gzp"]
MASK_KINDS = ("fza", "gzp")


def axis_phase(n: int, pitch: float, r1: float) -> np.ndarray:
    """Per-axis zone phase ``x^2 / r1^2`` reduced modulo 2 (units of pi), in float64.

    ``pi (x^2 + y^2) / r1^2 = pi (phase_x + phase_y) (mod 2 pi)``; reducing each axis in
    float64 first keeps a float32 kernel accurate to ~1e-6 rad for any grid size.
    """
    k = (np.arange(int(n), dtype=np.float64) - int(n) // 2) ** 2
    return np.mod(k * (float(pitch) ** 2 / float(r1) ** 2), 2.0)


def aperture_radius2_pixels(R: float | None, pitch: float) -> float:
    """Aperture radius squared in pixel units (``inf`` when there is no aperture)."""
    if R is None or np.isinf(R):
        return np.inf
    return (positive("R", R) / float(pitch)) ** 2


def zone_plate(shape: tuple[int, int], pitch: float, r1: float, *, kind: MaskKind = "gzp",
               R: float | None = None, phase: float = 0.0,
               center: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Sample a zone-plate intensity transmittance on a centred grid (float64 reference).

    Parameters
    ----------
    shape : (int, int)
        Grid size (rows, cols).
    pitch : float
        Sample spacing in mm.
    r1 : float
        Radius of the innermost zone in mm (use ``r1'`` for the shadow on the sensor).
    kind : {"fza", "gzp"}
        ``"fza"``: binary ``1/2 + 1/2 sgn(cos(pi r^2/r1^2 + phase))`` (Eq. 1);
        ``"gzp"``: sinusoidal ``1/2 + 1/2 cos(pi r^2/r1^2 + phase)`` (Eq. 9).
    R : float or None
        Aperture radius in mm (``circ(r/R)``); None for an unbounded pattern.
    phase : float
        Phase offset in radians (0 for the paper's masks).
    center : (float, float)
        Offset (rows, cols) in samples of the pattern's centre (and its aperture's) from
        index ``(n // 2)``; 0 keeps the centred reference exact.

    Returns
    -------
    numpy.ndarray
        float64 array of the given shape with values in [0, 1].
    """
    ny, nx = shape2d("shape", shape)
    pitch = positive("pitch", pitch)
    r1 = positive("r1", r1)
    if kind not in MASK_KINDS:
        raise ClfzaError(f"mask kind must be one of {MASK_KINDS}, got {kind!r}")
    if not np.isfinite(phase):
        raise ClfzaError(f"phase must be finite, got {phase!r}")
    try:
        dy, dx = (float(c) for c in center)
    except (TypeError, ValueError):
        raise ClfzaError(f"center must be a pair (rows, cols) of numbers, got {center!r}"
                         ) from None
    if not (np.isfinite(dy) and np.isfinite(dx)):
        raise ClfzaError(f"center must be finite, got {center!r}")
    y = ((np.arange(ny) - ny // 2 - dy) * pitch)[:, None]
    x = ((np.arange(nx) - nx // 2 - dx) * pitch)[None, :]
    c = np.cos(np.pi * (x**2 + y**2) / r1**2 + phase)
    t = 0.5 + 0.5 * (np.sign(c) if kind == "fza" else c)
    r2lim = aperture_radius2_pixels(R, pitch)
    if np.isfinite(r2lim):
        iy = (np.arange(ny) - ny // 2 - dy)[:, None] ** 2
        ix = (np.arange(nx) - nx // 2 - dx)[None, :] ** 2
        t = np.where(ix + iy <= r2lim, t, 0.0)
    return t


def fza_fourier_orders(r: np.ndarray, r1: float, orders: int) -> np.ndarray:
    """Partial Fourier series of the binary FZA as a sum of GZPs (Eq. 7).

    ``T(r) = 1/2 + (2/pi) sum_{n=1}^{orders} (1/n) sin(n pi / 2) cos(pi n r^2 / r1^2)``.
    """
    r = np.asarray(r, dtype=np.float64)
    out = np.full(r.shape, 0.5)
    for n in range(1, int(orders) + 1):
        out += (2 / np.pi) * np.sin(n * np.pi / 2) / n * np.cos(np.pi * n * r**2 / r1**2)
    return out
