"""Built-in benchmark scenes, all shipped with scikit-image or drawn here (no downloads).

=========  ==========================================================================
name       scene
=========  ==========================================================================
natural    ``skimage.data.camera()``: the natural grey image of the paper's Fig. 7 role
text       ``skimage.data.text()`` binarised (Otsu) and inverted: sparse white text on
           black, padded to a square
rgb        ``skimage.data.astronaut()``: an RGB image (channels reconstruct independently)
usaf       a USAF-1951-like bar target drawn here: 3 groups, elements 1..6 at
           ``2^(g + (e-1)/6)`` line pairs per mm in the object plane (see :func:`usaf_target`)
points     a few point sources on the sensor plane (:func:`clfza.simulation.point_sources`)
=========  ==========================================================================

Scenes are placed with :func:`measurement`, which simulates one shot on a camera: the scene is
projected to fill 60% of the sensor width (the paper's 300-of-512 pixel fill), except ``points``
which are placed directly on the sensor grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from skimage import data
from skimage.filters import threshold_otsu

from ..camera import Camera
from ..errors import ClfzaError
from ..simulation import Measurement, Noise, point_sources, simulate

SCENES = ("natural", "text", "rgb", "usaf", "points")


def natural() -> np.ndarray:
    """scikit-image's 512x512 'camera' (grey, float in [0, 1])."""

    return data.camera().astype(np.float64) / 255.0


