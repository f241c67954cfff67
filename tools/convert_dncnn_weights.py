"""Convert scico's pretrained DnCNN weights (flax msgpack) to the ``.npz`` files clfza ships.

Run once, by a maintainer, to (re)create ``clfza/denoisers/weights/dncnn*.npz``::

    .venv/bin/python -m pip download --no-deps scico==0.0.7 -d /tmp/scico_whl
    .venv/bin/python -m pip install msgpack     # a tool-only dependency of this script
    .venv/bin/python tools/convert_dncnn_weights.py /tmp/scico_whl/scico-0.0.7-py3-none-any.whl

The wheel is read as a zip file: scico, JAX and flax are never imported (nor installed).
``msgpack`` is needed by this script alone; clfza itself does not depend on it (the shipped
``.npz`` files are read by numpy). scico is BSD-3-Clause (Copyright (c) 2021-2025, Los Alamos
National Laboratory); its licence is copied next to the weights as ``LICENSE``.

What the flax files hold (``flax.serialization.msgpack_serialize``): a nested map
``{"params": {...}, "batch_stats": {...}}`` whose arrays are msgpack extension objects of
type 1, each a packed ``(shape, dtype name, raw bytes)``. scico's ``DnCNNNet`` names them
``conv_start/kernel`` (3, 3, C, 64), ``ConvBNBlock_<k>/Conv_0/kernel`` (3, 3, 64, 64),
``ConvBNBlock_<k>/BatchNorm_0/{scale, bias}`` and ``batch_stats/.../{mean, var}`` (64,),
``conv_end/kernel`` (3, 3, 64, C), with C = 1 for the blind variants and 2 for the
noise-conditional ``N`` ones (the image and a constant sigma channel).

Each ``.npz`` stores the arrays *unchanged* (float32, flax's layouts: kernels height x width x
in x out): ``w0``, ``w1`` .. ``w{D-2}`` (the blocks), ``w{D-1}`` (the last conv), and
``bn_scale``, ``bn_bias``, ``bn_mean``, ``bn_var`` of shape (D - 2, 64). BatchNorm is folded
into a per-channel scale and bias at *load* time (:func:`clfza.denoisers.load_dncnn`), so the
shipped files remain the trained parameters themselves and the reference network can apply
BatchNorm literally. A ``meta`` string records the source (wheel, file, its SHA-256).
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import sys
import zipfile
from pathlib import Path

import numpy as np

try:
    import msgpack
except ImportError:  # pragma: no cover - a tool-only dependency
    sys.exit("convert_dncnn_weights.py needs msgpack: .venv/bin/python -m pip install msgpack")

VARIANTS = ("6L", "6M", "6H", "6N", "17L", "17M", "17H", "17N")
# What clfza ships (4.3 MB): every 6-layer variant and the noise-conditional 17-layer one,
# which covers the blind 17-layer ones' noise levels (0.06/0.10/0.20) with its sigma input.
# The three blind 17-layer files would add 6.2 MB; --variants converts them too.
SHIPPED = ("6L", "6M", "6H", "6N", "17N")
FLAX_DIR = "scico/data/flax/"
LICENSE_MEMBER = "scico-0.0.7.dist-info/licenses/LICENSE"
OUT = Path(__file__).resolve().parents[1] / "clfza" / "denoisers" / "weights"


def _decode(obj):
    """flax's msgpack tree -> nested dicts of numpy arrays (ExtType 1: an ndarray)."""
    if isinstance(obj, dict):
        return {k: _decode(v) for k, v in obj.items()}
    if isinstance(obj, msgpack.ExtType):
        if obj.code != 1:
            raise ValueError(f"unexpected msgpack extension type {obj.code} (not an ndarray)")
        shape, dtype, raw = msgpack.unpackb(obj.data, raw=False)
        return np.frombuffer(raw, dtype=np.dtype(dtype)).reshape(shape).copy()
    raise ValueError(f"unexpected object {type(obj).__name__} in the flax tree")


def convert(data: bytes, variant: str) -> dict[str, np.ndarray]:
    """The arrays of one ``dncnn<variant>.mpk`` file, named as the ``.npz`` stores them."""
    tree = _decode(msgpack.unpackb(data, raw=False, strict_map_key=False))
    params, stats = tree["params"], tree["batch_stats"]
    blocks = sorted((k for k in params if k.startswith("ConvBNBlock_")),
                    key=lambda k: int(k.rsplit("_", 1)[1]))
    depth = len(blocks) + 2
    if depth != int(variant[:-1]):
        raise ValueError(f"dncnn{variant}: {depth} layers in the file")
    out = {"w0": params["conv_start"]["kernel"]}
    for i, b in enumerate(blocks, start=1):
        out[f"w{i}"] = params[b]["Conv_0"]["kernel"]
    out[f"w{depth - 1}"] = params["conv_end"]["kernel"]
    for key, src, name in (("bn_scale", params, "scale"), ("bn_bias", params, "bias"),
                           ("bn_mean", stats, "mean"), ("bn_var", stats, "var")):
        out[key] = np.stack([src[b]["BatchNorm_0"][name] for b in blocks])
    chans = 2 if variant.endswith("N") else 1
    if out["w0"].shape != (3, 3, chans, 64) or out[f"w{depth - 1}"].shape != (3, 3, 64, chans):
        raise ValueError(f"dncnn{variant}: unexpected first/last kernel shapes")
    for k, v in out.items():
        if v.dtype != np.float32 or not np.all(np.isfinite(v)):
            raise ValueError(f"dncnn{variant}: {k} is not finite float32")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("wheel", help="scico-0.0.7-py3-none-any.whl (pip download --no-deps)")
    ap.add_argument("--out", default=str(OUT), help="output folder (default: %(default)s)")
    ap.add_argument("--variants", nargs="+", default=list(SHIPPED), choices=VARIANTS,
                    help="variants to convert (default: those clfza ships, %(default)s)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    wheel = Path(args.wheel)
    with zipfile.ZipFile(wheel) as z:
        for v in args.variants:
            data = z.read(f"{FLAX_DIR}dncnn{v}.mpk")
            arrays = convert(data, v)
            meta = json.dumps({"source": f"{wheel.name}:{FLAX_DIR}dncnn{v}.mpk",
                               "sha256": hashlib.sha256(data).hexdigest(),
                               "layers": int(v[:-1]), "variant": v,
                               "batchnorm": "unfolded (folded at load time), eps 1e-5"})
            buf = io.BytesIO()
            np.savez_compressed(buf, meta=np.array(meta), **arrays)
            (out / f"dncnn{v}.npz").write_bytes(buf.getvalue())
            print(f"dncnn{v}.npz: {len(buf.getvalue()) / 1e6:.2f} MB, "
                  f"{sum(a.size for a in arrays.values())} parameters")
        notice = z.read(LICENSE_MEMBER).decode("utf-8")
    (out / "LICENSE").write_text(
        "The DnCNN weights in this folder (dncnn*.npz) are converted, unchanged, from the\n"
        "pretrained models shipped in scico 0.0.7 (scico/data/flax/*.mpk; trained by the\n"
        "scico developers at Los Alamos National Laboratory following Zhang et al., 'Beyond a\n"
        "Gaussian denoiser: residual learning of deep CNN for image denoising', IEEE TIP\n"
        "26(7), 2017) by tools/convert_dncnn_weights.py. scico's licence:\n\n" + notice,
        encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
