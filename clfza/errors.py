"""Errors and up-front validation shared by every clfza module: the one validator module.

Every check raises :class:`ClfzaError` (a ``ValueError``) with one sentence that names the
parameter and the allowed range, so that a bad input never reaches a kernel.

The number checks (:func:`positive`, :func:`nonnegative`, :func:`in_range`,
:func:`positive_int`, :func:`strict_int`, :func:`strict_number`) behave alike: a real number
(``int``, ``float``, numpy integers and floats, a 0-d numeric array, ``fractions.Fraction``)
is accepted, a bool, a string or None is an error, never converted (``True`` is not 1 and
``"3"`` is not 3). Text from the command line is parsed to a number first
(:func:`parse_number`, :func:`parse_int`), then checked by the same functions.

Examples
--------
>>> positive("tau", 0.01)
0.01
>>> positive("tau", True)
Traceback (most recent call last):
...
clfza.errors.ClfzaError: tau must be a positive number, got True
>>> positive("tau", parse_number("tau", "0.01"))
0.01
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence

import numpy as np


class ClfzaError(ValueError):
    """A clear, user-facing error: bad parameters, files, shapes or devices."""


class DeviceError(ClfzaError):
    """No usable OpenCL device, a failed kernel build, or too little device memory."""


def is_real(value) -> bool:
    """True for a real number given as a number: ``int``, ``float``, numpy integers and
    floats, a 0-d numeric array or a :class:`fractions.Fraction`; False for a bool (Python's
    or numpy's), a string, None or anything else."""
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, numbers.Real):
        return True
    return isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf"


def _real(name: str, value, what: str) -> float:
    """``value`` as float if :func:`is_real`, else ClfzaError("{name} must be {what}")."""
    if not is_real(value):
        raise ClfzaError(f"{name} must be {what}, got {value!r}")
    return float(value)


def positive(name: str, value: float, *, allow_inf: bool = False) -> float:
    """Return ``value`` as float if it is a real number, finite (or inf with ``allow_inf``)
    and > 0, else raise ClfzaError (a bool or a string is an error, see the module
    docstring)."""
    v = _real(name, value, "a positive number")
    if math.isnan(v) or v <= 0 or (math.isinf(v) and not allow_inf):
        rng = "(0, inf]" if allow_inf else "(0, inf)"
        raise ClfzaError(f"{name} must be in {rng}, got {value!r}")
    return v


def nonnegative(name: str, value: float) -> float:
    """Return ``value`` as float if it is a real number, finite and >= 0, else raise
    ClfzaError."""
    v = _real(name, value, "a number >= 0")
    if not math.isfinite(v) or v < 0:
        raise ClfzaError(f"{name} must be in [0, inf), got {value!r}")
    return v


def in_range(name: str, value: float, lo: float, hi: float) -> float:
    """Return ``value`` as float if it is a real number with lo <= value <= hi, else raise
    ClfzaError."""
    v = _real(name, value, f"a number in [{lo}, {hi}]")
    if not (lo <= v <= hi):
        raise ClfzaError(f"{name} must be in [{lo}, {hi}], got {value!r}")
    return v


def parse_number(name: str, text: str) -> float:
    """A number from text (the command line): ``float(text)``, or ClfzaError naming
    ``name``; check the range with the validators above.

    Examples
    --------
    >>> positive("--z1", parse_number("--z1", "300"))
    300.0
    """
    try:
        return float(text)
    except (TypeError, ValueError):
        raise ClfzaError(f"{name} must be a number, got {text!r}") from None


def parse_int(name: str, text: str) -> int:
    """An integer from text (the command line): ``int(text)`` ("3.5" and "x" are errors, never
    truncated), or ClfzaError naming ``name``."""
    try:
        return int(text)
    except (TypeError, ValueError):
        raise ClfzaError(f"{name} must be an integer, got {text!r}") from None