def text() -> np.ndarray:
    """Sparse binary text: scikit-image's 'text' thresholded (Otsu), inverted, squared."""

    t = data.text().astype(np.float64)
    b = (t < threshold_otsu(t)).astype(np.float64)  # dark letters -> 1
    h, w = b.shape
    n = max(h, w)
    out = np.zeros((n, n))
    out[(n - h) // 2:(n - h) // 2 + h, (n - w) // 2:(n - w) // 2 + w] = b
    return out


def rgb() -> np.ndarray:
    """scikit-image's 512x512 'astronaut' (RGB, float in [0, 1])."""

    return data.astronaut().astype(np.float64) / 255.0


def usaf_lp_per_mm(group: int, element: int) -> float:
    """Line pairs per mm of a USAF-1951 group and element: ``2^(g + (e - 1)/6)``."""
    return float(2.0 ** (group + (element - 1) / 6.0))


def usaf_target(size: int = 512, width_mm: float = 20.0, groups: tuple[int, ...] | None = None,
                oversample: int = 4) -> tuple[np.ndarray, list[dict]]:
    """Draw a USAF-1951-like resolution target: white bars on black.

    Each element is three horizontal and three vertical bars of width ``1 / (2 lp)`` mm and
    length five bar widths, at ``lp = 2^(g + (e-1)/6)`` line pairs per mm of the object plane,
    for a target ``width_mm`` wide drawn on ``size`` x ``size`` pixels. ``groups`` default:
    three groups whose coarsest bar is about ``width_mm / 40`` (0, 1, 2 for a 20 mm target:
    1 to 7.1 lp/mm, up to the Nyquist limit of the paper's simulation setup). The canvas is drawn
    ``oversample`` times finer and block-averaged (anti-aliased edges).

    Returns
    -------
    (image, elements)
        The target in [0, 1] and, per element, its group, element, lp/mm and the pixel box
        (row0, col0, row1, col1) it occupies.
    """
    if size < 64:
        raise ClfzaError(f"the USAF target needs at least 64 pixels, got {size}")
    fine = size * oversample
    mm_per_px = width_mm / fine
    canvas = np.zeros((fine, fine))
    elements: list[dict] = []
    margin = int(0.03 * fine)
    col = margin
    row = margin
    row_h = 0
    if groups is None:  # three groups, the coarsest bar about width / 40
        g0 = int(round(np.log2(20.0 / width_mm)))
        groups = (g0, g0 + 1, g0 + 2)
    for g in sorted(groups):
        for e in range(1, 7):
            lp = usaf_lp_per_mm(g, e)
            bw = 1.0 / (2.0 * lp) / mm_per_px  # bar width in fine pixels
            bl = 5.0 * bw
            w = int(np.ceil(bl + 5.0 * bw + 2 * bw))  # horizontal + gap + vertical set
            h = int(np.ceil(bl))
            if col + w > fine - margin:
                col = margin
                row += row_h + int(2 * bw) + margin // 3
                row_h = 0
            if row + h > fine - margin:
                raise ClfzaError("the USAF target does not fit; use fewer groups or a larger "
                                 "width_mm")
            # three horizontal bars (resolve vertical detail), then three vertical bars
            for k in range(3):
                r0 = row + 2 * k * bw
                canvas[int(round(r0)):int(round(r0 + bw)), int(col):int(round(col + bl))] = 1
            c1 = col + bl + 2 * bw
            for k in range(3):
                c0 = c1 + 2 * k * bw
                canvas[int(row):int(round(row + bl)), int(round(c0)):int(round(c0 + bw))] = 1
            elements.append({"group": g, "element": e, "lp_per_mm": lp,
                             "bar_width_mm": 1.0 / (2.0 * lp),
                             "box_px": [int(row) // oversample, int(col) // oversample,
                                        int(np.ceil((row + h) / oversample)),
                                        int(np.ceil((col + w) / oversample))]})
            col += w + int(2 * bw)
            row_h = max(row_h, h)
    img = canvas.reshape(size, oversample, size, oversample).mean(axis=(1, 3))
    used = np.flatnonzero(img.any(axis=1))
    shift = (size - 1 - used[-1] - used[0]) // 2  # centre the drawn rows vertically
    img = np.roll(img, shift, axis=0)
    for el in elements:
        el["box_px"][0] += shift
        el["box_px"][2] += shift
    return img, elements


def point_list(camera: Camera, count: int = 7, seed: int = 3) -> list[tuple[float, float, float]]:
    """``count`` point sources spread over the central 60% of the field, intensities 0.5-1."""
    rng = np.random.default_rng(seed)
    M = camera.magnification or 1.0
    half = 0.3 * min(camera.sensor_size) / M  # object-plane half width of the central 60%
    pts = []
    for _ in range(count):
        x, y = rng.uniform(-half, half, size=2)
        pts.append((float(x), float(y), float(rng.uniform(0.5, 1.0))))
    return pts


@dataclass
class SceneMeasurement:
    """A simulated benchmark shot and how it was made."""

    name: str
    description: str
    measurement: Measurement
    extra: dict


def describe(name: str) -> str:
    """One-line description of a built-in scene."""
    return {
        "natural": "skimage.data.camera (natural grey, 512^2)",
        "text": "skimage.data.text binarised and inverted (sparse binary text)",
        "rgb": "skimage.data.astronaut (RGB, 512^2)",
        "usaf": "USAF-1951-like bar target, 3 groups (1-7.1 lp/mm at 20 mm width)",
        "points": "7 point sources on the sensor plane (bilinear)",
    }[name]


def scene_image(name: str) -> np.ndarray:
    """The scene array of a built-in scene (not for ``points``, which lives on the sensor)."""
    if name == "natural":
        return natural()
    if name == "text":
        return text()
    if name == "rgb":
        return rgb()
    if name == "usaf":
        return usaf_target()[0]
    raise ClfzaError(f"unknown scene {name!r}; choose one of {SCENES}")


def measurement(name: str, camera: Camera, noise: Noise | None = None,
                object_width: float | None = None) -> SceneMeasurement:
    """Simulate one shot of a built-in scene on ``camera``.

    Parameters
    ----------
    name : str
        One of :data:`SCENES`.
    camera : Camera
        The camera; the scene fills 60% of its sensor width unless ``object_width`` is given.
    noise : Noise, optional
        Sensor / observation noise.
    object_width : float, optional
        Object-plane width of the scene in mm.
    """
    if name not in SCENES:
        raise ClfzaError(f"unknown scene {name!r}; choose one of {SCENES}")
    extra: dict = {}
    if name == "points":
        pts = point_list(camera)
        obj = point_sources(camera, pts)
        meas = simulate(obj, camera, noise=noise, sensor_plane=True)
        extra["points"] = [list(p) for p in pts]
    else:
        width = object_width
        if width is None:
            width = 0.6 * camera.shape[1] * camera.pitch / (camera.magnification or 1.0)
        if name == "usaf":
            img, elems = usaf_target(width_mm=width)
            extra["usaf_elements"] = [{k: v for k, v in e.items() if k != "box_px"}
                                      for e in elems]
            extra["object_pixel_mm"] = camera.pitch / (camera.magnification or 1.0)
            extra["object_nyquist_lp_per_mm"] = 0.5 / extra["object_pixel_mm"]
        else:
            img = scene_image(name)
        meas = simulate(img, camera, object_width=width, noise=noise)
        extra["object_width_mm"] = width
    return SceneMeasurement(name, describe(name), meas, extra)
