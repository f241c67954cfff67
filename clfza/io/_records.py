"""The JSON records clfza writes, documented field by field, and a small validator.

Kinds (:data:`RECORD_SCHEMAS`): ``frame`` (one reconstructed frame, ``OUT/NAME.json``),
``batch`` (a batch's summary, ``OUT/batch-NNN.json``), ``simulate`` (``OUT/NAME.json`` of
``clfza simulate``), ``focus`` (``OUT/NAME-focus.json``), ``sweep``
(``OUT/sweep-NNN/sweep.json``) and ``calibrate`` (``FRAME-camera.json``). Each schema is
JSON Schema (the subset :func:`validate_record` checks: ``type``, ``properties``,
``required``, ``additionalProperties``, ``items``, ``enum``) with a ``description`` on
every field; ``docs/records.md`` is generated from it (:func:`records_markdown`) and a test
keeps the two equal. Objects whose keys follow the solver, camera or search
(``parameters``, ``camera``, ``timings_s``...) are described as a whole and accept any key.
"""

from __future__ import annotations

NUM = ["number", "null"]  # JSON numbers; NaN/Inf are written as NaN/Infinity (numbers)


def _f(type_, desc: str, required: bool = True, **more) -> dict:
    d = {"type": type_, "description": desc, **more}
    if not required:
        d["x-optional"] = True
    return d


def _obj(desc: str, props: dict | None = None, required: bool = True, open_: bool = False,
         nullable: bool = False) -> dict:
    d = _f(["object", "null"] if nullable else "object", desc, required)
    if props is not None:
        d["properties"] = props
        d["required"] = [k for k, v in props.items() if not v.get("x-optional")]
        d["additionalProperties"] = open_
    return d


def _arr(desc: str, items: dict | None = None, required: bool = True,
         nullable: bool = False) -> dict:
    d = _f(["array", "null"] if nullable else "array", desc, required)
    if items is not None:
        d["items"] = items
    return d


_COMMON = {
    "clfza_version": _f("string", "clfza's version that wrote the record"),
    "date": _f("string", "local time the record was written, YYYY-MM-DD HH:MM:SS"),
}
_CAMERA = _obj("the camera the work ran with (clfza.Camera.summary(): shape, pitch_mm, r1_mm, "
               "r1_shadow_mm, z1_mm, z2_mm, R_mm, mask, mask_center_px and the derived "
               "optics: magnification, field of view, resolution, band limit, suggested bin, "
               "sampling regime)")
_INPUT_FILE = _obj("the frame file as stored", {
    "path": _f("string", "the file, or the frame's label inside a stack ('a.tif'[3])"),
    "format": _f("string", "png, tiff, npy, npz, gif, video or array"),
    "dtype": _f("string", "the stored sample type (uint8, uint16, float32...)"),
    "shape": _arr("the stored shape (H, W) or (H, W, C)", {"type": "integer"}),
    "bit_depth": _f(["integer", "null"], "8 or 16 for integer frames, null for floating point"),
})
_PREP = {
    "input_file": _INPUT_FILE,
    "preparation": _arr("the steps applied to the raw frame in order (dark, flat, crop HxW at "
                        "(y, x), demosaic, bin BxB with the crop it forced)", {"type": "string"}),
    "crop_origin": _arr("the crop's top-left corner in sensor pixels (row, column)",
                        {"type": "integer"}),
    "bin": _f("integer", "bin factor of the frame preparation (frame records: times the "
              "plan's, see bin_prepare and bin_plan)"),
    "bayer": _f(["string", "null"], "the Bayer pattern demosaiced (RGGB...), or null"),
    "object_mean": _f("number", "the assumed mean of the object (--object-mean): the output "
                      "scale"),
    "dark": _f(["string", "null"], "the dark frame subtracted, or null"),
    "flat": _f(["string", "null"], "the flat field divided by, or null"),
    "frame_mean": _arr("the prepared frame's mean per channel, digital numbers",
                       {"type": "number"}),
    "ignored_options": _arr("options given that did nothing in this combination (each also "
                            "warned about)", {"type": "string"}, required=False),
}

