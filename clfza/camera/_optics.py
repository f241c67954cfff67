"""Geometry, resolution and sampling of an FZA lensless camera: pure functions.

Units are millimetres (lengths) and cycles per millimetre (spatial frequencies). Equation
numbers refer to Wu et al., "Single-shot lensless imaging with Fresnel zone aperture and
incoherent illumination", Light Sci. Appl. 9, 53 (2020).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import j1

from ..errors import positive

# First zero of J1(2 pi x) is at x = 0.6098 (j_{1,1} / (2 pi) = 3.8317 / 6.2832).
BESSEL_J1_FIRST_ZERO = 3.831705970207512 / (2.0 * math.pi)


def magnification(z1: float, z2: float) -> float:
    """Image magnification ``M = z2 / z1`` of the pinhole model (Eq. 2)."""
    return positive("z2", z2) / positive("z1", z1)


def image_size(h_o: float, z1: float, z2: float) -> float:
    """Size on the sensor ``h_i = M h_o`` of an object of size ``h_o`` at ``z1`` (Eq. 2)."""
    return positive("h_o", h_o) * magnification(z1, z2)


def field_of_view(h_i: float, z2: float) -> float:
    """Half field of view in radians, ``theta = atan(h_i / (2 z2))`` (Eq. 3).

    ``h_i`` is the sensor (image) width that is used; the full angle is twice this.
    """
    return math.atan(positive("h_i", h_i) / (2.0 * positive("z2", z2)))


def shadow_scale(z1: float, z2: float) -> float:
    """Shadow magnification ``1 + z2/z1`` of the mask cast by a point at distance ``z1``."""
    return 1.0 + positive("z2", z2) / positive("z1", z1, allow_inf=True)


def shadow_r1(r1: float, z1: float, z2: float) -> float:
    """FZA constant of the shadow on the sensor, ``r1' = (1 + z2/z1) r1``."""
    return positive("r1", r1) * shadow_scale(z1, z2)


def resolution(r1: float, R: float) -> float:
    """Rayleigh resolution ``r_c = 0.61 r1^2 / R`` in the plane of the FZA pattern (Eq. 5).

    Uses the exact first zero of J1 (0.6098); the paper rounds it to 0.61.
    """
    return BESSEL_J1_FIRST_ZERO * positive("r1", r1) ** 2 / positive("R", R)


def outermost_zone_width(r1: float, R: float) -> float:
    """Width ``dr = (sqrt(n) - sqrt(n - 1)) r1`` of the outermost zone, ``n = (R/r1)^2``.

    For many zones ``dr ~ r1 / (2 sqrt(n)) = r1^2 / (2 R)``, so ``r_c = 1.22 dr`` (Eq. 6).
    """
    r1 = positive("r1", r1)
    n = (positive("R", R) / r1) ** 2
    if n < 1:
        return R
    return (math.sqrt(n) - math.sqrt(n - 1.0)) * r1


def object_resolution(r1: float, R: float, z1: float, z2: float) -> float:
    """Resolution in the object plane ``r_c' = r_c / M`` (text after Eq. 6)."""
    return resolution(r1, R) / magnification(z1, z2)


def band_limit(R: float, r1p: float) -> float:
    """Highest spatial frequency the aperture records, ``rho_c = R / r1'^2`` (cycles/mm)."""
    return positive("R", R) / positive("r1'", r1p) ** 2


def coherent_impulse_response(r: np.ndarray, r1: float, R: float) -> np.ndarray:
    """Coherent impulse response ``exp(i pi r^2/r1^2) (R/r) J1(2 pi r R / r1^2)`` (Eqs. 4, 13).

    Returned complex; its value at ``r = 0`` is the limit ``pi R^2 / r1^2``. Only the real part
    is physical for an intensity object (text after Eq. 4).
    """
    r1 = positive("r1", r1)
    R = positive("R", R)
    r = np.abs(np.asarray(r, dtype=np.float64))
    arg = 2.0 * np.pi * r * R / r1**2
    with np.errstate(divide="ignore", invalid="ignore"):
        amp = np.where(r > 0, R * j1(arg) / np.where(r > 0, r, 1.0), np.pi * R**2 / r1**2)
    return np.exp(1j * np.pi * r**2 / r1**2) * amp


@dataclass(frozen=True)
class SamplingRegime:
    """How the FZA shadow relates to the sensor grid (docs/design.md s.1).

    ``ratio = r1'^2 / (N p^2)`` with ``N`` the larger sensor side; 1 is critical sampling, where
    the FFT transfer function ``H_T`` equals the spatial convolution. Below 1 the spatial FZA is
    under-sampled at the sensor edge; above 1 the frequency chirp is under-sampled and the
    implied PSF wraps around the periodic grid.
    """

    ratio: float
    name: str  # "critical", "undersampled-space" or "undersampled-frequency"
    advice: str

    @property
    def is_critical(self) -> bool:
        return self.name == "critical"


# warn (and let model="auto" choose the exact model) when r1'^2 / (N p^2) is off 1 by more
FAR_FROM_CRITICAL = 0.25
# |ratio - 1| <= 10 %: a small model error (measured: docs/measurements.md, clfza.camera._optics;
# docs/design.md s.1)
CRITICAL_TOLERANCE = 0.1


def sampling_regime(r1p: float, pitch: float, n: int) -> SamplingRegime:
    """Classify ``r1'^2`` against ``N p^2`` (docs/design.md s.1).

    Parameters
    ----------
    r1p : float
        Shadow FZA constant ``r1'`` in mm.
    pitch : float
        Pixel pitch ``p`` in mm.
    n : int
        Number of samples along the (larger) sensor side.
    """
    ratio = positive("r1'", r1p) ** 2 / (int(n) * positive("pitch", pitch) ** 2)
    if abs(ratio - 1.0) <= CRITICAL_TOLERANCE:
        return SamplingRegime(ratio, "critical", "H_T on the FFT grid is exact")
    if ratio < 1.0:
        return SamplingRegime(
            ratio,
            "undersampled-space",
            "the spatial FZA aliases at the sensor edge; use model='exact' (linear convolution "
            "on a padded grid, clfza.models._exact) or bin less",
        )
    return SamplingRegime(
        ratio,
        "undersampled-frequency",
        "the chirp sin(pi r1'^2 rho^2) aliases and the PSF wraps around; use model='exact' "
        "(linear convolution on a padded grid with a crop, clfza.models._exact)",
    )


def critical_r1p(pitch: float, n: int) -> float:
    """The shadow constant ``r1' = sqrt(N) p`` at which ``H_T`` is exact on an N-point grid."""
    return math.sqrt(int(n)) * positive("pitch", pitch)


def pixel_nyquist(pitch: float) -> float:
    """Pixel Nyquist frequency ``1 / (2 p)`` in cycles/mm."""
    return 0.5 / positive("pitch", pitch)


def suggested_bin_factor(pitch: float, R: float, r1p: float) -> int:
    """Largest integer ``b`` with ``1/(2 b p) >= R / r1'^2`` (docs/design.md s.3); 1 = no binning.

    Binning by ``b`` keeps every frequency the aperture can record.
    """
    ratio = pixel_nyquist(pitch) / band_limit(R, r1p)
    return max(1, int(math.floor(ratio + 1e-9)))

