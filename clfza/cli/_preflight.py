"""``clfza reconstruct``'s checks of its outputs before the first frame is solved.

Work is never thrown away at the end for something that could be known at the start:

* ``--stack-out``: each target's suffix (and ffmpeg for MP4), no existing file without
  ``--force``, and the frames' channels from their headers (a stack needs one shape: grey
  and RGB frames cannot share it);
* ``--out`` and the stacks' folders: folders (not files), writable (the nearest existing
  folder where they are still to be made);
* free disk space: the outputs' size is estimated from the grid, the channels and the
  formats (:func:`output_bytes`) and compared with the free space of each file system.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from ..errors import ClfzaError
from ..io import STACK_FORMATS, check_stack_target, fmt_bytes, frame_channels, frame_shapes

#: bytes per sample of the saved image, by --format (the NPY adds 8, float64)
IMAGE_BYTES = {"png": 2, "tiff": 2, "tiff-float": 4}
#: bytes per sample of a stack, by kind (GIF and MP4 are 8-bit and compressed: an upper bound)
STACK_BYTES = {"tiff": 2, "gif": 1, "mp4": 1}
JSON_BYTES = 64 << 10  # a frame's JSON record, an upper bound (histories included)


def _existing_folder(p: Path) -> Path:
    """``p`` or its nearest existing ancestor (where a folder still to be made would go)."""
    p = p.absolute()
    while not p.exists() and p.parent != p:
        p = p.parent
    return p


def check_folder(path: str | Path, what: str) -> Path:
    """``path`` is a folder, or can be made: not a file, and writable (itself or the nearest
    existing folder above it); returns the existing folder its files go to."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ClfzaError(f"{what} {str(p)!r} is a file, not a folder")
    base = _existing_folder(p)
    if not base.is_dir():
        raise ClfzaError(f"{what} {str(p)!r} cannot be made: {str(base)!r} is a file")
    if not os.access(base, os.W_OK | os.X_OK):
        made = "" if base == p.absolute() else f" (to make {str(p)!r} in)"
        raise ClfzaError(f"{what}: no permission to write to {str(base)!r}{made}")
    return base


def stack_shape_problem(refs, shapes, bayer: bool) -> str | None:
    """Why these frames cannot share one stack (grey and colour mixed), or None."""
    chans = [3 if (bayer and s is not None) else frame_channels(s) for s in shapes]
    groups: dict[int, list[str]] = {}
    for r, c in zip(refs, chans, strict=True):
        if c is not None:
            groups.setdefault(c, []).append(r.label)
    if len(groups) < 2:
        return None
    parts = []
    for c, labels in sorted(groups.items()):
        more = f" and {len(labels) - 2} more" if len(labels) > 2 else ""
        parts.append(f"{len(labels)} {'grey' if c == 1 else 'RGB'} ({', '.join(labels[:2])}"
                     f"{more})")
    return (f"the frames mix grey and colour: {'; '.join(parts)}; a stack needs one shape, so "
            "their reconstructions cannot share it")


def output_bytes(n_frames: int, grid, channels: list[int], fmt: str,
                 stacks: list[str]) -> tuple[float, float]:
    """Estimated bytes of the frames' outputs (image, NPY, JSON each) and of the stacks."""
    px = int(grid[0]) * int(grid[1])
    samples = sum(px * c for c in channels) + px * (n_frames - len(channels))
    frames = samples * (IMAGE_BYTES.get(fmt, 4) + 8) + n_frames * JSON_BYTES
    st = sum(samples * STACK_BYTES[STACK_FORMATS.get(Path(s).suffix.lower(), "tiff")]
             for s in stacks)
    return float(frames), float(st)


def _free(folder: Path) -> tuple[int, float]:
    """(device id, free bytes) of the file system holding ``folder``."""
    try:
        return os.stat(folder).st_dev, float(shutil.disk_usage(folder).free)
    except OSError:  # cannot tell: do not refuse
        return -1, float("inf")


def check_disk(needs: list[tuple[Path, float, str]]) -> None:
    """``needs``: (existing folder, bytes, what) per output; refuse when a file system has
    less free space than the outputs it will hold (estimated)."""
    per_dev: dict[int, list] = {}
    for folder, nbytes, what in needs:
        dev, free = _free(folder)
        entry = per_dev.setdefault(dev, [0.0, free, folder, []])
        entry[0] += nbytes
        entry[3].append(what)
    for total, free, folder, whats in per_dev.values():
        if total > free:
            raise ClfzaError(f"the outputs ({', '.join(whats)}) need about {fmt_bytes(total)} "
                             f"of disk, more than the {fmt_bytes(free)} free on "
                             f"{str(folder)!r}; free space, write elsewhere (--out), or make "
                             "the outputs smaller (--roi, --bin, --format png)")


def check_outputs(args, refs, grid) -> None:
    """Every check of ``clfza reconstruct``'s outputs before the first frame is solved (see
    the module's docstring). ``grid``: the reconstruction's (H, W) after --roi."""
    out_base = check_folder(args.out, "--out")
    stacks = list(getattr(args, "stack_out", []) or [])
    seen: set = set()
    needs: list[tuple[Path, float, str]] = []
    shapes = frame_shapes(refs)
    for target in stacks:
        check_stack_target(target, force=args.force)
        key = Path(target).absolute()
        if key in seen:
            raise ClfzaError(f"--stack-out {target!r} is given twice")
        seen.add(key)
        check_folder(Path(target).parent if str(Path(target).parent) else ".",
                     f"--stack-out {target!r}: its folder")
    if stacks:
        why = stack_shape_problem(refs, shapes, bool(args.bayer))
        if why is not None:
            raise ClfzaError(f"--stack-out {stacks[0]!r}: {why}; reconstruct them separately "
                             "or drop --stack-out (nothing was solved)")
    chans = [3 if args.bayer else (frame_channels(s) or 1) for s in shapes]
    fmt = getattr(args, "format", "png")
    frames_b, _ = output_bytes(len(refs), grid, chans, fmt, [])
    needs.append((out_base, frames_b, f"{len(refs)} frame(s) into {str(args.out)!r}"))
    for target in stacks:
        _, sb = output_bytes(len(refs), grid, chans, fmt, [target])
        needs.append((_existing_folder(Path(target).parent), sb, f"stack {target!r}"))
    check_disk(needs)