FRAME = _obj("one reconstructed frame: OUT/NAME.json, written last, with OUT/NAME.png|.tif "
             "and OUT/NAME.npy (clfza reconstruct, clfza.reconstruct_many)", {
    **_COMMON,
    "command": _f("string", "the command line as typed (empty from the Python API)"),
    "input": _f("string", "the input file"),
    "input_key": _f("string", "the array's name inside an .npz archive", required=False),
    "input_index": _f("integer", "the page, frame or leading index inside a stack or video",
                      required=False),
    "name": _f("string", "the output stem (unique within the batch)"),
    "kind": _f("string", "'y' when the input was a DC-free observation, used as it is",
               required=False, enum=["y"]),
    **{k: dict(v, **{"x-optional": True}) for k, v in _PREP.items()},
    "camera": _CAMERA,
    "camera_file": _f(["string", "null"], "the camera preset or TOML file given",
                      required=False),
    "method": _f("string", "the method that ran: bp, twist, fista, admm or wiener"),
    "parameters": _obj("the method's options as given and as resolved (tau, weight, iters, "
                       "model, stopping rule...; plan: the planner's record with --plan)"),
    "backend": _f("string", "opencl or numpy"),
    "device": _f("string", "the device that ran the solve"),
    "dtype": _f("string", "the solve's floating-point type"),
    "iterations": _f("integer", "iterations run (1 for a direct method)"),
    "stop_reason": _f("string", "why the solve stopped (max_iters, tolerance, ...)"),
    "stop_rule_fired": _f("string", "the stopping rule that fired (the plan's, else "
                          "stop_reason)"),
    "notes": _arr("remarks of the solver and the model choice, one sentence each",
                  {"type": "string"}),
    "psf": _obj("the measured PSF used (--psf): its file and every step of its loading", {
        "file": _f("string", "the PSF file (or the array's shape)"),
        "scale": _f("number", "--psf-scale: the magnification applied to the PSF after "
                    "resampling it to the frame's pitch", required=False),
        "scale_cut_fraction": _f("number", "the magnified PSF's light outside the 2N - 1 "
                                 "window a frame of N pixels sees", required=False),
        "scale_search": _obj("--psf-scale auto: the search on the first frame (frame, scale, "
                             "confident, reason, scale_uncertainty, depth_mm, seconds)",
                             required=False),
    }, open_=True, nullable=True),
    "output_geometry": _obj("what was done to the saved image", {
        "orient": _f("string", "sensor, or upright (rotated by 180 degrees)"),
        "roi": _arr("the region saved (y, x, h, w) of the sensor grid", {"type": "integer"},
                    required=False),
    }),
    "worker": _obj("the process that ran the frame", {
        "name": _f("string", "the Dask worker's name, or local"),
        "pid": _f("integer", "its process id"),
        "frames_done": _f("integer", "frames this process has reconstructed so far"),
        "first_of_kind": _f("boolean", "the first frame of this camera, method and device on "
                            "this process (its time includes set-up and kernel builds)"),
    }),
    "batch": _f("string", "the batch's id (a retried chunk skips frames it already wrote)"),
    "frames_per_solve": _f("integer", "frames solved together with this one, one kernel "
                           "launch per step for all (1: alone; --frames-per-solve)"),
    "machine": _obj("where it ran", {
        "platform": _f("string", "the operating system"),
        "python": _f("string", "Python's version"),
    }),
    "bin_prepare": _f("integer", "bin factor of the frame preparation (--bin)"),
    "bin_plan": _f("integer", "bin factor the plan added (--plan), else 1"),
    "solve_shape": _arr("the grid the solve ran on (rows, columns)", {"type": "integer"}),
    "objective_last": _f(NUM, "the final value of the objective, summed over colour channels; "
                         "null for a method without one (bp)"),
    "objective_history": _arr("the objective at every evaluation: a list of numbers, or one "
                              "list per colour channel solved separately; null without one",
                              nullable=True),
    "returned": _obj("which image the solve returned", {
        "image": _f("string", "last (the last iterate), mean (the averaged iterate, which "
                    "the exact model's ADMM returns when its objective is lower) or direct "
                    "(a method without iterations: bp, wiener)",
                    enum=["last", "mean", "direct"]),
        "objective_mean": _f(NUM, "the averaged iterate's objective (exact-model ADMM), "
                             "else null"),
        "objective_last": _f(NUM, "the last iterate's objective, else null"),
    }),
    "tau_auto": _obj("tau='auto': the tau chosen, the criterion and its values",
                     required=False),
    "coarse_pilot": _obj("a measured-PSF frame's coarse pilot (tau='auto', frames of 384 "
                         "pixels a side and more): bin, shape, iterations, the coarse solve's "
                         "rule and tau, seconds, and whether the full-size solve used it",
                         required=False),
    "channel_choices": _arr("a colour frame's channels, solved one by one (a colour PSF's, "
                            "or colour='independent'): per channel its tau_auto and "
                            "coarse_pilot", {"type": "object"}, required=False),
    "white_balance": _obj("colour frames: the white balance applied (--white-balance)", {
        "mode": _f("string", "the balance asked: psf (the default), grey or none",
                   enum=["psf", "grey", "none"]),
        "applied": _f("string", "the balance applied: psf (the colour PSF's channel sums), "
                      "grey (grey-world; psf asked without a colour PSF falls back to it) or "
                      "none (the sensor's colours)", enum=["psf", "grey", "none"]),
        "gains": _arr("the per-channel gains divided out of the image (mean 1)",
                      {"type": "number"}),
        "statistic": _f("string", "grey-world: the channels' statistic made equal (mean, or "
                        "rms where a channel's mean is not reliable; flat: none)",
                        required=False),
        "reason": _f("string", "where the gains came from"),
    }, required=False),
    "outputs": _obj("the files written for the frame", {
        "image": _f("string", "the 16-bit PNG or TIFF (or float TIFF)"),
        "npy": _f("string", "the reconstruction as float64 NPY"),
        "json": _f("string", "this record"),
    }),
    "scaling": _obj("how the image file was scaled from the reconstruction (mode, lo, hi, "
                    "out_range, percentiles, clipped_fraction, dtype; colour: one range for "
                    "all three channels)"),
    "timings_s": _obj("seconds: read, prepare, reconstruct, compile, plan, solve, write, "
                      "task; solver (the solver's own timings); start_unix and end_unix"),
})

