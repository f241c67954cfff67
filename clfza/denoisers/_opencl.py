"""DnCNN on an OpenCL device: ``kernels/dncnn.cl`` with BatchNorm folded into the weights.

The program is built by :meth:`clfza.cl.Runtime.program` (the one build path: flags, the
device defines, build logs, the program cache). The folded weights (float32) are uploaded
once per denoiser; the activations live in two ping-pong buffers of (N, H, W, 64) floats that
every layer reuses, allocated once per image shape and batch size; the last layer writes
``x - network(x)`` straight into the output image.

The 64 -> 64 layers (all but the first and the last) run one of two kernels: ``dncnn_mid``,
``PX`` pixels of a row per work-item with all 64 outputs as float16 vectors (CPU devices), or
``dncnn_mid_tiled``, a 16 x 16 pixel tile per work-group through local memory (GPUs and other
non-CPU devices); ``kernel=`` forces one.
"""

from __future__ import annotations

import numpy as np

from ..cl import DeviceArray, Runtime, get_runtime, typed_kernel
from ..errors import ClfzaError
from ._weights import DnCNNWeights

MID_KERNELS = ("cpu", "tiled")
#: dncnn_mid's pixels per work-item (PX): 16 float16 accumulators (measured: 2, 4, 6, 8 on the
#: three CPU implementations, bench/bench_dncnn.py --pixels; docs/measurements.md)
CPU_PIXELS = 4
TILE = (16, 16)  # dncnn_mid_tiled's output tile (TW, TH)
TILE_GROUP = (16, 8)  # ... and its work-group (each work-item two rows)
TILE_OUT = 32  # ... output channels per work-group (OG)
TILE_CHANNELS = 16  # ... input channels per pass through local memory (CB)


def _ceil(a: int, b: int) -> int:
    return -(-a // b) * b


class DnCNNDevice:
    """A pretrained DnCNN resident on one OpenCL device (float32).

    Parameters
    ----------
    weights : DnCNNWeights
        From :func:`~clfza.denoisers.load_dncnn`.
    runtime : Runtime, optional
        The device (default: :func:`clfza.cl.get_runtime`).
    kernel : {"auto", "cpu", "tiled"}
        The 64 -> 64 layers' kernel: ``auto`` takes ``cpu`` on CPU devices, ``tiled`` elsewhere.
    pixels : int
        ``dncnn_mid``'s pixels per work-item, 1 to 8 (default :data:`CPU_PIXELS`, measured:
        bench/bench_dncnn.py ``--pixels``).

    Examples
    --------
    >>> import numpy as np
    >>> from clfza.denoisers import DnCNNDevice, load_dncnn
    >>> net = DnCNNDevice(load_dncnn("6N"))  # doctest: +SKIP
    >>> net(np.full((2, 16, 16), 0.5), sigma=0.05).shape  # doctest: +SKIP
    (2, 16, 16)
    """

    def __init__(self, weights: DnCNNWeights, runtime: Runtime | None = None,
                 kernel: str = "auto", pixels: int = CPU_PIXELS):
        if kernel not in ("auto",) + MID_KERNELS:
            raise ClfzaError(f"DnCNN kernel must be 'auto', 'cpu' or 'tiled', got {kernel!r}")
        if isinstance(pixels, bool) or not isinstance(pixels, (int, np.integer)) \
                or not 1 <= pixels <= 8:
            raise ClfzaError(f"DnCNN pixels per work-item must be 1 to 8, got {pixels!r}")
        self.pixels = int(pixels)
        self.rt = rt = runtime if runtime is not None else get_runtime()
        self.weights = weights
        self.kernel = ("cpu" if rt.is_cpu else "tiled") if kernel == "auto" else kernel
        f = weights.folded(np.float32)
        if weights.features != 64:
            raise ClfzaError(f"dncnn.cl is written for 64 features, not {weights.features}")
        prg = rt.program("dncnn", np.float32, {
            "PX": self.pixels, "OG": TILE_OUT, "CB": TILE_CHANNELS}, include=("common",),
            flags=("-cl-denorms-are-zero",))
        # scalar argument types fixed on the first launch (numpy scalars): clfza.cl.typed_kernel
        self._k = {nm: typed_kernel(rt.cl, prg, nm) for nm in
                   ("dncnn_first", "dncnn_last", "dncnn_mid", "dncnn_mid_tiled")}

        def up(a):
            return DeviceArray.from_host(rt, np.ascontiguousarray(a, np.float32).reshape(-1))

        self._w = [up(w) for w in f.weights]  # (3, 3, in, out): w[tap][c][o] as dncnn.cl reads
        self._b = [up(b) for b in f.biases]
        self._sbias = up(f.sigma_bias)
        self._shape: tuple[int, int, int] | None = None
        self._act: list[DeviceArray] = []
        self._img: DeviceArray | None = None
        self._out: DeviceArray | None = None

    @property
    def layers(self) -> int:
        return self.weights.layers

    def buffers(self, n: int, h: int, w: int) -> None:
        """Allocate (once per shape) the two activation buffers and the image buffers."""
        if self._shape == (n, h, w):
            return
        self._act = []
        self.rt.check_total(2 * n * h * w * 64 * 4 + 2 * n * h * w * 4,
                            f"DnCNN's activations for {n} image(s) of {h}x{w}")
        self._act = [DeviceArray.empty(self.rt, (n, h, w, 64)) for _ in range(2)]
        self._img = DeviceArray.empty(self.rt, (n, h, w))
        self._out = DeviceArray.empty(self.rt, (n, h, w))
        self._shape = (n, h, w)

    def enqueue(self, img: DeviceArray, out: DeviceArray, sigma: float) -> None:
        """Queue every layer on ``img`` (N, H, W) into ``out`` (same shape): no wait, no
        allocation once :meth:`buffers` has run for this shape."""
        n, h, w = img.shape
        self.buffers(n, h, w)
        q, i32 = self.rt.queue, np.int32
        W, H = i32(w), i32(h)
        cpu = self.rt.is_cpu
        g1 = (w, h, n)
        l1 = (w, 1, 1) if cpu and w <= int(self.rt.device.max_work_group_size) else None
        a, b = self._act
        self._k["dncnn_first"](q, g1, l1, img.buf, self._w[0].buf, self._b[0].buf,
                               self._sbias.buf, np.float32(sigma), a.buf, W, H)
        if self.kernel == "cpu":
            gx = -(-w // self.pixels)
            gm, lm, km = (gx, h, n), None, self._k["dncnn_mid"]
        else:
            tx, ty = TILE
            gm = (_ceil(w, tx), _ceil(h, ty) // (ty // TILE_GROUP[1]), n * (64 // TILE_OUT))
            lm, km = TILE_GROUP + (1,), self._k["dncnn_mid_tiled"]
        for layer in range(1, self.layers - 1):
            km(q, gm, lm, a.buf, self._w[layer].buf, self._b[layer].buf, b.buf, W, H)
            a, b = b, a
        self._k["dncnn_last"](q, g1, l1, a.buf, self._w[-1].buf, img.buf, out.buf, W, H)

    def __call__(self, x: np.ndarray, sigma: float = 0.0) -> np.ndarray:
        """``x - DnCNN(x)`` for a (H, W) image or an (N, H, W) batch (float32 result)."""
        x = np.asarray(x, np.float32)
        single = x.ndim == 2
        xb = x[None] if single else x
        self.buffers(*xb.shape)
        self._img.set(xb)
        self.enqueue(self._img, self._out, sigma)
        y = self._out.get()
        return y[0] if single else y
