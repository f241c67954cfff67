"""The camera description: sensor, mask and geometry, with its derived optics.

A :class:`Camera` is immutable and validated on construction. Presets for the paper's two
setups ship as TOML files in ``clfza/presets``.
"""

from __future__ import annotations

import math
import sys
import warnings
from dataclasses import asdict, dataclass, field, replace
from importlib import resources
from pathlib import Path

from ..errors import ClfzaError, in_range, positive, shape2d, strict_number
from . import _optics as optics
from ._masks import MASK_KINDS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

PRESETS = ("simulation", "experiment")
CAMERA_KINDS = ("fza", "psf")
#: the keys of a zone-plate camera that a measured-PSF camera file does not have
FZA_KEYS = ("r1", "z1", "R", "mask", "phase", "r1_shadow", "mask_center", "wavelength")

#: physical ranges of a camera's values (mm): outside them a value is most likely a unit slip
PITCH_RANGE = (0.5e-3, 0.1)  # 0.5 um .. 100 um photosites
PITCH_IMPOSSIBLE = 1.0  # a pixel of 1 mm or more is no sensor: an error, not a warning
#: lengths (mm) clfza computes with: outside, squares and ratios of the optics (r1'^2,
#: r1'^2 / (N p^2), (R / p)^2) overflow or vanish in float64 -- an error, naming the value
LENGTH_RANGE = (1e-12, 1e12)


class CameraWarning(UserWarning):
    """A camera value outside its physical range (most likely a unit slip); the message is
    one line naming the slip."""


def _um(v: float) -> str:
    return f"{v * 1000:.4g} um"


def plausibility(cam: Camera) -> tuple[list[str], list[str]]:
    """(errors, warnings) for values of a camera file outside their physical ranges, each one
    line naming the likely unit slip (camera files give millimetres): a pitch above 0.1 mm
    (micrometres written as millimetres; 1 mm or more is an error) or below 0.5 um (metres
    written as millimetres), ``z2 > z1`` (the distances swapped), ``r1`` larger than the
    sensor (micrometres as millimetres, or the aperture ``R`` for ``r1``); and an error for a
    length (or the shadow's ``r1'``) outside :data:`LENGTH_RANGE`, where the optics' squares
    and ratios overflow or vanish in float64."""
    errors: list[str] = []
    warns: list[str] = []
    lo_len, hi_len = LENGTH_RANGE
    for key in ("pitch", "r1", "z1", "z2", "R", "r1_shadow"):
        v = getattr(cam, key)
        if v is not None and not (lo_len <= v <= hi_len) and not (key == "z1" and v == math.inf):
            errors.append(f"{key} = {v:g} mm is outside the lengths clfza computes with "
                          f"({lo_len:g} .. {hi_len:g} mm): camera files give millimetres")
    if errors:  # the shadow's constant below would overflow
        return errors, warns
    if not lo_len <= cam.r1p <= hi_len:
        errors.append(f"the shadow's zone constant r1' = (1 + z2/z1) r1 = {cam.r1p:g} mm (z1 = "
                      f"{cam.z1:g} mm, z2 = {cam.z2:g} mm) is outside the lengths clfza "
                      f"computes with ({lo_len:g} .. {hi_len:g} mm): is z1 in millimetres?")
        return errors, warns
    p = cam.pitch
    lo, hi = PITCH_RANGE
    if p > hi:
        msg = (f"pitch = {p:g} mm is a {p:g}-mm pixel, above the {hi:g} mm of any sensor: "
               f"camera files give millimetres, so {p:g} um is pitch = {p / 1000:g}")
        (errors if p >= PITCH_IMPOSSIBLE else warns).append(msg)
    elif p < lo:
        warns.append(f"pitch = {p:g} mm is a {_um(p)} pixel, below the {_um(lo)} of any "
                     f"sensor: camera files give millimetres, so {p:g} m is pitch = "
                     f"{p * 1000:g}")
    if math.isfinite(cam.z1) and cam.z2 > cam.z1:
        warns.append(f"z2 = {cam.z2:g} mm (mask to sensor) is larger than z1 = {cam.z1:g} mm "
                     "(object to mask): swapped? the mask sits a few mm from the sensor and "
                     "the object further away")
    side = max(cam.sensor_size)
    if cam.r1 > side and lo <= p <= hi:  # (a wrong pitch makes the sensor's size wrong too)
        warns.append(f"r1 = {cam.r1:g} mm (the innermost zone's radius) is larger than the "
                     f"sensor ({side:g} mm): micrometres written as millimetres (r1 = "
                     f"{cam.r1 / 1000:g})? or the aperture R given as r1?")
    return errors, warns


