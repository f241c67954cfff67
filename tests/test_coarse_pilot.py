"""Measured-PSF solves: a start (``x0``) in the units given, the ``pilot`` run control, and the
coarse pilot of large frames (clfza.reconstruction's ``_coarse_pilot``): ``tau="auto"`` reads
the noise from the residual of a 2x-binned solve's image instead of full-size pilot passes."""

from __future__ import annotations

import numpy as np
import pytest
from skimage import data

import clfza
from clfza.errors import ClfzaError
from clfza.metrics import psnr
from clfza.models import crop_to_support, load_psf, scale_psf
from clfza.reconstruction import _reconstruct
from clfza.simulation import simulate_psf_capture

N = _reconstruct.COARSE_PILOT_MIN_SIDE  # the smallest frame that gets the coarse pilot


def capture(n: int, noise=None, rgb: bool = False, **kw):
    scene = data.astronaut() if rgb else data.camera()
    opts = {} if noise is None else {"noise": noise}
    if noise == "none":
        opts = {"noise": None}
    cap = simulate_psf_capture(scene, shape=(n, n), scene_z1=40.0, **opts, **kw)
    psf = load_psf(cap.psf, center="centroid")
    psf = crop_to_support(scale_psf(psf, cap.true_scale, max_shape=(2 * n - 1, 2 * n - 1)))
    return cap, psf


@pytest.fixture(scope="module")
def grey():
    return capture(N)


@pytest.fixture(scope="module")
def grey_solved(grey):
    cap, psf = grey
    return clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)


def test_x0_is_in_the_units_given_with_a_measured_psf():
    """A solve continued from its own image stays there: the start is scaled with the frame
    (before, the start went in unscaled and the continued solve fell 20 dB)."""
    cap, psf = capture(96)
    kw = {"psf": psf, "tau": 3e-4, "stop": "none"}
    first = clfza.reconstruct(cap.y, cap.camera, "admm", iters=200, **kw).image
    again = clfza.reconstruct(cap.y, cap.camera, "admm", iters=2, x0=first, **kw).image
    assert psnr(again, first) > 35.0


def test_x0_and_truth_with_a_colour_psf_go_channel_by_channel():
    cap, psf = capture(64, rgb=True)
    kw = {"psf": psf, "tau": 3e-4, "stop": "none", "white_balance": "none"}
    first = clfza.reconstruct(cap.y, cap.camera, "admm", iters=100, **kw).image
    again = clfza.reconstruct(cap.y, cap.camera, "admm", iters=2, x0=first, **kw).image
    assert again.shape == cap.y.shape
    assert psnr(again, first) > 35.0
    with pytest.raises(ClfzaError, match="x0 has shape"):
        clfza.reconstruct(cap.y, cap.camera, "admm", iters=2, x0=first[..., 0], **kw)
    # the truth too (it failed on its shape): checkpoints score each channel against its own
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", iters=20, truth=cap.truth,
                            checkpoints=[10], **kw)
    assert rec.info.checkpoints and np.isfinite(rec.info.checkpoints[0]["psnr"])


def test_pilot_needs_x0_and_a_bool():
    cap, psf = capture(64)
    with pytest.raises(ClfzaError, match="give x0 with it"):
        clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, pilot=True)
    with pytest.raises(ClfzaError, match="pilot must be True or False"):
        clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, x0=np.zeros(cap.y.shape),
                          pilot="yes")


def test_pilot_start_reads_the_noise_from_its_residual_without_passes():
    """A noisy frame's good estimate given as a pilot: one residual, no pass, and the noise it
    finds is the frame's (the Haar MAD of pure noise)."""
    cap, psf = capture(96)  # the capture noise: photons, read noise, 8 bits
    start = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf).image
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, x0=start, pilot=True)
    a = rec.info.stats["tau_auto"]
    assert a["pilot_start"] and a["stage_iterations_total"] == 0 and len(a["stages"]) == 1
    assert a["rule"] == "noise"
    assert a["sigma"] == pytest.approx(a["sigma_frame"], rel=0.1)
    assert "after the pilot estimate given as the start," in " ".join(rec.info.notes)


def test_pilot_start_that_looks_noise_free_runs_the_passes():
    """A noise-free frame's estimate leaves a structured residual far below the frame's own
    estimate: the passes run from it, as from any start, and the rule is the noise-free one."""
    cap, psf = capture(96, noise="none")
    start = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf).image
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, x0=start, pilot=True)
    a = rec.info.stats["tau_auto"]
    assert a["pilot_start"] and a["stage_iterations_total"] > 0 and len(a["stages"]) > 1
    assert a["rule"] in ("noise_free", "floor")


