"""Frame streams: folders, globs, multi-page TIFFs, ``.npy``/``.npz`` stacks and videos.

:func:`expand_frames` turns what a user names on the command line into an ordered list of
:class:`FrameRef` -- small, picklable references (a path and an index), so that a distributed
batch sends paths to its workers, not pixels. :func:`read_ref` reads one referenced frame
(on a worker) and validates it with :func:`clfza.io.check_frame`.

Inputs
    * a frame file (``.png``, ``.tif``/``.tiff``, ``.npy``) -- one frame, or a stack: a TIFF
      with several pages, an ``.npy`` array of shape ``(N, H, W)`` or ``(N, H, W, 3)`` (a
      3-D array whose last axis is 1, 3 or 4, or shorter than both others, is one frame);
    * an ``.npz`` archive: every array in it, in the archive's order (a 3-D or 4-D array is
      a stack as above);
    * a video or animation (``.mp4``, ``.avi``, ``.mov``, ``.mkv``, ``.webm``, ``.gif``)
      through imageio; all but GIF need its ffmpeg plugin (``pip install imageio-ffmpeg``,
      which ships an ffmpeg binary). Video frames whose colour channels agree within 1 DN
      (a grey sensor stored as a video) are read as grey;
    * a folder (its frame, stack and video files, in natural order: ``f2`` before ``f10``),
      without clfza's own outputs: the files its JSON records there name as results (a
      reconstruction's image and NPY, a simulation's truth, a batch's stacks) and a
      simulation's ``NAME-truth.npy``/``.png`` beside ``NAME-raw.*``; the log says, in one
      line, what was taken and what was skipped (:func:`folder_frames`);
    * a glob pattern (sorted the same way).

Stacks write :func:`write_stack`: a multi-page TIFF, a GIF or an MP4 of reconstructions.
"""

from __future__ import annotations

import glob
import io
import json
import logging
import math
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import tifffile

from ..errors import ClfzaError
from ._headers import gif_header, npy_header, one_line, tiff_header
from ._limits import pixel_limit
from ._outputs import atomic_write_bytes
from ._read import (
    FRAME_SUFFIXES,
    MIN_SIDE,
    FrameInfo,
    check_frame,
    check_layout_memory,
    frame_layout,
    read_frame,
)

log = logging.getLogger("clfza")

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".gif")
STACK_SUFFIXES = (".npz",)
ALL_SUFFIXES = tuple(FRAME_SUFFIXES) + STACK_SUFFIXES + VIDEO_SUFFIXES
FFMPEG_HINT = "install imageio's ffmpeg plugin: pip install imageio-ffmpeg"


@dataclass(frozen=True)
class FrameRef:
    """One frame of an input: a file, or one page/array/frame inside a container.

    Attributes
    ----------
    path : str
        The file.
    index : int or None
        Page (TIFF), leading index (``.npy``/``.npz`` stack) or frame number (video);
        None when the file is one frame.
    key : str or None
        The array's name inside an ``.npz`` archive.
    name : str
        The output stem (unique within a batch; :func:`unique_names`).
    """

    path: str
    index: int | None = None
    key: str | None = None
    name: str = ""

    @property
    def label(self) -> str:
        """How messages name the frame: ``'a.tif'``, ``'a.tif'[3]``, ``'a.npz'[y][3]``."""
        s = repr(self.path)
        if self.key is not None:
            s += f"[{self.key}]"
        if self.index is not None:
            s += f"[{self.index}]"
        return s


