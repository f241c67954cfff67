"""Writing results safely: atomic writes, no silent overwrites, numbered run folders."""

from __future__ import annotations

import io
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from ..errors import ClfzaError


def new_run_dir(base: str | Path, stem: str) -> Path:
    """Create and return ``base/stem-NNN`` with the next free number (never reuses one)."""
    base = Path(base)
    base.mkdir(parents=True, exist_ok=True)
    n = 1
    while True:
        d = base / f"{stem}-{n:03d}"
        try:
            d.mkdir()
            return d
        except FileExistsError:
            n += 1


def _check_target(path: Path, force: bool) -> None:
    if path.exists() and not force:
        raise ClfzaError(f"{str(path)!r} exists; pass --force (force=True) to overwrite it")
    if not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)


def current_umask() -> int:
    """The process's umask, read without changing it where the system says (Linux
    ``/proc/self/status``); elsewhere set and restored at once."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _file_mode(path: Path) -> int:
    """Permissions of a new output: ``0666 & ~umask`` as ``open()`` gives other tools'
    files; an overwritten file (``--force``) keeps its own mode."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        return 0o666 & ~current_umask()


def _write_temp(path: Path, data: bytes) -> str:
    """``data`` in a temporary file next to ``path`` with the output's final permissions
    (``mkstemp`` creates 0600)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, _file_mode(path))
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return tmp


def atomic_write_bytes(path: str | Path, data: bytes, force: bool = False) -> Path:
    """Write bytes to ``path`` via a temporary file and an atomic rename (permissions from
    the umask, like any other tool's output)."""
    path = Path(path)
    _check_target(path, force)
    tmp = _write_temp(path, data)
    try:
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_many(items, force: bool = False) -> list[Path]:
    """Write a whole record -- several files -- or nothing.

    ``items``: ``(path, bytes)`` pairs, in the order they are published (put the file that
    marks the record complete, the JSON, last). Every target is checked first (no overwrite
    without ``force``), every file is written to a temporary name, and only then are they
    renamed; if anything fails, the temporaries and the files already renamed are removed
    (an overwritten file cannot be restored, so with ``force`` a failure leaves the target
    absent rather than half old and half new). No file is ever left under an output name
    unless the whole record was written.
    """
    pairs = [(Path(p), bytes(d)) for p, d in items]
    names = [p.resolve() if p.exists() else p.absolute() for p, _ in pairs]
    if len(set(names)) != len(names):
        raise ClfzaError("two outputs of one record have the same file name")
    for p, _ in pairs:
        _check_target(p, force)
    temps: list[str] = []
    done: list[Path] = []
    try:
        for p, d in pairs:
            temps.append(_write_temp(p, d))
        for (p, _), tmp in zip(pairs, temps, strict=True):
            os.replace(tmp, p)
            done.append(p)
    except BaseException:
        for tmp in temps:
            if os.path.exists(tmp):
                os.unlink(tmp)
        for p in done:
            try:
                p.unlink()
            except OSError:
                pass
        raise
    return [p for p, _ in pairs]


def _jsonable(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    if hasattr(o, "to_dict"):
        return o.to_dict()
    return str(o)


def encode_json(obj) -> bytes:
    """``obj`` as indented JSON bytes (numpy scalars and arrays converted)."""
    text = json.dumps(obj, indent=2, default=_jsonable, allow_nan=True)
    return text.encode("utf-8") + b"\n"


def write_json(path: str | Path, obj, force: bool = False) -> Path:
    """Atomically write ``obj`` as indented JSON (numpy scalars and arrays converted)."""
    return atomic_write_bytes(path, encode_json(obj), force)


def write_figure(path: str | Path, fig, force: bool = False, dpi: int = 110) -> Path:
    """Atomically save a matplotlib figure as PNG."""

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return atomic_write_bytes(path, buf.getvalue(), force)
