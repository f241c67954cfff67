"""Raw frames in, images out: reading, validation, calibration, cropping and writing.

The work lives in private modules by job; this one re-exports their names, so ``clfza.io.X``
keeps working for each of them (and ``monkeypatch.setattr(clfza.io, ...)`` reaches every
caller that looks the name up here).

Reading (:mod:`clfza.io._read`)
    :func:`read_frame` reads PNG (imageio; 16-bit colour PNGs, which Pillow truncates to 8
    bits, with a small decoder here), TIFF (tifffile) and NPY files, 8/16-bit unsigned
    integer or floating point, grey ``(H, W)`` or colour ``(H, W, 3)``; anything else (a
    corrupt file, an unknown suffix, 1/32-bit or signed integers, NaN/Inf, an empty or
    wrongly shaped array) raises :class:`~clfza.errors.ClfzaError` with one sentence.
    Frames stay in the sensor's own units (digital numbers); nothing is rescaled, so dark and
    flat frames from the same sensor apply directly.

Calibration and geometry (:mod:`clfza.io._calibrate`)
    :func:`subtract_dark`, :func:`flat_field`, :func:`demosaic` (2x2 superpixel binning of a
    Bayer mosaic) and :func:`center_crop` (the paper crops the 4656 x 3522 frame to 2048^2
    around its centre).

The observation (:mod:`clfza.io._calibrate`)
    :func:`frame_to_measurement` turns a raw frame into the DC-free observation ``y`` in the
    units of the operator ``K`` (see its docstring for the gain calibration).

Headers (:mod:`clfza.io._headers`)
    :func:`npy_header`, :func:`tiff_header` and :func:`gif_header` give an array's layout
    without decoding it;
    :func:`tiff_pages` decodes a TIFF stack page by page; :func:`one_line` folds a caught
    exception's message for a :class:`~clfza.errors.ClfzaError`.

Records (:mod:`clfza.io._records`)
    :data:`RECORD_SCHEMAS`: every JSON record clfza writes (a frame, a batch, a simulation,
    a focus search, a sweep), documented field by field as JSON Schema;
    :func:`validate_record` checks one; ``docs/records.md`` is :func:`records_markdown`.

Writing (:mod:`clfza.io._write`)
    :func:`write_image` (16-bit PNG, 16-bit or float32 TIFF, float NPY) through
    :mod:`clfza.io._outputs`: atomic, and never over an existing file unless ``force``.
"""

from __future__ import annotations

from ._calibrate import (
    BAYER_PATTERNS,
    HUGE_VALUE,
    center_crop,
    demosaic,
    effective_pixels,
    flat_field,
    frame_to_measurement,
    parse_pair,
    subtract_dark,
)
from ._headers import gif_header, npy_header, one_line, tiff_header, tiff_pages
from ._limits import (
    ENV as LIMIT_ENV,
)
from ._limits import (
    PIXELS_ENV,
    check_memory,
    check_reconstruct,
    check_values,
    fmt_bytes,
    grid_bytes,
    pixel_limit,
)
from ._outputs import (
    atomic_write_bytes,
    atomic_write_many,
    encode_json,
    new_run_dir,
    write_figure,
    write_json,
)
from ._prepare import (
    Prepared,
    bin_crop_note,
    bin_factor,
    load_calibration_frame,
    prepare_frame,
    warn_ignored,
)
from ._read import (
    FRAME_SUFFIXES,
    MIN_SIDE,
    PNG16_DECODER_BYTES,
    ZLIB_MAX_RATIO,
    FrameInfo,
    check_frame,
    check_layout_memory,
    frame_layout,
    read_frame,
    read_scene,
)
from ._records import RECORD_SCHEMAS, records_markdown, validate_record
from ._stream import (
    STACK_FORMATS,
    STACK_SUFFIXES,
    VIDEO_SUFFIXES,
    FrameRef,
    check_stack_target,
    expand_frames,
    folder_frames,
    frame_channels,
    frame_shapes,
    read_ref,
    refs_of_file,
    unique_names,
    write_stack,
)
from ._write import (
    SCALINGS,
    check_output_options,
    encode_array,
    encode_image,
    encode_npy,
    encode_png,
    encode_tiff,
    scale_to_uint16,
    write_array,
    write_image,
)

__all__ = [
    "BAYER_PATTERNS",
    "FRAME_SUFFIXES",
    "FrameInfo",
    "FrameRef",
    "HUGE_VALUE",
    "LIMIT_ENV",
    "MIN_SIDE",
    "PIXELS_ENV",
    "PNG16_DECODER_BYTES",
    "Prepared",
    "RECORD_SCHEMAS",
    "SCALINGS",
    "STACK_FORMATS",
    "STACK_SUFFIXES",
    "VIDEO_SUFFIXES",
    "ZLIB_MAX_RATIO",
    "atomic_write_bytes",
    "atomic_write_many",
    "bin_crop_note",
    "bin_factor",
    "center_crop",
    "check_frame",
    "check_layout_memory",
    "check_memory",
    "check_output_options",
    "check_reconstruct",
    "check_stack_target",
    "check_values",
    "demosaic",
    "effective_pixels",
    "encode_array",
    "encode_image",
    "encode_json",
    "encode_npy",
    "encode_png",
    "encode_tiff",
    "expand_frames",
    "flat_field",
    "fmt_bytes",
    "folder_frames",
    "frame_channels",
    "frame_shapes",
    "frame_layout",
    "frame_to_measurement",
    "gif_header",
    "grid_bytes",
    "load_calibration_frame",
    "new_run_dir",
    "npy_header",
    "one_line",
    "parse_pair",
    "pixel_limit",
    "prepare_frame",
    "read_frame",
    "read_ref",
    "read_scene",
    "records_markdown",
    "refs_of_file",
    "scale_to_uint16",
    "subtract_dark",
    "tiff_header",
    "tiff_pages",
    "unique_names",
    "validate_record",
    "warn_ignored",
    "write_array",
    "write_figure",
    "write_image",
    "write_json",
    "write_stack",
]