def natural_key(path: str | Path) -> list:
    """Sort key that orders ``frame2`` before ``frame10``."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", str(path))]


# ----------------------------------------------------------------------------------------
# expansion (client side: headers only, no pixels)
# ----------------------------------------------------------------------------------------
def _npy_shape(p: Path) -> tuple[int, ...]:
    try:
        return tuple(np.load(p, mmap_mode="r", allow_pickle=False).shape)
    except Exception:  # a corrupt file: one frame, whose read names the problem
        return ()


def _npz_members(p: Path) -> list[tuple[str, tuple[int, ...], bool]]:
    """(name, shape, whole) of each array in an ``.npz`` archive, from the headers only;
    ``whole`` is False where the header declares more data than the member holds (a
    corrupt or crafted member: its read names the problem)."""
    out = []
    try:
        with zipfile.ZipFile(p) as zf:
            for info in zf.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with zf.open(info) as fh:
                    shape, dtype, _, offset = npy_header(fh)
                nbytes = math.prod(shape) * dtype.itemsize
                out.append((info.filename[:-4], shape, offset + nbytes <= info.file_size))
    except Exception as exc:  # zipfile raises many kinds (zlib.error, EOFError, ...)
        raise ClfzaError(f"cannot read NPZ {str(p)!r}: the archive is corrupt "
                         f"({one_line(exc)})") from None
    if not out:
        raise ClfzaError(f"NPZ {str(p)!r} holds no arrays")
    return out


def _stack_len(shape: tuple[int, ...]) -> int | None:
    """Frames in an array of ``shape``: None for one frame (H, W) or (H, W, C). A 3-D array
    is a stack ``(N, H, W)`` only where its last axis is no channel axis: not 1, 3 or 4, and
    not shorter than both other axes (``(64, 64, 5)`` is a 5-channel frame, reported as such,
    not 64 frames of 64 x 5 pixels; ``(200, 64, 64)`` is 200 frames). Frames narrower than
    both their height and their count are read as one frame: save such a stack as
    ``(N, H, W, 1)``."""
    if len(shape) == 4 or (len(shape) == 3 and shape[2] not in (1, 3, 4)
                           and shape[2] >= min(shape[0], shape[1])):
        return int(shape[0])
    return None


def video_length(p: str | Path) -> int:
    """Number of frames of a video or GIF (ffmpeg counts them; an error names the plugin)."""
    p = Path(p)
    if p.suffix.lower() == ".gif":
        _check_gif(p)  # counting decodes every frame: the canvas is bounded first
        try:
            return int(iio.improps(p, index=None).shape[0])
        except Exception as exc:
            raise ClfzaError(f"cannot read GIF {str(p)!r}: {one_line(exc)}") from None
    reader = _video_reader(p)
    try:
        return int(reader.count_frames())
    except Exception as exc:
        raise ClfzaError(f"cannot count the frames of video {str(p)!r}: {one_line(exc)}") \
            from None
    finally:
        reader.close()


def _check_gif(p: Path, label: str | None = None) -> None:
    """Refuse a GIF whose canvas (the screen, grown to every frame's extent: what Pillow
    allocates for each frame) exceeds ``CLFZA_MAX_PIXELS`` or the memory, from its headers,
    before Pillow decodes a frame (Pillow's own limit is 179 Mpixel whatever clfza's);
    a GIF whose headers cannot be walked is left to the decoder, which names the problem."""
    try:
        _, (h, w) = gif_header(p)
    except (ValueError, OSError):
        return
    check_layout_memory(label or repr(str(p)), (h, w, 4), 1)


def _require_ffmpeg(doing: str) -> None:
    """Raise :class:`ClfzaError` naming the install when imageio's ffmpeg plugin is missing."""
    try:
        import imageio_ffmpeg  # noqa: F401  # lazy: video support is optional (clfza[video])
    except ImportError:
        raise ClfzaError(f"{doing} needs ffmpeg; {FFMPEG_HINT}") from None


def _video_reader(p: Path):
    _require_ffmpeg(f"reading video {str(p)!r}")
    import imageio.v2 as iio2  # lazy: video support is optional (pip install "clfza[video]")

    try:
        return iio2.get_reader(p, format="FFMPEG")
    except Exception as exc:
        raise ClfzaError(f"cannot open video {str(p)!r}: {one_line(exc)}") from None


