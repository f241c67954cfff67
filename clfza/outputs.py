"""Writing results safely: atomic writes, no silent overwrites, numbered run folders."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from .errors import ClfzaError


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


def atomic_write_bytes(path: str | Path, data: bytes, force: bool = False) -> Path:
    """Write bytes to ``path`` via a temporary file and an atomic rename."""
    path = Path(path)
    _check_target(path, force)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


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


def write_json(path: str | Path, obj, force: bool = False) -> Path:
    """Atomically write ``obj`` as indented JSON (numpy scalars and arrays converted)."""
    text = json.dumps(obj, indent=2, default=_jsonable, allow_nan=True)
    return atomic_write_bytes(path, text.encode("utf-8") + b"\n", force)


def write_figure(path: str | Path, fig, force: bool = False, dpi: int = 110) -> Path:
    """Atomically save a matplotlib figure as PNG."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return atomic_write_bytes(path, buf.getvalue(), force)