def test_coarse_pilot_on_a_large_noisy_frame(grey, grey_solved):
    """The frame's noise from the coarse start's residual (no full-size pass), the record and
    the note say so, and the image is what the full-size passes give, within 0.3 dB."""
    cap, psf = grey
    rec = grey_solved
    c = rec.info.stats["coarse_pilot"]
    assert c["used"] and c["rule"] == "noise" and c["bin"] == 2 and c["shape"] == [N // 2] * 2
    a = rec.info.stats["tau_auto"]
    assert a["pilot_start"] and a["stage_iterations_total"] == 0
    assert a["sigma"] == pytest.approx(a["sigma_frame"], rel=0.05)  # a noisy frame's residual
    assert any(n.startswith("coarse pilot: the frame and the PSF binned 2x")
               for n in rec.info.notes)
    assert rec.info.timings["tau_search"] >= c["seconds"] > 0
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_reconstruct, "COARSE_PILOT_MIN_SIDE", 10 * N)
        fine = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)
    assert "coarse_pilot" not in fine.info.stats
    assert fine.info.stats["tau_auto"]["stage_iterations_total"] > 0
    truth = cap.truth
    assert psnr(rec.image, truth) > psnr(fine.image, truth) - 0.3


def test_coarse_pilot_is_skipped_where_it_does_not_apply(grey):
    cap, psf = grey
    small = capture(N // 2)
    rec = clfza.reconstruct(small[0].y, small[0].camera, "admm", psf=small[1])
    assert "coarse_pilot" not in rec.info.stats  # below the size
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf, tau=3e-4, iters=5)
    assert "coarse_pilot" not in rec.info.stats  # a tau given


def test_coarse_pilot_on_a_noise_free_frame_is_no_worse():
    """A noise-free frame: the binned solve's residual holds the binned model's error, which
    the coarse route reads as noise at the full-size residual's level; its image is no worse
    than the full-size passes' (their noise-free rule)."""
    cap, psf = capture(N, noise="none")
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)
    assert rec.info.stats["coarse_pilot"]["used"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_reconstruct, "COARSE_PILOT_MIN_SIDE", 10 * N)
        fine = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)
    assert psnr(rec.image, cap.truth) > psnr(fine.image, cap.truth) - 0.3


def test_coarse_pilot_that_finds_no_noise_leaves_the_full_size_route(grey, monkeypatch):
    """Where the binned solve calls the frame noise-free, the full-size route runs as
    without the coarse pilot (its passes from the default start) and the note says why."""
    cap, psf = grey
    solve = _reconstruct._psf_solve

    def coarse_says_noise_free(*args, coarse_pilot=True, **kw):
        rec = solve(*args, coarse_pilot=coarse_pilot, **kw)
        if not coarse_pilot:  # the coarse solve
            rec.info.stats["tau_auto"] = dict(rec.info.stats["tau_auto"], rule="noise_free")
        return rec

    monkeypatch.setattr(_reconstruct, "_psf_solve", coarse_says_noise_free)
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)
    c = rec.info.stats["coarse_pilot"]
    assert not c["used"] and c["rule"] == "noise_free"
    a = rec.info.stats["tau_auto"]
    assert not a["pilot_start"] and a["stage_iterations_total"] > 0
    assert any("so the full-size pilot passes ran" in n for n in rec.info.notes)


def test_colour_frame_decides_sparsity_from_the_coarse_images():
    """Every channel's coarse pilot runs before the full-size solves, so the frame's
    sparse-scene decision is taken once and no channel is solved again."""
    cap, psf = capture(N, rgb=True)
    rec = clfza.reconstruct(cap.y, cap.camera, "admm", psf=psf)
    chans = rec.info.stats["channels"]
    assert all(ch["coarse_pilot"]["used"] for ch in chans)
    supports = {ch["tau_auto"]["frame_energy_support"] for ch in chans}
    assert len(supports) == 1 and None not in supports
    assert "colour_energy_support" not in rec.info.stats


@pytest.mark.usefixtures("cli_logging")
def test_the_command_line_records_the_coarse_pilot_per_channel(tmp_path):
    """``clfza reconstruct`` of a 384^2 RGB capture with a colour PSF: the record keeps each
    channel's coarse pilot and tau choice (a colour PSF's channels are solved one by one) and
    validates against the documented schema."""
    import json

    from clfza.cli import main
    from clfza.io import validate_record

    cap = simulate_psf_capture(data.astronaut(), shape=(N, N), scene_z1=400.0, psf_z1=400.0)
    np.save(tmp_path / "frame.npy", cap.frame)
    np.save(tmp_path / "psf.npy", cap.psf)
    (tmp_path / "cam.toml").write_text(f"[camera]\npitch = {cap.camera.pitch}\n"
                                       f"shape = [{N}, {N}]\n")
    out = tmp_path / "out"
    assert main(["reconstruct", str(tmp_path / "frame.npy"), "--camera",
                 str(tmp_path / "cam.toml"), "--psf", str(tmp_path / "psf.npy"), "--method",
                 "admm", "--out", str(out), "-q"]) == 0
    rec = json.loads((out / "frame.json").read_text())
    assert validate_record(rec, "frame") == []
    chans = rec["channel_choices"]
    assert len(chans) == 3 and all(c["coarse_pilot"]["used"] for c in chans)
    assert all(c["tau_auto"]["pilot_start"] for c in chans)
    assert any(n.startswith("coarse pilot:") for n in rec["notes"])


@pytest.mark.parametrize("shape, b", [((384, 384), 2), ((479, 600), 2), ((480, 480), 3),
                                      ((488, 488, 3), 3), ((1024, 1536), 3)])
def test_the_coarse_pilot_bins_3x_where_the_binned_frame_keeps_160_pixels(shape, b):
    assert _reconstruct.coarse_pilot_bin(shape) == b