def _frames_of_stack(shape: tuple[int, ...], inflated_whole: bool = False) -> int | None:
    """:func:`_stack_len`, but None (one reference, whose read names the problem) for a
    stack whose frames are all too small to be read (fewer than ``MIN_SIDE`` pixels a side),
    or, with ``inflated_whole`` (an ``.npz`` member, inflated whole to take one frame), one
    larger than ``CLFZA_MAX_PIXELS``: no list of references longer than the data allow."""
    n = _stack_len(shape)
    if n is None:
        return None
    if min(int(shape[1]), int(shape[2])) < MIN_SIDE:
        return None
    if inflated_whole and n * int(shape[1]) * int(shape[2]) > pixel_limit()[0]:
        return None
    return n


def refs_of_file(p: Path) -> list[FrameRef]:
    """The frames of one file (one ref for a plain frame; one per page/array/frame)."""
    suf = p.suffix.lower()
    sp = str(p)
    if suf == ".npz":
        refs = []
        for key, shape, whole in _npz_members(p):
            n = _frames_of_stack(shape, inflated_whole=True) if whole else None
            refs += ([FrameRef(sp, None, key)] if n is None
                     else [FrameRef(sp, i, key) for i in range(n)])
        return refs
    if suf in VIDEO_SUFFIXES:
        if suf == ".gif":
            try:
                _check_gif(p)
            except ClfzaError:  # counting would decode it: one frame, whose read says why
                return [FrameRef(sp, 0)]
        return [FrameRef(sp, i) for i in range(video_length(p))]
    if suf == ".npy" and p.is_file():
        n = _frames_of_stack(_npy_shape(p))
        return [FrameRef(sp)] if n is None else [FrameRef(sp, i) for i in range(n)]
    if suf in (".tif", ".tiff") and p.is_file():
        try:
            n, _, _ = tiff_header(p)
        except Exception:  # corrupt: one frame, whose read names the problem
            n = 1
        return [FrameRef(sp)] if n <= 1 else [FrameRef(sp, i) for i in range(n)]
    return [FrameRef(sp)]


#: the ``outputs`` of clfza's own JSON records that are frames a folder read takes: a
#: simulation's raw frame (every other output -- its truth, a reconstruction's image and NPY,
#: a batch's stacks -- is a result, not a frame)
FRAME_OUTPUTS = ("raw",)
#: names of clfza's own outputs when no record names them: a simulation's ground truth
#: (``NAME-truth.npy``/``.png``, written to ``truth/`` since issue 35, beside the raw frame
#: before) next to ``NAME-raw.*``
_TRUTH_NAME = re.compile(r"^(?P<stem>.+)-truth(-\d+)?\.(npy|png)$", re.IGNORECASE)
MAX_LISTED = 8  # file names a folder read's log line lists, each of taken and skipped


def _record_outputs(folder: Path) -> dict[str, str]:
    """File names in ``folder`` that clfza's own JSON records there name as results (not
    frames), each with the record that names it: a simulation's truth, a reconstruction's
    image and NPY, a batch's stacks. An output counts when its file name matches and its
    folder is this one (as written, relative or absolute)."""
    outs: dict[str, str] = {}
    for js in folder.glob("*.json"):
        try:
            if js.stat().st_size > (4 << 20):  # no clfza record is this large
                continue
            rec = json.loads(js.read_text(encoding="utf-8"))
        except (OSError, ValueError, UnicodeDecodeError):
            continue
        if not isinstance(rec, dict) or "clfza_version" not in rec:
            continue
        paths: list[str] = []
        o = rec.get("outputs")
        if isinstance(o, dict):
            paths += [str(v) for k, v in o.items() if k not in FRAME_OUTPUTS
                      and isinstance(v, str)]
        elif isinstance(o, list):  # a batch summary: one dict of outputs per frame
            paths += [str(v) for d in o if isinstance(d, dict)
                      for k, v in d.items() if k != "input" and isinstance(v, str)]
        stacks = rec.get("stacks")
        if isinstance(stacks, list):
            paths += [str(v) for v in stacks if isinstance(v, str)]
        for v in paths:
            q = Path(v)
            if q.parent == Path(".") or q.parent.name == folder.name or (
                    q.is_absolute() and q.parent == folder.absolute()):
                outs.setdefault(q.name, js.name)
    return outs