BATCH = _obj("a batch's summary: OUT/batch-NNN.json (clfza reconstruct of several frames)", {
    **_COMMON,
    "command": _f("string", "the command line as typed"),
    "method": _f("string", "the method"),
    "parameters": _obj("the method's options as given"),
    "frames": _f("integer", "frames in the batch"),
    "succeeded": _f("integer", "frames with complete outputs (skipped ones included)"),
    "skipped_complete": _f("integer", "frames --resume skipped: their outputs were complete"),
    "failed": _f("integer", "frames that failed"),
    "wall_s": _f("number", "the batch's wall time, seconds"),
    "where": _f("string", "this process, LocalCluster(N processes) or the scheduler"),
    "workers": _f("integer", "worker processes"),
    "outputs": _arr("per succeeded frame: its input and its files (image, npy, json)",
                    {"type": "object"}),
    "failures": _arr("per failed frame: its input and the error", {"type": "object"}),
    "stacks": _arr("the --stack-out files written", {"type": "string"}),
    "missing_inputs": _arr("inputs that gave no frame (input, error)", {"type": "object"}),
    "stack_errors": _arr("--stack-out files that failed, with the error", {"type": "string"}),
})

SIMULATE = _obj("a simulation: OUT/NAME.json beside OUT/NAME-raw.* (clfza simulate)", {
    **_COMMON,
    "scene": _f("string", "the scene: a file or a built-in name"),
    "camera": _CAMERA,
    "camera_file": _f("string", "the camera preset or TOML file given"),
    "noise": _obj("the noise model (gaussian_var, photons, read_noise, bit_depth, exposure, "
                  "seed)"),
    "frame_noise": _f(["string", "null"], "how the noise terms enter the frame"),
    "raw_storage": _f("string", "how the raw frame is stored (bit depth, quantisation)"),
    "frame_scale": _f("number", "the gain from the frame to y: y = (frame - mean) * scale"),
    "object_mean": _f("number", "the ground truth's mean: reconstruct's --object-mean for the "
                      "simulation's scale"),
    "object_mean_note": _f("string", "what object_mean is for"),
    "simulation": _obj("clfza.simulate's record: object width and centre, margin, diffraction, "
                       "noise, SNR, saturated fraction"),
    "simulate_s": _f("number", "seconds the simulation took"),
    "outputs": _obj("the files written", {
        "raw": _f("string", "the raw frame (OUT/NAME-raw.tif|png|npy), which a folder read "
                  "takes"),
        "truth_npy": _f("string", "the ground truth, float64 (OUT/truth/NAME-truth.npy)"),
        "truth_png": _f("string", "the ground truth, 16-bit (OUT/truth/NAME-truth.png)"),
        "json": _f("string", "this record"),
    }),
    "ignored_options": _arr("options given that did nothing", {"type": "string"},
                            required=False),
})

