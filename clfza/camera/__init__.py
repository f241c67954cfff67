"""The camera: sensor, mask and geometry (:class:`Camera`), its optics (Eqs. 2-8), masks
(Eqs. 1, 7, 9), calibration from a point-source capture, and the shipped presets."""

from __future__ import annotations

from ._camera import Camera

__all__ = ["Camera"]