def _own_output(f: Path, recorded: dict[str, str], names: set[str]) -> str | None:
    """Why ``f`` is one of clfza's own outputs (a record names it, or it is a simulation's
    truth beside its raw frame), or None for a frame."""
    if f.name in recorded:
        return f"an output of {recorded[f.name]}"
    m = _TRUTH_NAME.match(f.name)
    if m and any(n.startswith(f"{m['stem']}-raw.") or n == f"{m['stem']}.json"
                 for n in names):
        return "a simulation's ground truth"
    return None


def _listing(names: list[str]) -> str:
    head = ", ".join(names[:MAX_LISTED])
    return head + (f" and {len(names) - MAX_LISTED} more" if len(names) > MAX_LISTED else "")


def folder_frames(folder: Path) -> tuple[list[Path], list[tuple[Path, str]]]:
    """The frame, stack and video files of ``folder`` in natural order, and the files
    skipped with the reason: clfza's own outputs (named by its JSON records there, or a
    simulation's ``-truth`` files beside their raw frame). Hidden files, subfolders and
    other suffixes are not candidates. Logs one line: what was taken, what was skipped."""
    cands = sorted((f for f in folder.iterdir()
                    if f.is_file() and f.suffix.lower() in ALL_SUFFIXES
                    and not f.name.startswith(".")), key=natural_key)
    recorded = _record_outputs(folder)
    names = {f.name for f in folder.iterdir()}
    taken: list[Path] = []
    skipped: list[tuple[Path, str]] = []
    for f in cands:
        why = _own_output(f, recorded, names)
        if why is None:
            taken.append(f)
        else:
            skipped.append((f, why))
    line = (f"folder {str(folder)!r}: took {len(taken)} file(s)"
            + (f" ({_listing([f.name for f in taken])})" if taken else ""))
    if skipped:
        reasons = sorted({w for _, w in skipped})
        line += (f"; skipped {len(skipped)} of clfza's own output(s) "
                 f"({_listing([f.name for f, _ in skipped])}: {'; '.join(reasons[:3])}"
                 f"{'; ...' if len(reasons) > 3 else ''})")
    # skipped files are said by default (a folder that held them would surprise otherwise)
    (log.warning if skipped else log.info)("%s", line)
    return taken, skipped


def _files_of(pattern: str) -> tuple[list[Path], str | None]:
    p = Path(pattern)
    if p.is_dir():
        files, skipped = folder_frames(p)
        if files:
            return files, None
        return files, ("the folder holds only clfza's own outputs, no frame, stack or video "
                       "files" if skipped else "the folder holds no frame, stack or video files")
    if p.exists() or not any(c in pattern for c in "*?["):
        return [p], None
    hits = sorted(glob.glob(pattern, recursive=True), key=natural_key)
    return [Path(h) for h in hits], None if hits else "the pattern matches no file"


def expand_frames(inputs: list[str | Path]) -> tuple[list[FrameRef], list[tuple[str, str]]]:
    """Expand files, folders, globs, stacks and videos into named frame references.

    Returns
    -------
    (refs, missing)
        ``refs`` in input order with unique output names; ``missing``: ``(input, reason)``
        for inputs that give no frames (an empty folder, a pattern that matches nothing).
        A file that does not exist is kept as a ref, so that the batch names it.
    """
    refs: list[FrameRef] = []
    missing: list[tuple[str, str]] = []
    seen: set = set()
    for item in inputs:
        files, why = _files_of(str(item))
        if why is not None:
            missing.append((str(item), why))
        for f in files:
            key = f.resolve() if f.exists() else f
            if key in seen:
                continue
            seen.add(key)
            refs.extend(refs_of_file(f))
    return unique_names(refs), missing