def positive_int(name: str, value: int, minimum: int = 1) -> int:
    """Return ``value`` as int if it is an integer >= minimum, else raise ClfzaError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise ClfzaError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if value < minimum:
        raise ClfzaError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def strict_int(name: str, value) -> int:
    """An integer given as an integer: ``int``/``numpy`` integers, or a float with no
    fractional part (``64.0``); a fraction (``64.5``), a string, a bool or None is an error,
    never truncated."""
    if isinstance(value, (bool, np.bool_)) or value is None or isinstance(value, str):
        raise ClfzaError(f"{name} must be an integer, got {value!r}")
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        if math.isfinite(value) and float(value).is_integer():
            return int(value)
        raise ClfzaError(f"{name} must be an integer, got {value!r} (fractional values are "
                         "not truncated)")
    raise ClfzaError(f"{name} must be an integer, got {value!r}")


def strict_number(name: str, value) -> float:
    """A real number given as a number (not a string, bool or None)."""
    return _real(name, value, "a number")


def shape2d(name: str, shape: Sequence[int]) -> tuple[int, int]:
    """Validate a (rows, cols) shape of positive integers (fractions are errors)."""
    if isinstance(shape, (str, bytes)) or not hasattr(shape, "__len__") or len(shape) != 2:
        raise ClfzaError(f"{name} must be a pair (rows, cols) of integers, got {shape!r}")
    try:
        ny, nx = (strict_int(name, s) for s in shape)
    except ClfzaError:
        raise ClfzaError(f"{name} must be a pair (rows, cols) of integers, got {shape!r} "
                         "(fractional values are not truncated)") from None
    if ny < 2 or nx < 2:
        raise ClfzaError(f"{name} must have at least 2 rows and 2 columns, got {shape!r}")
    return ny, nx


def finite_image(name: str, arr, *, ndim: tuple[int, ...] = (2, 3)) -> np.ndarray:
    """Return ``arr`` as a float64 array after checking dtype, rank, size and finiteness.

    Accepts real integer, boolean or floating arrays of rank in ``ndim`` (rank 3 means a
    trailing channel axis). Raises ClfzaError for complex, object or string data, empty
    arrays, the wrong rank, or any NaN/Inf.
    """
    a = np.asarray(arr)
    if a.dtype.kind not in "biuf":
        raise ClfzaError(
            f"{name} must be a real numeric array (bool, int, uint or float), got dtype {a.dtype}"
        )
    if a.ndim not in ndim:
        raise ClfzaError(f"{name} must have {' or '.join(map(str, ndim))} dimensions, "
                         f"got shape {a.shape}")
    if a.size == 0:
        raise ClfzaError(f"{name} is empty (shape {a.shape})")
    a = a.astype(np.float64, copy=False)
    if not np.isfinite(a).all():
        bad = int(np.size(a) - np.count_nonzero(np.isfinite(a)))
        raise ClfzaError(f"{name} contains {bad} NaN or Inf value(s); clean the data first")
    return a


def report_exception(exc: BaseException) -> tuple[str, int]:
    """The one-line message and exit status for an exception that ends a command: a
    :class:`ClfzaError` (2), out of memory (2, with advice), an OpenCL or OS error (2), anything
    else (1, "unexpected", pointing to ``--debug``).

    Examples
    --------
    >>> report_exception(ClfzaError("tau must be > 0"))
    ('clfza: error: tau must be > 0', 2)
    """
    one = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, ClfzaError):
        return f"clfza: error: {one}", 2
    mod = type(exc).__module__ or ""
    name = type(exc).__name__
    if isinstance(exc, MemoryError) or (mod.startswith("pyopencl") and "MemoryError" in name):
        return (f"clfza: error: out of memory ({one}); use a smaller crop, bin the frame "
                "(--bin), or another device"), 2
    if mod.startswith("pyopencl"):
        return f"clfza: error: OpenCL error: {one}", 2
    if isinstance(exc, OSError):
        return f"clfza: error: {one}", 2
    return (f"clfza: error: unexpected {name}: {one} (rerun with --debug for the traceback)",
            1)
