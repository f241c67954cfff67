"""The camera: sensor, mask and geometry (:class:`Camera`) with its optics (magnification,
field of view, resolution and sampling regime, Eqs. 2-8), the zone-plate masks (Eqs. 1, 7, 9),
calibration from a point-source capture (:func:`calibrate`) and the shipped presets."""

from __future__ import annotations

from ._calibrate import calibrate, camera_toml
from ._camera import PITCH_RANGE, Camera, CameraWarning, plausibility
from ._masks import aperture_radius2_pixels, axis_phase, zone_plate
from ._optics import FAR_FROM_CRITICAL
from ._sampling import SamplingWarning, check_regime

__all__ = [
    "Camera",
    "CameraWarning",
    "FAR_FROM_CRITICAL",
    "PITCH_RANGE",
    "SamplingWarning",
    "aperture_radius2_pixels",
    "axis_phase",
    "calibrate",
    "camera_toml",
    "check_regime",
    "plausibility",
    "zone_plate",
]
