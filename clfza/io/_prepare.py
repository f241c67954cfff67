"""A raw frame made ready for reconstruction: dark, flat, crop, demosaic and bin, then the
observation ``y`` on the final grid (the one preparation path of the command line and of
:func:`clfza.reconstruct_many`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera import Camera
from ..errors import ClfzaError
from ._calibrate import center_crop, demosaic, flat_field, frame_to_measurement, subtract_dark
from ._read import MIN_SIDE, read_frame

log = logging.getLogger("clfza")


@dataclass
class Prepared:
    """A frame made ready for reconstruction."""

    y: np.ndarray
    camera: Camera
    record: dict = field(default_factory=dict)


def load_calibration_frame(path: str | None, what: str):

    if path is None:
        return None
    frame, _ = read_frame(path, name=f"{what} {str(path)!r}")
    return frame


def prepare_frame(path: str | Path, camera: Camera, prep, cal: dict | None = None,
                  loaded: tuple | None = None) -> Prepared:
    """Read RAW and apply dark, flat, demosaic, crop and bin; compute y on the final grid.

    ``prep`` carries the preparation options by attribute, as ``clfza reconstruct`` parses
    them: ``dark`` and ``flat`` (paths or None), ``crop`` ((H, W) or None), ``center``
    ((Y, X) pixels or None), ``bayer`` (pattern or None), ``bin`` (int or ``"auto"``) and
    ``object_mean``.

    The camera file describes the sensor: its pitch is the photosite pitch and its shape the
    crop in photosites (``--crop`` overrides it). Demosaicing halves and ``--bin B`` divides
    the grid; the pitch grows to match. ``loaded``: ``(frame, FrameInfo)`` already read
    (a page of a stack, see :mod:`clfza.io._stream`) instead of reading ``path``.
    """

    frame, finfo = loaded if loaded is not None else read_frame(path)
    cal = cal if cal is not None else {"dark": load_calibration_frame(prep.dark, "dark frame"),
                                       "flat": load_calibration_frame(prep.flat, "flat field")}
    steps = []
    if cal.get("dark") is not None:
        frame = subtract_dark(frame, cal["dark"])
        steps.append("dark")
    if cal.get("flat") is not None:
        frame = flat_field(frame, cal["flat"])
        steps.append("flat")
    crop = tuple(prep.crop) if prep.crop else tuple(camera.shape)
    pitch = camera.pitch
    if prep.bayer:
        if frame.ndim != 2:
            raise ClfzaError(f"--bayer needs a single-channel mosaic, but {str(path)!r} has "
                             f"{frame.shape[2]} channels")
        crop = (crop[0] - crop[0] % 2, crop[1] - crop[1] % 2)
    origin = (0, 0)
    ignored: list[str] = []
    if frame.shape[:2] != crop:
        center = tuple(prep.center) if prep.center else None
        frame, origin = center_crop(frame, crop, center, align=2 if prep.bayer else 1)
        steps.append(f"crop {crop[0]}x{crop[1]} at {origin}")
    elif prep.center:
        ignored.append(warn_ignored(
            prep, f"--center is ignored: the frame is already {crop[0]}x{crop[1]}, the "
            "crop's shape, so there is nothing to centre"))
    if prep.bayer:
        frame = demosaic(frame, prep.bayer)
        pitch *= 2
        steps.append(f"demosaic {prep.bayer} (2x2 superpixels)")
    b = bin_factor(prep.bin, camera.with_shape(frame.shape[:2], pitch))
    if b > 1:
        h, w = frame.shape[0] // b, frame.shape[1] // b
        if min(h, w) < MIN_SIDE:
            raise ClfzaError(f"--bin {b} leaves only {h}x{w} pixels")
        note = bin_crop_note(frame.shape[:2], b)
        if note is not None:  # said once per run; the record's preparation step says it too
            warn_ignored(prep, note)
        f = frame[:h * b, :w * b]
        frame = f.reshape(h, b, w, b, *f.shape[2:]).sum(axis=(1, 3))
        pitch *= b
        steps.append(f"bin {b}x{b}" + ("" if note is None else
                                       f" (cropped to {h * b}x{w * b} first)"))
    cam = camera.with_shape(frame.shape[:2], pitch)
    y = frame_to_measurement(frame, cam, object_mean=prep.object_mean)
    if y.ndim == 3 and y.shape[2] > 1:
        y = one_colour_scale(y, frame)
        steps.append("colour channels on one scale (white balance at the reconstruction)")
    record = {"input_file": finfo.to_dict(), "preparation": steps, "crop_origin": list(origin),
              "bin": b, "bayer": prep.bayer, "object_mean": prep.object_mean,
              "dark": prep.dark, "flat": prep.flat,
              "frame_mean": [float(v) for v in np.ravel(frame.mean(axis=(0, 1)))]}
    if ignored:
        record["ignored_options"] = ignored
    return Prepared(y, cam, record)


def one_colour_scale(y: np.ndarray, frame: np.ndarray) -> np.ndarray:
    """The colour observation of :func:`frame_to_measurement` with every channel on one
    scale: that function divides each channel by its own mean (in effect grey-world), and
    this multiplies channel ``c`` back by ``mean_c / mean(means)``, so that the channels keep
    the sensor's gains and only the reconstruction's white balance (``white_balance`` of
    :func:`clfza.reconstruct`: the PSF's gains, grey-world or none) decides the colours. A
    grey frame's scale is unchanged (the means are equal)."""
    means = np.asarray(frame, np.float64).mean(axis=(0, 1))
    return y * (means / means.mean())


def warn_ignored(prep, message: str) -> str:
    """Say (once per run) that an option does nothing here; returns the message for the
    JSON record's ``ignored_options``."""
    seen = getattr(prep, "_warned", None)
    if seen is None:
        seen = set()
        try:
            prep._warned = seen
        except AttributeError:  # pragma: no cover - a frozen namespace
            pass
    if message not in seen:
        seen.add(message)
        log.warning("%s", message)
    return message


def bin_crop_note(shape, b: int) -> str | None:
    """The warning for a crop that binning by ``b`` forces on a grid of ``shape`` (sides
    that are no multiple of ``b`` lose their last rows or columns), or None."""
    h, w = int(shape[0]), int(shape[1])
    dh, dw = h % b, w % b
    if b <= 1 or not (dh or dw):
        return None
    return (f"--bin {b} crops the {h}x{w} frame to {h - dh}x{w - dw} (sides must be multiples "
            f"of {b}: the last {dh} row(s) and {dw} column(s) are dropped); choose a bin factor "
            f"that divides the crop, or --crop {h - dh},{w - dw} to say so")


def bin_factor(text: str, cam: Camera) -> int:
    if str(text).lower() == "auto":
        return int(cam.suggested_bin)
    try:
        b = int(text)
    except ValueError:
        raise ClfzaError(f"--bin must be a positive integer or 'auto', got {text!r}") from None
    if b < 1:
        raise ClfzaError(f"--bin must be a positive integer or 'auto', got {text!r}")
    return b