def unique_names(refs: list[FrameRef]) -> list[FrameRef]:
    """Give every ref an output stem: ``stem``, ``stem-0003`` inside stacks, ``-2`` on clashes."""
    counts: dict[tuple[str, str | None], int] = {}
    for r in refs:
        counts[(r.path, r.key)] = counts.get((r.path, r.key), 0) + 1
    used: dict[str, int] = {}
    out = []
    for r in refs:
        stem = Path(r.path).stem or "frame"
        if r.key is not None:
            stem += f"-{r.key}"
        if r.index is not None:
            width = max(4, len(str(counts[(r.path, r.key)] - 1)))
            stem += f"-{r.index:0{width}d}"
        n = used.get(stem, 0) + 1
        used[stem] = n
        out.append(FrameRef(r.path, r.index, r.key, stem if n == 1 else f"{stem}-{n}"))
    return out


def _channels_last(shape: tuple[int, ...]) -> tuple[int, ...]:
    """A stored frame shape as read: planar ``(3, H, W)`` becomes ``(H, W, 3)``."""
    if len(shape) == 3 and shape[0] in (3, 4) and shape[-1] not in (3, 4):
        return (shape[1], shape[2], shape[0])
    return shape


def _file_frame_shape(p: Path, ref: FrameRef,
                      archives: dict | None = None) -> tuple[int, ...] | None:
    """The shape one frame of ``p`` has as stored, from the headers alone (None: unknown,
    e.g. a video, whose grey or colour frames show only when decoded). ``archives`` keeps
    each ``.npz`` archive's member shapes, read once for all its members."""
    suf = p.suffix.lower()
    try:
        if suf == ".npz":
            archives = {} if archives is None else archives
            if str(p) not in archives:
                archives[str(p)] = {}  # a corrupt archive is tried once, not per member
                archives[str(p)] = {key: shape for key, shape, _ in _npz_members(p)}
            shape = archives[str(p)].get(ref.key)
            if shape is None:
                return None
            return shape[1:] if ref.index is not None else shape
        if suf == ".npy":
            shape, _, _, _ = npy_header(p)
            return shape[1:] if ref.index is not None else shape
        if suf in (".tif", ".tiff"):
            _, shape, _ = tiff_header(p)  # the first page stands for every page
            return shape
        if suf in FRAME_SUFFIXES:
            lay = frame_layout(p)
            return None if lay is None else lay[0]
    except Exception:  # corrupt or unreadable: the frame's own read names the problem
        return None
    return None


def frame_shapes(refs: list[FrameRef]) -> list[tuple[int, ...] | None]:
    """Each frame's shape as it will be read -- ``(H, W)`` or ``(H, W, C)``, channels last --
    from the file headers alone (nothing is decoded; one header read per file and member:
    an archive's member headers are read once for all its members), or None where the
    header does not tell (a video, a missing or corrupt file)."""
    cache: dict = {}
    archives: dict = {}
    out: list[tuple[int, ...] | None] = []
    for r in refs:
        k = (r.path, r.key, r.index is None)
        if k not in cache:
            shape = _file_frame_shape(Path(r.path), r, archives)
            cache[k] = None if shape is None else _channels_last(tuple(int(v) for v in shape))
        out.append(cache[k])
    return out


def frame_channels(shape: tuple[int, ...] | None) -> int | None:
    """Colour channels a frame of ``shape`` gives after validation (grey 1, RGB/RGBA 3; an
    alpha channel is dropped), or None when unknown."""
    if shape is None:
        return None
    if len(shape) == 2 or (len(shape) == 3 and shape[2] == 1):
        return 1
    if len(shape) == 3 and shape[2] in (3, 4):
        return 3
    return None


