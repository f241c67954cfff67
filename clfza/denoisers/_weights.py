"""The pretrained DnCNN weights shipped with clfza, and BatchNorm folded into them.

The ``.npz`` files in ``clfza/denoisers/weights/`` are scico 0.0.7's trained models
(BSD-3-Clause, Los Alamos National Laboratory; ``weights/LICENSE``), converted unchanged by
``tools/convert_dncnn_weights.py``. BatchNorm is folded at *load* time
(:meth:`DnCNNWeights.folded`), so the files stay the trained parameters themselves.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from importlib import resources

import numpy as np

from ..errors import ClfzaError

#: BatchNorm's epsilon in scico's DnCNNNet (flax ``BatchNorm(epsilon=1e-5)``)
BN_EPS = 1e-5
#: the noise level (standard deviation, image in [0, 1]) each blind variant was trained at
BLIND_SIGMA = {"L": 0.06, "M": 0.10, "H": 0.20}
#: the noise-conditional variants' training range of sigma
CONDITIONAL_RANGE = (0.0, 0.2)
#: every variant scico trained, and those clfza ships (the blind 17-layer ones are covered by
#: 17N; ``tools/convert_dncnn_weights.py --variants 17L 17M 17H`` converts them)
ALL_VARIANTS = ("6L", "6M", "6H", "6N", "17L", "17M", "17H", "17N")
VARIANTS = ("6L", "6M", "6H", "6N", "17N")


@dataclass(frozen=True)
class DnCNNWeights:
    """One pretrained DnCNN: its trained parameters as scico stores them (float32).

    Attributes
    ----------
    variant : str
        ``"6L"``, ``"6M"``, ``"6H"``, ``"6N"`` or ``"17N"``.
    kernels : tuple of ndarray
        The ``layers`` convolution kernels, height x width x in x out (3, 3, Cin, Cout):
        (3, 3, C, 64), then (3, 3, 64, 64) for the blocks, then (3, 3, 64, C), with C = 1 for
        the blind variants and 2 (the image and a constant sigma channel) for the ``N`` ones.
    bn_scale, bn_bias, bn_mean, bn_var : ndarray
        The blocks' BatchNorm parameters and running statistics, (layers - 2, 64).
    """

    variant: str
    kernels: tuple[np.ndarray, ...]
    bn_scale: np.ndarray
    bn_bias: np.ndarray
    bn_mean: np.ndarray
    bn_var: np.ndarray

    @property
    def layers(self) -> int:
        return len(self.kernels)

    @property
    def conditional(self) -> bool:
        """True for the noise-conditional variants (sigma as a second input channel)."""
        return self.variant.endswith("N")

    @property
    def features(self) -> int:
        return int(self.kernels[0].shape[3])

    def flops(self, height: int, width: int) -> float:
        """Floating-point operations of one call on a ``height`` x ``width`` image: two per
        multiply-add of the convolutions, as the network is defined (the sigma channel's
        products included), the bias, ReLU and residual not counted."""
        return 2.0 * height * width * sum(int(np.prod(k.shape)) for k in self.kernels)

    def folded(self, dtype=np.float64) -> FoldedDnCNN:
        """The network with BatchNorm folded into the convolutions (what the kernels run).

        Block ``k``'s ``conv -> BN`` becomes ``conv(x, w * s) + (beta - mean * s)`` with
        ``s = gamma / sqrt(var + eps)`` per output channel, computed in float64 and then cast
        to ``dtype``. The first layer's sigma channel (``N`` variants) is a constant image, and
        under circular padding its 3x3 correlation is that constant times the sum of its
        kernel: it becomes :attr:`FoldedDnCNN.sigma_bias` (the first layer's bias is
        ``sigma * sigma_bias``). The last layer keeps its first output channel only (the
        network's output is ``x - y[..., 0]``; scico's second one is discarded).
        """
        dt = np.dtype(dtype)
        ks = [np.asarray(k, np.float64) for k in self.kernels]
        w = [ks[0][:, :, :1, :]]
        b = [np.zeros(self.features)]
        s = self.bn_scale.astype(np.float64) / np.sqrt(self.bn_var.astype(np.float64) + BN_EPS)
        for i in range(1, self.layers - 1):
            w.append(ks[i] * s[i - 1])
            b.append(self.bn_bias[i - 1].astype(np.float64) - self.bn_mean[i - 1] * s[i - 1])
        w.append(ks[-1][:, :, :, :1])
        b.append(np.zeros(1))
        sigma_bias = (ks[0][:, :, 1, :].sum(axis=(0, 1)) if self.conditional
                      else np.zeros(self.features))
        return FoldedDnCNN(self.variant, tuple(a.astype(dt) for a in w),
                           tuple(a.astype(dt) for a in b), sigma_bias.astype(dt))


@dataclass(frozen=True)
class FoldedDnCNN:
    """A DnCNN with BatchNorm folded in (:meth:`DnCNNWeights.folded`): layer ``l`` is
    ``relu(conv(a, weights[l]) + biases[l])`` (no ReLU on the last), with the first layer's
    bias plus ``sigma * sigma_bias``, and the output is ``x - a_last``."""

    variant: str
    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    sigma_bias: np.ndarray


def check_variant(variant) -> str:
    """``variant`` if clfza ships it; a ClfzaError naming the choices otherwise."""
    if not isinstance(variant, str) or variant not in ALL_VARIANTS:
        raise ClfzaError(f"DnCNN variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
    if variant not in VARIANTS:
        raise ClfzaError(
            f"DnCNN variant {variant!r} is not shipped with clfza (17N covers its noise level; "
            f"shipped: {', '.join(VARIANTS)}); convert it from scico's wheel with "
            f"tools/convert_dncnn_weights.py --variants {variant} (see that script)")
    return variant


@functools.cache
def load_dncnn(variant: str = "6N") -> DnCNNWeights:
    """Load a pretrained DnCNN shipped with clfza (scico 0.0.7's weights, BSD-3-Clause).

    Parameters
    ----------
    variant : str
        ``"6N"`` (default: 6 layers, noise-conditional, trained on sigma in [0, 0.2] for
        images in [0, 1]), ``"17N"`` (17 layers, likewise), or the blind 6-layer ones
        ``"6L"``, ``"6M"``, ``"6H"`` trained at sigma 0.06, 0.10, 0.20.

    Returns
    -------
    DnCNNWeights
        The trained parameters (float32), unchanged; cached per variant.

    Raises
    ------
    ClfzaError
        For an unknown variant, one not shipped, or a missing weights file.

    Examples
    --------
    >>> from clfza.denoisers import load_dncnn
    >>> w = load_dncnn("6N")
    >>> w.layers, w.conditional, w.kernels[0].shape
    (6, True, (3, 3, 2, 64))
    """
    check_variant(variant)
    ref = resources.files("clfza.denoisers").joinpath("weights", f"dncnn{variant}.npz")
    try:
        with ref.open("rb") as f, np.load(f) as z:
            layers = int(variant[:-1])
            kernels = tuple(np.array(z[f"w{i}"], np.float32) for i in range(layers))
            bn = {k: np.array(z[k], np.float32) for k in ("bn_scale", "bn_bias", "bn_mean",
                                                           "bn_var")}
            meta = json.loads(str(z["meta"]))
    except (FileNotFoundError, OSError, KeyError, ValueError) as exc:
        raise ClfzaError(f"the DnCNN weights dncnn{variant}.npz are missing or unreadable in "
                         f"the clfza installation ({exc}); reinstall clfza") from None
    if meta.get("variant") != variant:
        raise ClfzaError(f"dncnn{variant}.npz holds variant {meta.get('variant')!r}")
    for a in bn.values():
        a.setflags(write=False)
    for k in kernels:
        k.setflags(write=False)
    return DnCNNWeights(variant, kernels, **bn)
