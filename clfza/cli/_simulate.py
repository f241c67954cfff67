"""``clfza simulate SCENE --camera CAMERA``: a raw frame and its ground truth.

Writes ``OUT/NAME-raw.<png|tif|npy>`` (the sensor frame, readable by ``clfza reconstruct``),
``OUT/NAME.json`` (camera, noise, scene geometry, the frame's gain and the object's mean, which
is the ``--object-mean`` that reproduces the simulation's scale) and, in the subfolder
``OUT/truth/``, ``NAME-truth.npy`` and ``NAME-truth.png`` (the sensor-plane object, the
reconstruction target): a folder read (``clfza reconstruct OUT``) takes only the raw frames
(it takes no subfolders, and skips the outputs clfza's records name).

The raw frame is written losslessly: quantised frames (``bits=N`` in ``--noise``) as 8- or
16-bit integers; unquantised frames as float32 TIFF or float64 NPY, or, for PNG, quantised to
16 bits at the frame's peak.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from skimage import data

from .. import __version__
from ..errors import ClfzaError
from ..io import atomic_write_many, encode_array, encode_image, encode_json, read_scene
from ..simulation import Noise, simulate
from ._common import (
    add_camera_option,
    ignored_options,
    load_camera,
    pair,
    positive_float,
)

TRUTH_DIR = "truth"  # OUT/truth/NAME-truth.npy|png
BUILTIN_SCENES = ("camera", "astronaut", "checkerboard", "coins", "moon")
NOISE_KEYS = {"gaussian": "gaussian_var", "var": "gaussian_var", "photons": "photons",
              "read": "read_noise", "bits": "bit_depth", "exposure": "exposure", "seed": "seed"}


def parse_noise(text: str | None):
    """``--noise`` as ``KEY=V,KEY=V`` with keys gaussian (variance of y), photons, read,
    bits, exposure, seed; or a bare number: the Gaussian variance (the paper uses 0.01)."""

    if text is None or not str(text).strip() or str(text).strip().lower() in ("0", "none"):
        return Noise()
    kw: dict = {}
    try:
        var = float(text)
    except ValueError:
        pass
    else:
        return Noise(gaussian_var=var)
    for item in str(text).split(","):
        if "=" not in item:
            raise ClfzaError(f"--noise items are KEY=VALUE (keys: {', '.join(NOISE_KEYS)}), "
                             f"got {item!r}")
        k, v = (s.strip() for s in item.split("=", 1))
        if k not in NOISE_KEYS:
            raise ClfzaError(f"unknown --noise key {k!r}; keys: {', '.join(NOISE_KEYS)}")
        try:
            val = float(v)
        except ValueError:
            raise ClfzaError(f"--noise {k} must be a number, got {v!r}") from None
        if k in ("bits", "seed"):
            if not val.is_integer():
                raise ClfzaError(f"--noise {k} must be an integer, got {v!r}")
            val = int(val)
        kw[NOISE_KEYS[k]] = val
    return Noise(**kw)


def _noise_type(text: str):
    try:
        return parse_noise(text)
    except ClfzaError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


NAME = "simulate"
HELP = "simulate a raw frame and its ground truth"
DESCRIPTION = (
    "Simulate a shot through the FZA camera: SCENE is an image file "
    f"(PNG/TIFF/NPY) or a built-in scene ({', '.join(BUILTIN_SCENES)}).")


def add_arguments(p) -> None:
    """The arguments of ``clfza simulate`` (its parser made by the command line from
    :data:`NAME`, :data:`HELP` and :data:`DESCRIPTION`)."""
    p.add_argument("scene", metavar="SCENE", help="image file or built-in scene name")
    add_camera_option(p)
    p.add_argument("--noise", type=_noise_type, default=None, metavar="SPEC",
                   help="noise: a Gaussian variance (e.g. 0.01) or KEY=V,... with keys "
                   "gaussian, photons, read, bits, exposure, seed")
    p.add_argument("--object-width", type=positive_float, metavar="MM",
                   help="scene width in mm at z1 (default: fills 60%% of the sensor)")
    p.add_argument("--object-offset", type=pair(False), default=(0.0, 0.0), metavar="Y,X",
                   help="the scene centre's offset from the optical axis in mm in the object "
                   "plane, row then column direction (Y,X, the order of reconstruct's "
                   "--center; default 0,0)")
    p.add_argument("--sensor-plane", action="store_true",
                   help="SCENE is already the sensor-plane object on the camera grid")
    p.add_argument("--diffraction", action="store_true",
                   help="Fresnel diffraction of the mask (needs the camera's wavelength)")
    p.add_argument("--z1", type=positive_float, metavar="MM", help="override object distance")
    p.add_argument("--format", choices=("png", "tiff", "npy"), default="tiff",
                   help="raw frame format (default tiff)")
    p.add_argument("--name", help="output name stem (default: the scene's name)")
    p.add_argument("--out", default="clfza-out", metavar="DIR",
                   help="output folder (default clfza-out)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.set_defaults(func=run)
    return p


def load_scene(spec: str) -> tuple[np.ndarray, str]:
    """A scene image in [0, 1] from a file or a scikit-image built-in; and its name."""

    if spec in BUILTIN_SCENES and not Path(spec).exists():

        img = getattr(data, spec)()
        a = np.asarray(img, dtype=np.float64)
        if img.dtype.kind in "ui":
            a = a / np.iinfo(img.dtype).max
        return a, spec
    return read_scene(spec), Path(spec).stem


def raw_for_file(frame: np.ndarray, bits: int | None, fmt: str) -> tuple[np.ndarray, str]:
    """The frame as it will be stored, and a note on how."""
    if bits is not None:
        if bits > 16 and fmt == "png":
            raise ClfzaError(f"PNG holds at most 16 bits; the frame has {bits}")
        if bits <= 16:
            dt = np.uint8 if bits <= 8 else np.uint16
            return frame.astype(dt), f"{bits}-bit digital numbers as {np.dtype(dt).name}"
    if fmt == "png":
        peak = float(frame.max()) or 1.0
        return (np.round(np.clip(frame / peak, 0, 1) * 65535).astype(np.uint16),
                "quantised to 16 bits at the frame's peak")
    if fmt == "tiff":
        return frame.astype(np.float32), "float32"
    return frame.astype(np.float64), "float64"


def run(args) -> int:
    """Entry point of ``clfza simulate``."""

    ignored = ignored_options(args)
    camera = load_camera(args.camera, args.z1)
    scene, name = load_scene(args.scene)
    name = args.name or name
    if not name or "/" in name or "\\" in name:
        raise ClfzaError(f"--name must be a plain file name stem, got {name!r}")
    noise = args.noise or Noise()
    ext = {"png": ".png", "tiff": ".tif", "npy": ".npy"}[args.format]
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ClfzaError(f"--out {str(out)!r} is a file, not a folder")
    truth = out / TRUTH_DIR  # not beside the raw frames: a folder read takes no subfolder
    if truth.exists() and not truth.is_dir():
        raise ClfzaError(f"{str(truth)!r} is a file; simulate writes the ground truth into "
                         "that folder")
    targets = {"raw": out / f"{name}-raw{ext}", "truth_npy": truth / f"{name}-truth.npy",
               "truth_png": truth / f"{name}-truth.png", "json": out / f"{name}.json"}
    if not args.force:
        for t in targets.values():
            if t.exists():
                raise ClfzaError(f"{str(t)!r} exists; pass --force to overwrite it")
    t0 = time.perf_counter()
    dy, dx = args.object_offset  # clfza.simulate's center is (x, y)
    meas = simulate(scene, camera, object_width=args.object_width, center=(dx, dy),
                    noise=noise, diffraction=args.diffraction, sensor_plane=args.sensor_plane)
    t_sim = time.perf_counter() - t0
    raw, how = raw_for_file(meas.frame, noise.bit_depth, args.format)
    files = [(targets["raw"], encode_array(targets["raw"], raw)),
             (targets["truth_npy"], encode_image(targets["truth_npy"], meas.truth)[0]),
             (targets["truth_png"], encode_image(targets["truth_png"], meas.truth,
                                                 scaling="unit")[0])]
    truth_mean = float(np.mean(meas.truth))
    record = {
        "clfza_version": __version__,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "scene": args.scene,
        "camera": camera.summary(),
        "camera_file": args.camera,
        "noise": noise.__dict__.copy(),
        "frame_noise": meas.info.get("frame_noise"),
        "raw_storage": how,
        "frame_scale": meas.frame_scale,
        "object_mean": truth_mean,
        "object_mean_note": "pass as --object-mean to reconstruct on the simulation's scale",
        "simulation": meas.info,
        "simulate_s": t_sim,
        "outputs": {k: str(v) for k, v in targets.items()},
    }
    if ignored:
        record["ignored_options"] = ignored
    # the whole record or nothing (JSON last)
    atomic_write_many(files + [(targets["json"], encode_json(record))], force=args.force)
    if not args.quiet:
        print(f"wrote {targets['raw']} ({how}), {targets['truth_npy']}, {targets['truth_png']}, "
              f"{targets['json']}")
    return 0
