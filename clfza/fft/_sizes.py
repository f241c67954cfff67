"""FFT sizes for the OpenCL Stockham kernels (:mod:`clfza.fft._opencl`): which lengths are
"fast" (prime factors 2, 3, 5 and 7 only), rounding up to them, and the radix sequence of a
fast length's Stockham passes.
"""

from __future__ import annotations

from ..errors import ClfzaError

FAST_PRIMES = (2, 3, 5, 7)


def _factor_out(n: int) -> int:
    for p in FAST_PRIMES:
        while n % p == 0:
            n //= p
    return n


def is_fast_size(n: int) -> bool:
    """True when ``n >= 1`` has no prime factors other than 2, 3, 5 and 7."""
    return int(n) >= 1 and _factor_out(int(n)) == 1


def next_fast_size(n: int) -> int:
    """The smallest size ``>= n`` whose only prime factors are 2, 3, 5 and 7."""
    n = int(n)
    if n < 1:
        raise ClfzaError(f"FFT size must be >= 1, got {n}")
    while not is_fast_size(n):
        n += 1
    return n


good_size = next_fast_size


def fast_shape(shape) -> tuple[int, ...]:
    """``shape`` with every axis rounded up to :func:`next_fast_size`."""
    return tuple(next_fast_size(s) for s in shape)


def radices(n: int) -> list[int]:
    """Stockham radix sequence for a fast size: as many 8s as possible, then 4/2, 3, 5, 7."""
    out: list[int] = []
    k = 0
    while n % 2 == 0:
        n //= 2
        k += 1
    out += [8] * (k // 3)
    if k % 3 == 2:
        out.append(4)
    elif k % 3 == 1:
        out.append(2)
    for p in (3, 5, 7):
        while n % p == 0:
            n //= p
            out.append(p)
    if n != 1:  # pragma: no cover - callers check is_fast_size
        raise ClfzaError(f"internal error: {n} left after factoring")
    return out