FOCUS = _obj("an autofocus search: OUT/NAME-focus.json (clfza focus)", {
    **_COMMON,
    "input": _f("string", "the raw frame"),
    **_PREP,
    "camera": _CAMERA,
    "camera_file": _f("string", "the camera preset or TOML file given"),
    "z_range": _arr("the search interval of z1, mm (not with --psf)", {"type": "number"},
                    required=False),
    "search": _f("string", "the search strategy (not with --psf)", required=False),
    "backend": _f("string", "opencl or numpy (not with --psf)", required=False),
    "focus": _obj("the search's result (clfza.focus.FocusResult: z1_best, r1p_best, "
                  "confident, evidence with at_edge and reason, z_grid, scores, metric, "
                  "evaluations, depth_resolution, timings; not with --psf)", required=False),
    "psf": _obj("--psf: the measured PSF searched (file and every step of its loading)",
                required=False),
    "psf_scale": _obj("--psf: the scale search's result (clfza.focus.PSFScaleResult: scale, "
                      "confident, scale_uncertainty, depth_mm, bin, metric, evidence with "
                      "reason, prominence, fine_prominence, ambiguity and candidates, the "
                      "scales and scores of every level, timings)", required=False),
    "wall_s": _f("number", "seconds the search took"),
})

SWEEP = _obj("a parameter sweep: OUT/sweep-NNN/sweep.json (clfza sweep)", {
    "raw": _f("string", "the raw frame"),
    "method": _f("string", "the method"),
    "options": _obj("the method's options besides tau"),
    "taus": _arr("the tau grid (null: the method's default)"),
    "z1s": _arr("the z1 grid, mm", {"type": "number"}),
    "truth": _f(["string", "null"], "the ground truth for PSNR/SSIM, or null"),
    "wall_s": _f("number", "seconds the sweep took"),
    "camera": _CAMERA,
    "command": _f("string", "the command line as typed"),
    "suggested": _obj("the suggested point: by (psnr or focus), its metrics, and at_edge: the "
                      "parameters (tau, z1) whose best value is the first or last of a grid of "
                      "three or more (the optimum may lie beyond it)", {
        "by": _f("string", "psnr (with a truth) or focus"),
        "at_edge": _arr("tau and/or z1 when the best sits at the edge of its grid",
                        {"type": "string"}),
    }, open_=True),
    "points": _arr("per grid point (z1 outer, tau inner): z1, tau, iterations, solve_s, tv, "
                   "focus, objective (the final objective, a number or null); psnr and ssim "
                   "with a truth", {"type": "object"}),
})

_NUM_PAIR = {"type": "number"}
CALIBRATE = _obj("a calibration on a point-source capture: FRAME-camera.json beside the "
                 "camera file FRAME-camera.toml (clfza calibrate; the record is named after "
                 "--out with .json)", {
    **_COMMON,
    "input": _f("string", "the point-source frame"),
    "camera_file": _f("string", "the camera TOML file written"),
    "z1": _f("number", "--z1: the point source's distance, mm"),
    "z2": _f("number", "--z2: the mask-to-sensor distance, mm"),
    "r1_given": _f(NUM, "--r1: the mask's innermost zone radius given, mm (null: from the "
                   "fitted shadow, r1 = r1' / (1 + z2/z1))"),
    "R_given": _f(NUM, "--R: the mask's aperture radius given, mm, or null"),
    "R_source": _f("string", "where the camera file's R comes from: measured (the fitted "
                   "edge), given (--R, the capture does not determine R') or omitted (neither)",
                   enum=["measured", "given", "omitted"]),
    "calibration": _obj("the fit (clfza.camera.Calibration.to_dict()): every value with its "
                        "standard error; a parameter the capture does not determine has no "
                        "value (null) and is named in undetermined", {
        "r1_shadow_squared": _f("number", "r1'^2, the shadow's innermost zone radius squared, "
                                "mm^2"),
        "r1_shadow_squared_std": _f("number", "its standard error, mm^2"),
        "center": _arr("the zone pattern's centre (row, column), pixels", _NUM_PAIR),
        "center_std": _arr("its standard errors (row, column), pixels", _NUM_PAIR),
        "R_shadow": _f(NUM, "R', the aperture's shadow radius, mm; null when undetermined"),
        "R_shadow_std": _f(NUM, "its standard error, mm; null when undetermined"),
        "mask": _f("string", "the mask type found: fza (binary) or gzp (sinusoidal)"),
        "harmonic_ratio": _f("number", "|a3| / |a1| of the fitted series (FZA 1/3, GZP 0)"),
        "phase": _f("number", "the zone pattern's phase, rad"),
        "phase_std": _f("number", "its standard error, rad"),
        "amplitude": _f("number", "the fitted zone amplitude, frame units"),
        "mean": _f("number", "the fitted mean level, frame units"),
        "background": _f("number", "the fitted level outside the aperture, frame units"),
        "fill": _f("number", "the binary mask's fill factor (open fraction of a period)"),
        "residual_rms": _f("number", "RMS of the fit's residual, frame units"),
        "signal_rms": _f("number", "RMS of the fitted zone pattern, frame units"),
        "pitch": _f("number", "the frame's pixel pitch, mm"),
        "shape": _arr("the frame's shape (rows, columns)", {"type": "integer"}),
        "bin": _f("integer", "the bin factor the fit ran at"),
        "warnings": _arr("reasons for low confidence (empty: trustworthy; otherwise no camera "
                         "file is written)", {"type": "string"}),
        "timings": _obj("seconds per stage (and total_s)"),
        "undetermined": _obj("the parameters the capture does not determine, each with the "
                             "reason (R_shadow: the aperture's shadow reaches past the "
                             "sensor; fill: the fill factor ran to a bound)"),
        "mask_center": _arr("the centre's offset from pixel N // 2 (rows, columns)",
                            _NUM_PAIR),
        "confident": _f("boolean", "true when there is no warning"),
    }),
})