# ----------------------------------------------------------------------------------------
# reading (worker side)
# ----------------------------------------------------------------------------------------
def _npz_layout(p: Path, key: str | None) -> tuple[tuple[int, ...], int] | None:
    """Shape and item size of one array of an ``.npz`` archive from its header."""
    try:
        with zipfile.ZipFile(p) as zf, zf.open(f"{key}.npy") as fh:
            shape, dtype, _, _ = npy_header(fh)
        return shape, int(dtype.itemsize)
    except Exception:  # corrupt: the read below names the problem
        return None


def _check_ref_memory(ref: FrameRef, shape, itemsize: int, decoder: float = 0.0) -> None:

    check_layout_memory(ref.label, tuple(int(v) for v in shape), int(itemsize), decoder)


def _read_raw(ref: FrameRef) -> tuple[np.ndarray, str]:
    """One referenced frame as stored; its declared size is checked against the memory
    limit (:mod:`clfza.io._limits`) before anything is decoded."""
    p = Path(ref.path)
    suf = p.suffix.lower()
    if not p.exists():
        raise ClfzaError(f"{ref.label} does not exist")
    if suf == ".npz":
        lay = _npz_layout(p, ref.key)
        if lay is not None:  # the whole member is inflated to take one frame of it
            _check_ref_memory(ref, *lay)
        with np.load(p, allow_pickle=False) as z:
            if ref.key not in z.files:
                raise ClfzaError(f"{ref.label}: no array {ref.key!r} in the archive")
            a = z[ref.key]
        return (a if ref.index is None else a[ref.index]), "npz"
    if suf == ".npy":

        lay = frame_layout(p)  # the header, before the file is mapped
        if lay is not None:
            _check_ref_memory(ref, lay[0][1:] if ref.index is not None else lay[0], lay[1])
        return np.array(np.load(p, mmap_mode="r", allow_pickle=False)[ref.index]), "npy"
    if suf in (".tif", ".tiff"):

        with tifffile.TiffFile(p) as tf:
            page = tf.pages[ref.index]
            _check_ref_memory(ref, page.shape, page.dtype.itemsize, page.dtype.itemsize)
            return page.asarray(), "tiff"
    if suf == ".gif":
        _check_gif(p, ref.label)  # the canvas Pillow decodes into, from the headers
        props = iio.improps(p, index=ref.index)  # the frame's size
        _check_ref_memory(ref, props.shape, 1)  # CLFZA_MAX_PIXELS, then the memory
        return _grey_if_equal(np.asarray(iio.imread(p, index=ref.index))), "gif"
    if suf in VIDEO_SUFFIXES:
        reader = _video_reader(p)
        try:
            size = reader.get_meta_data().get("size")  # (width, height), from the header
            if size:  # CLFZA_MAX_PIXELS, then the memory, before the frame is decoded
                _check_ref_memory(ref, (int(size[1]), int(size[0]), 3), 1)
            return _grey_if_equal(np.asarray(reader.get_data(ref.index))), "video"
        finally:
            reader.close()
    raise ClfzaError(f"{ref.label}: {p.suffix!r} files hold one frame, not a stack")


def _grey_if_equal(a: np.ndarray) -> np.ndarray:
    """An RGB(A) video frame whose channels agree within 1 DN, as grey."""
    if a.ndim == 3 and a.shape[2] in (3, 4):
        c = a[..., :3].astype(np.int32)
        if np.abs(c - c[..., :1]).max() <= 1:
            return np.round(c.mean(axis=2)).astype(a.dtype)
        return a[..., :3]
    return a


