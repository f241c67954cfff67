"""Device arrays that are zero-copy host arrays on CPU devices.

On a CPU device (PoCL) a :class:`DeviceArray` owns an aligned numpy array and wraps it as a
``USE_HOST_PTR`` buffer, so host FFTs (scipy) and kernels share memory without copies
(docs/design.md s.6). On a GPU it owns a device buffer and copies only on ``get``/``set``.
"""

from __future__ import annotations

import numpy as np

from ..errors import ClfzaError

_ALIGN = 128


def complex_of(dtype) -> np.dtype:
    """The complex dtype of a real working precision: complex128 for float64, else
    complex64."""
    return np.dtype(np.complex128 if np.dtype(dtype) == np.float64 else np.complex64)


def aligned_empty(shape, dtype) -> np.ndarray:
    """A C-contiguous numpy array whose data pointer is 128-byte aligned."""
    dtype = np.dtype(dtype)
    n = int(np.prod(shape)) * dtype.itemsize
    raw = np.empty(n + _ALIGN, dtype=np.uint8)
    off = (-raw.ctypes.data) % _ALIGN
    return raw[off:off + n].view(dtype).reshape(shape)


class DeviceArray:
    """A buffer on one runtime's device with a known shape and dtype."""

    __slots__ = ("rt", "shape", "dtype", "buf", "host")

    def __init__(self, rt, shape, dtype, host: np.ndarray | None = None):
        cl = rt.cl
        self.rt = rt
        self.shape = tuple(int(s) for s in shape)
        self.dtype = np.dtype(dtype)
        nbytes = int(np.prod(self.shape)) * self.dtype.itemsize
        if nbytes == 0:
            raise ClfzaError(f"cannot allocate an empty device array of shape {self.shape}")
        rt.check_alloc(nbytes, f"a {self.shape} {self.dtype} array")
        if rt.zero_copy:
            self.host = aligned_empty(self.shape, self.dtype) if host is None else host
            self.buf = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE | cl.mem_flags.USE_HOST_PTR,
                                 hostbuf=self.host)
        else:
            self.host = None
            self.buf = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE, size=nbytes)

    def __del__(self):
        # A zero-copy buffer's memory is the numpy array: if it were freed now, a kernel still
        # queued on it would write into freed heap memory. Park it until the queue drains.
        host = getattr(self, "host", None)
        if host is not None:
            try:
                self.rt.defer_release(host, self.buf)
            except Exception:  # interpreter shutdown: nothing is queued any more
                pass

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def nbytes(self) -> int:
        return self.size * self.dtype.itemsize

    @classmethod
    def empty(cls, rt, shape, dtype=np.float32) -> DeviceArray:
        return cls(rt, shape, dtype)

    def leading_view(self, shape, dtype) -> DeviceArray:
        """An array of ``shape`` and ``dtype`` in this one's first bytes (a sub-buffer at
        offset 0, and on zero-copy devices a view of the same host memory): the two share
        memory, so use one only while the other's contents are dead."""
        view = object.__new__(DeviceArray)
        view.rt, view.dtype = self.rt, np.dtype(dtype)
        view.shape = tuple(int(s) for s in shape)
        nbytes = view.nbytes
        if nbytes == 0 or nbytes > self.nbytes:
            raise ClfzaError(f"a {view.shape} {view.dtype} view does not fit a {self.shape} "
                             f"{self.dtype} array")
        view.buf = self.buf.get_sub_region(0, nbytes)
        view.host = (None if self.host is None else
                     self.host.reshape(-1).view(np.uint8)[:nbytes].view(view.dtype)
                     .reshape(view.shape))
        return view

    @classmethod
    def from_host(cls, rt, a: np.ndarray, dtype=None) -> DeviceArray:
        a = np.asarray(a)
        out = cls(rt, a.shape, a.dtype if dtype is None else dtype)
        out.set(a)
        return out

    def set(self, a: np.ndarray) -> DeviceArray:
        """Copy host data in (waits for queued work that may use the buffer)."""
        a = np.ascontiguousarray(a, dtype=self.dtype)
        if a.shape != self.shape:
            raise ClfzaError(f"shape mismatch: array {a.shape} into buffer {self.shape}")
        if self.host is not None:
            self.rt.finish()
            np.copyto(self.host, a)
        else:
            self.rt.cl.enqueue_copy(self.rt.queue, self.buf, a)
        return self

    def get(self) -> np.ndarray:
        """A host copy of the contents (synchronises the queue)."""
        if self.host is not None:
            self.rt.finish()
            return self.host.copy()
        out = np.empty(self.shape, self.dtype)
        self.rt.cl.enqueue_copy(self.rt.queue, out, self.buf)
        return out

    def host_view(self) -> np.ndarray:
        """The shared host array on zero-copy devices, after the queue drains."""
        if self.host is None:
            raise ClfzaError("host_view is only available on zero-copy (CPU) devices")
        self.rt.finish()
        return self.host

    def __repr__(self) -> str:
        return f"DeviceArray(shape={self.shape}, dtype={self.dtype}, device={self.rt.info.name})"