RECORD_SCHEMAS = {"frame": FRAME, "batch": BATCH, "simulate": SIMULATE, "focus": FOCUS,
                  "sweep": SWEEP, "calibrate": CALIBRATE}

_TYPES = {"string": str, "boolean": bool, "object": dict, "array": list}


def _is(value, t: str) -> bool:
    if t == "null":
        return value is None
    if t == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if t == "number":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return isinstance(value, _TYPES[t])


def validate_record(record, schema: dict | str, path: str = "$") -> list[str]:
    """The ways ``record`` breaks ``schema`` (a dict, or a kind of :data:`RECORD_SCHEMAS`),
    one line each naming the field; empty when it conforms."""
    if isinstance(schema, str):
        schema = RECORD_SCHEMAS[schema]
    errs: list[str] = []
    types = schema.get("type")
    if types is not None:
        ts = [types] if isinstance(types, str) else list(types)
        if not any(_is(record, t) for t in ts):
            return [f"{path}: expected {' or '.join(ts)}, got {type(record).__name__} "
                    f"{str(record)[:60]!r}"]
    if "enum" in schema and record not in schema["enum"]:
        errs.append(f"{path}: {record!r} is not one of {schema['enum']}")
    if isinstance(record, dict) and "properties" in schema:
        props = schema["properties"]
        for k in schema.get("required", []):
            if k not in record:
                errs.append(f"{path}: missing field {k!r}")
        for k, v in record.items():
            if k in props:
                errs += validate_record(v, props[k], f"{path}.{k}")
            elif schema.get("additionalProperties", True) is False:
                errs.append(f"{path}: undocumented field {k!r}")
    if isinstance(record, list) and "items" in schema:
        for i, v in enumerate(record):
            errs += validate_record(v, schema["items"], f"{path}[{i}]")
    return errs


def _type_text(s: dict) -> str:
    t = s.get("type", "any")
    ts = [t] if isinstance(t, str) else list(t)
    out = " or ".join(ts)
    if "items" in s and isinstance(s["items"].get("type"), str):
        out = out.replace("array", f"array of {s['items']['type']}")
    return out


def _rows(props: dict, prefix: str = "") -> list[str]:
    rows = []
    for k, s in props.items():
        opt = " (optional)" if s.get("x-optional") else ""
        desc = s["description"].replace("|", "\\|")
        rows.append(f"| `{prefix}{k}` | {_type_text(s)}{opt} | {desc} |")
        if "properties" in s:
            rows += _rows(s["properties"], f"{prefix}{k}.")
    return rows


def records_markdown() -> str:
    """``docs/records.md``: every field of every record kind, from :data:`RECORD_SCHEMAS`."""
    out = ["# The JSON records clfza writes", "",
           "Generated from `clfza.io.RECORD_SCHEMAS` (`clfza/io/_records.py`) by",
           "`clfza.io.records_markdown()`; `tests/test_record_schema.py` checks that this file",
           "matches it and that every record the commands write validates against it. Numbers",
           "that are not finite are written as `NaN`/`Infinity`.", ""]
    for kind, schema in RECORD_SCHEMAS.items():
        out += [f"## `{kind}`", "", schema["description"] + ".", "",
                "| field | type | meaning |", "|---|---|---|", *_rows(schema["properties"]), ""]
    return "\n".join(out)