def read_ref(ref: FrameRef) -> tuple[np.ndarray, FrameInfo]:
    """Read and validate one referenced frame: float64 ``(H, W)``/``(H, W, 3)`` and its info.

    Raises
    ------
    ClfzaError
        One sentence naming the frame (``'a.tif'[3]``) for a missing, corrupt or invalid one.
    """
    if ref.index is None and ref.key is None:
        return read_frame(ref.path)
    try:
        raw, fmt = _read_raw(ref)
    except ClfzaError:
        raise
    except IndexError:
        raise ClfzaError(f"{ref.label} is past the end of the stack") from None
    except Exception as exc:  # corrupt containers raise many kinds
        raise ClfzaError(f"cannot read {ref.label}: the file is corrupt or truncated "
                         f"({one_line(exc)})") from None
    frame, bits = check_frame(raw, name=ref.label)
    info = FrameInfo(path=ref.label, format=fmt, dtype=str(raw.dtype), shape=tuple(raw.shape),
                     bit_depth=bits)
    return frame, info


# ----------------------------------------------------------------------------------------
# writing stacks of results
# ----------------------------------------------------------------------------------------
STACK_FORMATS = {".tif": "tiff", ".tiff": "tiff", ".gif": "gif", ".mp4": "mp4"}


def check_stack_target(path: str | Path, force: bool = False) -> str:
    """Check a stack output before any frame is solved: its suffix, ffmpeg for MP4, no
    existing file without ``force``; returns its kind (``"tiff"``, ``"gif"``, ``"mp4"``)."""
    p = Path(path)
    kind = STACK_FORMATS.get(p.suffix.lower())
    if kind is None:
        raise ClfzaError(f"cannot write a stack to {str(p)!r}: use .tif, .gif or .mp4")
    if kind == "mp4":
        _require_ffmpeg(f"writing {str(p)!r}")
    if p.is_dir():
        raise ClfzaError(f"stack output {str(p)!r} is a folder")
    if p.exists() and not force:
        raise ClfzaError(f"{str(p)!r} exists; pass --force (force=True) to overwrite it")
    return kind


def write_stack(path: str | Path, images: list[np.ndarray], *, force: bool = False,
                fps: float = 10.0) -> Path:
    """Write reconstructions as a multi-page 16-bit TIFF, a GIF or an MP4 (8-bit).

    Each frame is scaled by the same 0.1-99.9 percentile range of the whole stack, so that
    brightness changes between frames stay visible. Atomic; never over an existing file
    unless ``force``.
    """

    p = Path(path)
    kind = STACK_FORMATS.get(p.suffix.lower())
    if kind is None:
        raise ClfzaError(f"cannot write a stack to {str(p)!r}: use .tif, .gif or .mp4")
    if not images:
        raise ClfzaError("no reconstructions to write as a stack")
    shapes = {np.shape(a) for a in images}
    if len(shapes) > 1:
        raise ClfzaError(f"the reconstructions have different shapes {sorted(shapes)}; a stack "
                         "needs one shape")
    a = np.stack([np.asarray(x, np.float64) for x in images])
    lo, hi = np.percentile(a, [0.1, 99.9])
    u = np.clip((a - lo) / (hi - lo if hi > lo else 1.0), 0.0, 1.0)
    if kind == "tiff":


        buf = io.BytesIO()
        photometric = "rgb" if u.ndim == 4 else "minisblack"
        tifffile.imwrite(buf, np.round(u * 65535).astype(np.uint16), photometric=photometric)
        return atomic_write_bytes(p, buf.getvalue(), force)
    return _write_animation(p, np.round(u * 255).astype(np.uint8), kind, force, fps)


def _write_animation(p: Path, u8: np.ndarray, kind: str, force: bool, fps: float) -> Path:


    if kind == "mp4":
        _require_ffmpeg(f"writing {str(p)!r}")
        pad = [(0, 0), (0, u8.shape[1] % 2), (0, u8.shape[2] % 2)] + [(0, 0)] * (u8.ndim - 3)
        u8 = np.pad(u8, pad, mode="edge")  # yuv420 needs even sides
        data = iio.imwrite("<bytes>", u8, extension=".mp4", fps=fps)
    else:
        data = iio.imwrite("<bytes>", u8, extension=".gif", duration=1000.0 / fps, loop=0)
    return atomic_write_bytes(p, data, force)
