"""Kernel objects whose scalar argument types are fixed on their first launch.

pyopencl converts untyped numpy scalar arguments through a slow generic path, which costs a
launch with several scalar arguments more than the enqueue itself, on every implementation
(pyopencl issue #830; measured: docs/measurements.md, clfza.cl._kernels). With
``set_scalar_arg_dtypes`` it packs them directly. Every call site passes the same numpy scalar
types on every launch (the backends' ``r`` and ``i32``), so the types of the first launch's
arguments are taken (buffers: ``None``). A first launch with a Python scalar
among its arguments leaves the kernel untyped, so that pyopencl reports that argument as it
always has (it takes numpy scalars only).
"""

from __future__ import annotations

import numpy as np


class TypedKernel:
    """A pyopencl kernel that fixes its scalar argument types on its first launch."""

    __slots__ = ("kernel", "typed")

    def __init__(self, kernel):
        self.kernel = kernel
        self.typed = None  # None: not launched yet; then True or False

    def __call__(self, queue, gsize, lsize, *args, **kwargs):
        if self.typed is None:
            scalar = [isinstance(a, np.generic) for a in args]
            plain = any(isinstance(a, (int, float, complex)) and not s
                        for a, s in zip(args, scalar, strict=True))
            self.typed = not plain
            if self.typed:
                self.kernel.set_scalar_arg_dtypes(
                    [a.dtype if s else None for a, s in zip(args, scalar, strict=True)])
        return self.kernel(queue, gsize, lsize, *args, **kwargs)

    def __getattr__(self, name):
        return getattr(self.kernel, name)


def typed_kernel(cl, program, name: str) -> TypedKernel:
    """``cl.Kernel(program, name)`` with its scalar types fixed on first launch."""
    return TypedKernel(cl.Kernel(program, name))
