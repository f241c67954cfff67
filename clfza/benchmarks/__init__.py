"""Benchmarks and stress tests that anyone can rerun (issue 5).

- :mod:`.timeerror`: PSNR/SSIM/MSE against wall time per method, backend, size, scene and
  noise, and the cost of an iteration next to the machine's limit (items 1-2);
- :mod:`.scaling`: time per iteration from 256^2 to 4096^2 against N^2 log N (item 3);
- :mod:`.stability`: the numerical stress cases and their counts (item 4);
- :mod:`.machine`: machine/device/version/date record, triad bandwidth, FFT pair time;
- :mod:`.scenes`: the built-in scenes (natural, text, RGB, USAF-like bars, points).

``clfza bench --quick|--full --out DIR`` calls :func:`run`.
"""

from __future__ import annotations

import time
from pathlib import Path

from ..errors import ClfzaError
from . import _scaling as scaling
from . import _stability as stability
from . import _timeerror as timeerror
from ._machine import machine_record, machine_slug

PROFILES = ("quick", "full", "tiny")


def run(
    profile: str = "quick",
    out: str | Path = "bench-results",
    *,
    device: str | None = None,
    stress: bool | None = None,
    log=print,
    first_run: dict | None = None,
) -> dict:
    """Run a benchmark profile and write its result files into ``out``.

    Parameters
    ----------
    profile : {"quick", "full", "tiny"}
        ``"quick"``: about 2 minutes on 2 CPU cores: the paper's Fig. 7 row with every method
        on OpenCL (BP and ADMM on numpy too) and per-iteration scaling 256^2 to 1024^2.
        ``"full"``: the whole time-vs-error grid (5 scenes x 3 noises at 512^2, sizes 256^2 to
        2048^2, both backends), scaling 256^2 to 4096^2 and the stress report (tens of
        minutes). ``"tiny"``: 64^2, 2 iterations (a smoke test).
    out : path
        Output folder (created). Every file records the machine, device, versions and date.
    device : str, optional
        OpenCL device spec.
    stress : bool, optional
        Also run the stability stress report (default: only for ``"full"``).
    log : callable
        Where progress lines go.
    first_run : dict, optional
        What the command's first use of the device spent before the benchmarks
        (``clfza.cli._common.first_run``: the CPU devices' measurement, the first compile,
        the tuning), recorded as is in the time-error and scaling JSON's ``first_run``, never
        in a row.

    Returns
    -------
    dict
        ``{"profile", "out", "elapsed_s", "time_error", "scaling", "stress", "paths"}`` with the
        headline numbers (time to the paper's quality per method, scaling exponents, stress
        counts).
    """

    if profile not in PROFILES:
        raise ClfzaError(f"profile must be one of {PROFILES}, got {profile!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    label = machine_slug(machine_record(device))
    if profile == "quick":
        cases = [
            timeerror.Case("natural", "gauss0.01", 512, "opencl", None, dense=False),
            timeerror.Case("natural", "gauss0.01", 512, "numpy", ["bp", "admm-tv"], dense=False),
        ]
        te = timeerror.run(profile, out, device, cases=cases, log=log, label=label,
                           first_run=first_run)
    else:
        te = timeerror.run(profile, out, device, log=log, label=label, first_run=first_run)
    sc = scaling.run(profile, out, device, log=log, label=label, first_run=first_run)
    st = None
    if stress or (stress is None and profile == "full"):
        st = stability.run(
            out,
            level="test" if profile == "tiny" else "report",
            precision_size=64 if profile == "tiny" else 256,
            precision_iters=20 if profile == "tiny" else 1000,
            log=log,
        )
    headline = [
        {
            k: t[k]
            for k in (
                "scene",
                "noise",
                "size",
                "backend",
                "label",
                "target_psnr",
                "time_to_target_s",
                "final_psnr",
            )
        }
        for t in te["time_to_paper"]
    ]
    summary = {
        "profile": profile,
        "out": str(out),
        "elapsed_s": time.perf_counter() - t0,
        "first_run": first_run,
        "time_error": {"time_to_paper": headline, "paths": te.get("paths")},
        "scaling": {"fits": sc["fits"], "paths": sc.get("paths")},
        "stress": None if st is None else {"counts": st["counts"], "paths": st.get("paths")},
    }
    summary["paths"] = [
        p
        for part in (te.get("paths"), sc.get("paths"), st and st.get("paths"))
        if part
        for v in part.values()
        for p in (v if isinstance(v, list) else [v])
    ]
    log(
        f"clfza bench --{profile}: {summary['elapsed_s']:.0f} s; wrote "
        + ", ".join(Path(p).name for p in summary["paths"])
    )
    return summary


__all__ = ["run", "PROFILES"]