def _offset2d(name: str, value) -> tuple[float, float]:
    """Validate a (rows, cols) offset in pixels: two finite numbers."""
    try:
        dy, dx = (strict_number(name, v) for v in value)
    except (TypeError, ValueError):
        raise ClfzaError(f"{name} must be a pair [rows, cols] of numbers (pixels), got "
                         f"{value!r}") from None
    if not (math.isfinite(dy) and math.isfinite(dx)):
        raise ClfzaError(f"{name} must be finite, got {value!r}")
    return dy, dx


def _plausible(cam, source: str, stacklevel: int):
    """``cam`` read from ``source`` if it is physically plausible: its first implausibility a
    :class:`~clfza.errors.ClfzaError`, its doubts :class:`CameraWarning` (at the caller of the
    reading method, ``stacklevel`` frames up)."""
    errors, warns = plausibility(cam)
    if errors:
        raise ClfzaError(f"{source}: {errors[0]}")
    for w in warns:
        warnings.warn(f"{source}: {w}", CameraWarning, stacklevel=stacklevel)
    return cam


@dataclass(frozen=True)
class Camera:
    """An FZA lensless camera.

    Parameters
    ----------
    pitch : float
        Pixel pitch ``p`` in mm.
    shape : (int, int)
        Sensor (or crop) size in pixels, (rows, cols).
    r1 : float
        Innermost-zone radius of the physical mask in mm (Eq. 1).
    z1 : float
        Object distance from the mask in mm (``inf`` for a scene at infinity).
    z2 : float
        Mask-to-sensor distance in mm.
    R : float or None
        Aperture radius of the mask in mm; None for a mask larger than the sensor's view.
    mask : {"fza", "gzp"}
        Binary FZA (Eq. 1) or sinusoidal Gabor zone plate (Eq. 9).
    phase : float
        Phase offset of the zone pattern in radians.
    r1_shadow : float or None
        Calibrated shadow constant ``r1'`` in mm; overrides ``(1 + z2/z1) r1`` when given
        (the paper's experiment quotes ``r1'^2 = pi / 29.75`` mm^2).
    wavelength : float or None
        Illumination wavelength in mm, used only to simulate mask diffraction (Eq. 8).
    mask_center : (float, float)
        Offset (rows, cols) in pixels of the centre of the mask's shadow from the sensor
        pixel ``(N // 2)`` (a calibrated misalignment, see :mod:`clfza.camera._calibrate`); TOML
        ``mask_center = [dy, dx]``. It follows the physical offset when the pitch changes
        (:meth:`with_shape`).
    name : str
        A label for reports.
    kind : {"fza", "psf"}
        ``"fza"``: the mask is the zone plate above. ``"psf"``: a measured-PSF camera
        (:meth:`measured_psf`), whose operator is a point-source capture: only ``pitch`` and
        ``shape`` describe it (``r1`` and ``z1`` are placeholders that nothing reports), plus
        ``psf_z1`` and ``z2`` where depths are wanted.
    psf_z1 : float or None
        A measured-PSF camera's capture depth of its PSF (mm): with ``z2`` it turns the PSF's
        scale into the scene's depth (``1 + z2/z = scale (1 + z2/psf_z1)``).
    """

    pitch: float
    shape: tuple[int, int]
    r1: float
    z1: float
    z2: float
    R: float | None = None
    mask: str = "fza"
    phase: float = 0.0
    r1_shadow: float | None = None
    wavelength: float | None = None
    mask_center: tuple[float, float] = (0.0, 0.0)
    name: str = field(default="camera", compare=False)
    kind: str = "fza"
    psf_z1: float | None = None

    def __post_init__(self) -> None:
        for key in ("pitch", "r1", "z1", "z2", "R", "phase", "r1_shadow", "wavelength"):
            v = getattr(self, key)
            if v is not None or key in ("pitch", "r1", "z1", "z2", "phase"):
                strict_number(key, v)  # "0.01" or True is not silently converted
        if isinstance(self.mask_center, (str, bytes)):
            raise ClfzaError(f"mask_center must be a pair [rows, cols] of numbers (pixels), "
                             f"got {self.mask_center!r}")
        object.__setattr__(self, "pitch", positive("pitch", self.pitch))
        object.__setattr__(self, "shape", shape2d("shape", self.shape))
        object.__setattr__(self, "r1", positive("r1", self.r1))
        object.__setattr__(self, "z1", positive("z1", self.z1, allow_inf=True))
        object.__setattr__(self, "z2", positive("z2", self.z2))
        if self.R is not None:
            object.__setattr__(self, "R", positive("R", self.R))
        if self.mask not in MASK_KINDS:
            raise ClfzaError(f"mask must be one of {MASK_KINDS}, got {self.mask!r}")
        object.__setattr__(self, "phase", in_range("phase", self.phase, -2 * math.pi,
                                                   2 * math.pi))
        if self.r1_shadow is not None:
            object.__setattr__(self, "r1_shadow", positive("r1_shadow", self.r1_shadow))
        if self.wavelength is not None:
            object.__setattr__(self, "wavelength", in_range("wavelength", self.wavelength,
                                                            1e-5, 1e-2))
        object.__setattr__(self, "mask_center", _offset2d("mask_center", self.mask_center))
        if self.kind not in CAMERA_KINDS:
            raise ClfzaError(f"kind must be one of {CAMERA_KINDS}, got {self.kind!r}")
        if self.psf_z1 is not None:
            if self.kind != "psf":
                raise ClfzaError("psf_z1 (the depth a PSF was captured at) belongs to a "
                                 "measured-PSF camera (kind = 'psf', no r1)")
            object.__setattr__(self, "psf_z1", positive("psf_z1", strict_number(
                "psf_z1", self.psf_z1), allow_inf=True))

    @classmethod
    def measured_psf(cls, pitch: float, shape: tuple[int, int], *, z2: float | None = None,
                     psf_z1: float | None = None, name: str = "measured-psf") -> Camera:
        """A measured-PSF camera: the sensor's ``pitch`` (mm) and ``shape`` (rows, cols), and
        optionally the PSF's capture depth ``psf_z1`` and the mask-to-sensor distance ``z2``
        (mm, both or neither) to turn a PSF scale into a depth.

        The zone-plate fields are placeholders (``r1`` at critical sampling, ``z1`` at the
        capture depth or infinity) that :meth:`summary` leaves out.

        Examples
        --------
        >>> cam = Camera.measured_psf(0.0066, (488, 488), z2=8.0, psf_z1=400.0)
        >>> cam.kind, round(cam.depth_of_scale(1.0), 6)
        ('psf', 400.0)
        """
        if (z2 is None) != (psf_z1 is None):
            raise ClfzaError("a measured-PSF camera takes psf_z1 and z2 together (a depth "
                             "needs both) or neither")
        p = positive("pitch", pitch)
        n = max(shape2d("shape", shape))
        return cls(pitch=p, shape=shape, r1=math.sqrt(n) * p, z1=math.inf if psf_z1 is None
                   else psf_z1, z2=1.0 if z2 is None else z2, name=name, kind="psf",
                   psf_z1=psf_z1)

    @property
    def knows_depth(self) -> bool:
        """A measured-PSF camera with ``psf_z1`` and ``z2``: scales convert to depths."""
        return self.kind == "psf" and self.psf_z1 is not None

    def depth_of_scale(self, scale: float) -> float | None:
        """The scene depth (mm) at which the PSF captured at ``psf_z1`` is magnified by
        ``scale``: ``1 + z2/z = scale (1 + z2/psf_z1)``; ``inf`` at or beyond infinity's
        scale, None without ``psf_z1``."""
        if not self.knows_depth:
            return None
        m = positive("scale", scale) * (1.0 + self.z2 / self.psf_z1) - 1.0
        return math.inf if m <= 0 else self.z2 / m

    def scale_of_depth(self, z: float) -> float:
        """The PSF magnification for a scene at depth ``z`` (mm), the inverse of
        :meth:`depth_of_scale`."""
        if not self.knows_depth:
            raise ClfzaError("a depth needs the camera's psf_z1 and z2 (a measured-PSF camera "
                             "file's keys)")
        z = positive("z", z, allow_inf=True)
        return (1.0 + self.z2 / z) / (1.0 + self.z2 / self.psf_z1)

    # ----- geometry -------------------------------------------------------------------
    @property
    def r1p(self) -> float:
        """Shadow constant ``r1' = (1 + z2/z1) r1`` on the sensor (or the calibrated value)."""
        if self.r1_shadow is not None:
            return self.r1_shadow
        return optics.shadow_r1(self.r1, self.z1, self.z2)

    @property
    def shadow_scale(self) -> float:
        """``1 + z2/z1``: how much the mask's shadow is magnified."""
        return optics.shadow_scale(self.z1, self.z2)

    @property
    def R_shadow(self) -> float | None:
        """Aperture radius of the shadow on the sensor, ``(1 + z2/z1) R``."""
        return None if self.R is None else self.R * self.shadow_scale

    @property
    def magnification(self) -> float:
        """``M = z2 / z1`` (Eq. 2); 0 for a scene at infinity."""
        return 0.0 if math.isinf(self.z1) else self.z2 / self.z1

    @property
    def sensor_size(self) -> tuple[float, float]:
        """Physical size (height, width) of the sensor crop in mm."""
        return self.shape[0] * self.pitch, self.shape[1] * self.pitch

    @property
    def field_of_view(self) -> float:
        """Full field of view in degrees across the larger sensor side (Eq. 3, doubled)."""
        return math.degrees(2 * optics.field_of_view(max(self.sensor_size), self.z2))

    @property
    def recording_radius(self) -> float:
        """Radius on the sensor out to which zones are recorded: the aperture's shadow ``R'``,
        or the sensor half-diagonal when the mask is unbounded or larger than the sensor."""
        half_diag = 0.5 * math.hypot(*self.sensor_size)
        return half_diag if self.R_shadow is None else min(self.R_shadow, half_diag)

    @property
    def resolution_sensor(self) -> float:
        """Rayleigh resolution ``r_c = 0.61 r1'^2 / R'`` on the sensor in mm (Eq. 5)."""
        R = self.recording_radius
        return optics.resolution(self.r1p, R)

    @property
    def resolution_object(self) -> float:
        """Resolution in the object plane ``r_c / M`` in mm (after Eq. 6)."""
        if self.magnification == 0:
            return math.inf
        return self.resolution_sensor / self.magnification

    @property
    def band_limit(self) -> float:
        """``rho_c = R' / r1'^2`` in cycles/mm (docs/design.md s.1)."""
        R = self.recording_radius
        return optics.band_limit(R, self.r1p)

    @property
    def regime(self) -> optics.SamplingRegime:
        """Sampling regime of ``H_T`` on this sensor grid (docs/design.md s.1)."""
        return optics.sampling_regime(self.r1p, self.pitch, max(self.shape))

    @property
    def suggested_bin(self) -> int:
        """Bin factor that keeps every recorded frequency (docs/design.md s.3)."""
        R = self.recording_radius
        return optics.suggested_bin_factor(self.pitch, R, self.r1p)

    # ----- derived cameras ------------------------------------------------------------
    def at_depth(self, z1: float) -> Camera:
        """The same camera focused at object distance ``z1``.

        The shadow of the mask cast by a point at ``z1`` has ``r1' = (1 + z2/z1) r1`` (the
        paper's Methods). A calibrated ``r1_shadow`` was measured at this camera's ``z1``, so
        it is rescaled, not dropped:
        ``r1'(z) = r1'_cal (1 + z2/z) / (1 + z2/z1_cal)``; at the calibration depth it is
        unchanged, at ``z = inf`` it is the mask's own ``r1'_cal / (1 + z2/z1_cal)``.
        """
        z1 = positive("z1", z1, allow_inf=True)
        if self.r1_shadow is None:
            return replace(self, z1=z1)
        scale = optics.shadow_scale(z1, self.z2) / self.shadow_scale
        return replace(self, z1=z1, r1_shadow=self.r1_shadow * scale)

    def with_shape(self, shape: tuple[int, int], pitch: float | None = None) -> Camera:
        """The same camera on another grid (a crop, or a binned grid with a larger pitch).

        ``mask_center`` keeps its physical offset: it is rescaled by ``old / new`` pitch.
        """
        new_pitch = self.pitch if pitch is None else positive("pitch", pitch)
        k = self.pitch / new_pitch
        center = (self.mask_center[0] * k, self.mask_center[1] * k)
        return replace(self, shape=tuple(shape), pitch=new_pitch, mask_center=center)

    def summary(self) -> dict:
        """Derived quantities for reports: regime, resolution, band limit, FOV, bin factor.

        A measured-PSF camera reports its sensor (and ``psf_z1``, ``z2`` when known) and no
        zone-plate quantity."""
        if self.kind == "psf":
            return {"name": self.name, "kind": "psf", "shape": list(self.shape),
                    "pitch_mm": self.pitch, "z2_mm": self.z2 if self.knows_depth else None,
                    "psf_z1_mm": self.psf_z1,
                    "pixel_nyquist_cyc_per_mm": optics.pixel_nyquist(self.pitch)}
        reg = self.regime
        return {
            "name": self.name,
            "shape": list(self.shape),
            "pitch_mm": self.pitch,
            "r1_mm": self.r1,
            "r1_shadow_mm": self.r1p,
            "z1_mm": self.z1,
            "z2_mm": self.z2,
            "R_mm": self.R,
            "mask": self.mask,
            "mask_center_px": list(self.mask_center),
            "magnification": self.magnification,
            "field_of_view_deg": self.field_of_view,
            "resolution_sensor_mm": self.resolution_sensor,
            "resolution_object_mm": self.resolution_object,
            "band_limit_cyc_per_mm": self.band_limit,
            "pixel_nyquist_cyc_per_mm": optics.pixel_nyquist(self.pitch),
            "suggested_bin": self.suggested_bin,
            "sampling_ratio": reg.ratio,
            "sampling_regime": reg.name,
        }

    def to_dict(self) -> dict:
        d = asdict(self)
        d["shape"] = list(self.shape)
        d["mask_center"] = list(self.mask_center)
        return d

    # ----- files ----------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: dict, *, source: str = "camera") -> Camera:
        """Build a camera from a mapping (as read from TOML); unknown keys are an error.

        ``r1_shadow_squared`` (mm^2) may stand in for ``r1_shadow``.
        """
        table = data.get("camera", data)
        if not isinstance(table, dict):
            raise ClfzaError(f"{source}: 'camera' must be a table of camera keys, got "
                             f"{type(table).__name__} {table!r:.60}")
        data = dict(table)
        if "r1_shadow_squared" in data:
            v = positive(f"{source}: r1_shadow_squared", data.pop("r1_shadow_squared"))
            data["r1_shadow"] = math.sqrt(v)
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ClfzaError(f"{source}: unknown camera key(s) {unknown}; known keys are "
                             f"{sorted(known)} and r1_shadow_squared")
        if data.get("kind") == "psf" or (
                "r1" not in data and not any(k in data for k in FZA_KEYS)):
            return cls._measured_from_dict(data, source)
        missing = [k for k in ("pitch", "shape", "r1", "z1", "z2") if k not in data]
        if missing:
            raise ClfzaError(f"{source}: missing camera key(s) {missing}")
        if isinstance(data.get("z1"), str) and data["z1"].lower() in ("inf", "infinity"):
            data["z1"] = math.inf
        try:
            cam = cls(**data)
        except ClfzaError as exc:
            raise ClfzaError(f"{source}: {exc}") from None
        except TypeError as exc:
            raise ClfzaError(f"{source}: {exc}") from None
        return _plausible(cam, source, stacklevel=4)

    @classmethod
    def _measured_from_dict(cls, data: dict, source: str) -> Camera:
        """A measured-PSF camera file: ``pitch`` and ``shape``, optionally ``psf_z1`` and
        ``z2`` (and ``name``); a written-back camera (:meth:`to_dict`) carries its
        placeholders, which are dropped."""
        missing = [k for k in ("pitch", "shape") if k not in data]
        if missing:
            raise ClfzaError(f"{source}: missing camera key(s) {missing} (a measured-PSF "
                             "camera needs pitch and shape)")
        extra = sorted(set(data) - {"pitch", "shape", "z2", "psf_z1", "name", "kind", *FZA_KEYS})
        if extra:
            raise ClfzaError(f"{source}: unknown camera key(s) {extra}")
        z2 = data.get("z2") if data.get("psf_z1") is not None or "kind" not in data else None
        try:
            cam = cls.measured_psf(data["pitch"], data["shape"], z2=z2,
                                   psf_z1=data.get("psf_z1"),
                                   name=data.get("name", "measured-psf"))
        except (ClfzaError, TypeError) as exc:
            raise ClfzaError(f"{source}: {exc}") from None
        return _plausible(cam, source, stacklevel=5)

    @classmethod
    def from_toml(cls, path: str | Path) -> Camera:
        """Read a camera TOML file (a ``[camera]`` table or top-level keys)."""
        p = Path(path)
        if p.is_dir():
            raise ClfzaError(f"camera file {str(p)!r} is a folder, not a TOML file; give the "
                             f"camera file inside it or a preset ({', '.join(PRESETS)})")
        if not p.exists():
            raise ClfzaError(f"camera file {str(p)!r} does not exist (and is not a preset: "
                             f"{', '.join(PRESETS)})")
        if not p.is_file():
            raise ClfzaError(f"camera file {str(p)!r} is not a regular file")
        try:
            data = tomllib.loads(p.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ClfzaError(f"camera file {str(p)!r} is not valid TOML: {exc}") from None
        except RecursionError:  # tomllib recurses once per level of nested arrays/tables
            raise ClfzaError(f"camera file {str(p)!r} is not a camera file: its arrays or "
                             "tables are nested too deeply to read") from None
        table = data.get("camera", data)
        if not isinstance(table, dict):  # [[camera]] (an array of tables) or camera = 3
            what = ("an array of tables" if isinstance(table, list)
                    else f"the value {table!r:.40}")
            raise ClfzaError(f"camera file {str(p)!r}: 'camera' must be one [camera] table, "
                             f"got {what}")
        table.setdefault("name", p.stem)
        return cls.from_dict(data, source=str(p))

    @classmethod
    def preset(cls, name: str) -> Camera:
        """One of the paper's setups: ``"simulation"`` or ``"experiment"``."""
        if name not in PRESETS:
            raise ClfzaError(f"unknown camera preset {name!r}; choose one of {PRESETS}")
        text = resources.files("clfza.camera.presets").joinpath(f"{name}.toml").read_text("utf-8")
        return cls.from_dict(tomllib.loads(text), source=f"preset {name}")

    @classmethod
    def load(cls, spec: str | Path) -> Camera:
        """A preset name or a path to a TOML file."""
        if isinstance(spec, str) and spec in PRESETS:
            return cls.preset(spec)
        return cls.from_toml(spec)
