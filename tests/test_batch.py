"""Batches of frames (issue 37): one backend, one launch per step for many frames.

The reference of a batched solve is the one-frame solve of each frame: the batch must give
the same images, iteration counts, stop reasons and objective histories to float32 rounding
(on CPU devices with the host FFT they are bit-identical: the same kernels on the same
values), and within the float32 tolerance of the numpy float64 reference. These are agreement
tests: .ci/run reruns them on every OpenCL implementation; tests/test_oclgrind.py runs the
batch on the GPU code paths (device FFT, device-chosen work-groups) under Oclgrind.
"""

from __future__ import annotations

import numpy as np
import pytest
from _batch_frames import N
from _batch_frames import frames as _frames

import clfza
from clfza.backends import get_backend
from clfza.errors import ClfzaError
from clfza.solvers import ClfzaWarning, run_solver, run_solver_batch

pytestmark = pytest.mark.agreement



@pytest.fixture(scope="module")
def cam():
    return clfza.Camera.preset("simulation").with_shape((N, N))


def _same(batched, single, rtol: float = 1e-5) -> None:
    """Equal to float32 rounding: images (relative to the frame's scale), iterations, stop
    reasons, objective histories."""
    scale = max(float(np.abs(single.image).max()), 1e-30)
    np.testing.assert_allclose(batched.image, single.image, rtol=0, atol=rtol * scale)
    assert batched.info.iterations == single.info.iterations
    assert batched.info.stop_reason == single.info.stop_reason
    np.testing.assert_allclose(np.ravel(batched.info.objective),
                               np.ravel(single.info.objective), rtol=rtol)


KW = dict(model="tf", backend="opencl", iters=40, tol=2e-4)


@pytest.mark.parametrize("nonneg", [False, True])
def test_grey_batch_equals_one_frame_at_a_time(cam, nonneg):
    ys = _frames(cam, 4)
    taus = [0.002, 0.005, 0.01, 0.03]
    out = run_solver_batch(ys, cam, "admm", tau=taus, nonneg=nonneg, **KW)
    stops = set()
    for y, t, b in zip(ys, taus, out, strict=True):
        ref = run_solver(y, cam, "admm", tau=t, nonneg=nonneg, **KW)
        _same(b, ref)
        stops.add(b.info.iterations)
        assert b.info.params["tau"] == t
        assert b.info.stats["batch"]["frames"] == 4
    # the frames stopped at different iterations: the per-frame stop (and the kernels of a
    # stopped frame returning at once) is exercised, not only the common loop
    assert len(stops) > 1


def test_colour_channels_are_planes_of_the_batch(cam):
    ys = _frames(cam, 2, colour=True)
    out = run_solver_batch(ys, cam, "admm", tau=0.01, **KW)
    assert out[0].image.shape == (N, N, 3)
    for y, b in zip(ys, out, strict=True):
        ref = run_solver(y, cam, "admm", tau=0.01, **KW)
        scale = float(np.abs(ref.image).max())
        np.testing.assert_allclose(b.image, ref.image, rtol=0, atol=1e-5 * scale)
        assert b.info.stats["batch"]["frames"] == 6  # 2 frames x 3 channels
        assert len(b.info.objective) == 3  # one history per channel


def test_joint_colour_frames_batch(cam):
    ys = _frames(cam, 3, colour=True, seed=1)
    kw = dict(KW, colour="joint")
    out = run_solver_batch(ys, cam, "admm", tau=0.01, **kw)
    for y, b in zip(ys, out, strict=True):
        _same(b, run_solver(y, cam, "admm", tau=0.01, **kw))
        assert b.info.stats["batch"]["frames"] == 3


def test_batch_against_the_float64_reference(cam):
    """The batch in float32 against the numpy float64 one-frame solve: a few iterations
    without a stopping rule, 1e-4 of the data scale (as tests/test_api_solvers.py)."""
    ys = _frames(cam, 3, seed=2)
    kw = dict(model="tf", iters=5, min_iters=5, stop="none")
    out = run_solver_batch(ys, cam, "admm", tau=[0.005, 0.01, 0.02], backend="opencl", **kw)
    for y, t, b in zip(ys, [0.005, 0.01, 0.02], out, strict=True):
        ref = run_solver(y, cam, "admm", tau=t, backend="numpy", **kw).image
        assert np.abs(b.image - ref).max() <= 1e-4 * np.abs(ref).max()


def test_constant_frame_in_a_batch(cam):
    ys = _frames(cam, 3)
    ys[1] = 0.0
    with pytest.warns(ClfzaWarning, match="frame 1 of the batch is constant"):
        out = run_solver_batch(ys, cam, "admm", tau=0.01, **KW)
    assert not out[1].image.any()
    assert out[1].info.stop_reason == "constant_measurement"
    assert any("constant" in n for n in out[1].info.notes)
    _same(out[2], run_solver(ys[2], cam, "admm", tau=0.01, **KW))
    assert out[0].info.stats["batch"]["frames"] == 2


@pytest.mark.parametrize("extra, why", [
    ({"tau": "auto", "model": "exact"}, "'exact' model"),
    ({"checkpoints": 5}, "checkpoints"),
])
def test_what_cannot_batch_runs_alone_and_says_why(cam, extra, why):
    ys = _frames(cam, 2)
    kw = {**KW, "tau": 0.01, **extra}
    out = run_solver_batch(ys, cam, "admm", **kw)
    for y, b in zip(ys, out, strict=True):
        assert b.info.stats["batch"]["frames"] == 1
        assert why in b.info.stats["batch"]["alone"]
        _same(b, run_solver(y, cam, "admm", **kw))


def test_other_methods_run_alone(cam):
    ys = _frames(cam, 2)
    out = run_solver_batch(ys, cam, "twist", tau=0.01, iters=5, model="exact")
    assert "runs one frame at a time" in out[0].info.stats["batch"]["alone"]
    np.testing.assert_array_equal(
        out[1].image, run_solver(ys[1], cam, "twist", tau=0.01, iters=5, model="exact").image)


def test_bad_batches_are_refused(cam):
    ys = _frames(cam, 2)
    with pytest.raises(ClfzaError, match="2 frames"):
        run_solver_batch(ys, cam, "admm", tau=[0.1, 0.2, 0.3], **KW)
    with pytest.raises(ClfzaError, match=r"\(F, H, W\)"):
        run_solver_batch(ys[0], cam, "admm", **KW)


def test_batch_backend_sums_per_frame_and_refuses_one_frame_kernels(cam):
    rng = np.random.default_rng(3)
    B = get_backend("opencl", cam, frames=3)
    xs = rng.standard_normal((3, N, N))
    x = B.from_host(xs)
    got = B.reg_value(x).get()
    assert got.shape == (3, 2)
    for f in range(3):
        one = get_backend("opencl", cam)
        ref = one.reg_value(one.from_host(xs[f][None])).get()
        np.testing.assert_allclose(got[f], ref, rtol=1e-6)
        np.testing.assert_array_equal(B.frame_to_host(x, f)[0], xs[f].astype(np.float32))
    with pytest.raises(ClfzaError, match="one frame at a time"):
        B.prox_step("l1", x, x, 1.0, 0.1, B.empty(), 2, clfza.backends.ProxState())
    with pytest.raises(ClfzaError, match="batch"):
        get_backend("numpy", cam, frames=2)


def test_reconstruct_takes_a_stack(cam):
    ys = _frames(cam, 3)
    images, infos = clfza.reconstruct(ys, cam, "admm", tau=[0.005, 0.01, 0.02], **KW)
    assert images.shape == (3, N, N) and len(infos) == 3
    for y, t, img in zip(ys, [0.005, 0.01, 0.02], images, strict=True):
        np.testing.assert_allclose(img, clfza.reconstruct(y, cam, "admm", tau=t, **KW).image,
                                   rtol=0, atol=1e-5 * np.abs(img).max())
    # back-propagation of a stack: frame by frame
    bp, bp_infos = clfza.reconstruct(ys, cam, backend="numpy")
    np.testing.assert_array_equal(bp[1], clfza.reconstruct(ys[1], cam, backend="numpy").image)


# ----------------------------------------------------------------------------------------
# streams: reconstruct_many and clfza reconstruct solve consecutive frames together
# ----------------------------------------------------------------------------------------
def test_reconstruct_many_solves_frames_together(cam, tmp_path):
    from clfza.distributed import reconstruct_many

    ys = _frames(cam, 5, seed=4)
    kw = dict(kind="y", model="tf", tau=0.01, iters=30, tol=1e-4)
    alone = reconstruct_many(ys, cam, "admm", frames_per_solve=1, out_dir=tmp_path / "a", **kw)
    together = reconstruct_many(ys, cam, "admm", frames_per_solve=3, out_dir=tmp_path / "b",
                                **kw)
    assert all(r.ok for r in together.results)
    # 5 frames, 3 at a time: solves of 3 and 2 frames
    assert [r.record["frames_per_solve"] for r in together.results] == [3, 3, 3, 2, 2]
    assert [r.record["frames_per_solve"] for r in alone.results] == [1] * 5
    for a, b in zip(alone.results, together.results, strict=True):
        assert a.record["iterations"] == b.record["iterations"]
        ia = np.load(a.record["outputs"]["npy"])
        np.testing.assert_allclose(np.load(b.record["outputs"]["npy"]), ia, rtol=0,
                                   atol=1e-5 * np.abs(ia).max())


def test_frames_per_solve_auto_and_what_does_not_group(cam):
    from clfza.cl import get_runtime
    from clfza.distributed import reconstruct_many
    from clfza.solvers import frames_per_solve_for

    assert frames_per_solve_for("wiener", "opencl", None, (N, N)) == 1
    assert frames_per_solve_for("admm", "numpy", None, (N, N)) == 1
    auto = frames_per_solve_for("admm", "opencl", None, (N, N))
    assert auto == 1 if get_runtime().is_cpu else auto > 1  # CPUs: one frame at a time
    ys = _frames(cam, 2, seed=5)
    res = reconstruct_many(ys, cam, "fista", kind="y", model="tf", tau=0.01, iters=5,
                           reg="l1", frames_per_solve=2)  # l1 does not batch: frames alone
    assert [r.record["frames_per_solve"] for r in res.results if r.ok] == [1, 1]
    with pytest.raises(ClfzaError, match="frames_per_solve"):
        reconstruct_many(ys, cam, "admm", kind="y", frames_per_solve=0)


def test_cli_frames_per_solve(cam, tmp_path, cli_logging):
    import json

    from clfza.cli import main
    from clfza.io import write_array

    frames = tmp_path / "frames"
    frames.mkdir()
    rng = np.random.default_rng(8)
    for i in range(3):
        f = clfza.simulate(rng.random((N, N)), cam, object_width=N * cam.pitch).frame
        write_array(frames / f"f{i}.tif", np.round(f / f.max() * 4000).astype(np.uint16))
    outs = {}
    for k in ("1", "3"):
        assert main(["reconstruct", str(frames), "--camera", "simulation", "--crop", f"{N},{N}",
                     "--method", "admm", "--model", "tf", "--tau", "0.01", "--iters", "20",
                     "--frames-per-solve", k, "--out", str(tmp_path / k), "-q"]) == 0
        outs[k] = [json.loads((tmp_path / k / f"f{i}.json").read_text()) for i in range(3)]
    assert [r["frames_per_solve"] for r in outs["3"]] == [3, 3, 3]
    assert [r["frames_per_solve"] for r in outs["1"]] == [1, 1, 1]
    for a, b in zip(outs["1"], outs["3"], strict=True):
        ia, ib = np.load(a["outputs"]["npy"]), np.load(b["outputs"]["npy"])
        np.testing.assert_allclose(ib, ia, rtol=0, atol=1e-5 * np.abs(ia).max())


def test_tau_auto_batch_equals_one_frame_at_a_time(cam):
    """tau="auto": every frame's discrepancy search (its stages run together, frames with
    stages of one length in one batch) chooses the tau its solve alone chooses, and the
    image is the same."""
    ys = _frames(cam, 3, seed=6)
    kw = dict(model="tf", backend="opencl", tau="auto")
    out = run_solver_batch(ys, cam, "admm", **kw)
    for y, b in zip(ys, out, strict=True):
        ref = run_solver(y, cam, "admm", **kw)
        assert b.info.stats["batch"]["frames"] == 3
        assert b.info.params["tau"] == pytest.approx(ref.info.params["tau"], rel=1e-6)
        assert (b.info.stats["tau_auto"]["stage_iterations_total"]
                == ref.info.stats["tau_auto"]["stage_iterations_total"])
        _same(b, ref)


def test_one_frame_solves_after_a_batch_on_shared_backends(cam):
    """A batch leaves the backends it used (a cache shares them with one-frame solves) with
    their per-frame factors back at one."""
    from clfza.backends import BackendCache, reuse_backends

    ys = _frames(cam, 3, seed=7)
    kw = dict(model="tf", backend="opencl", tau="auto")
    with reuse_backends(BackendCache()):
        run_solver_batch(ys, cam, "admm", **kw)
        after = run_solver(ys[0], cam, "admm", **kw)
    fresh = run_solver(ys[0], cam, "admm", **kw)
    np.testing.assert_array_equal(after.image, fresh.image)


@pytest.mark.parametrize("stop", ["objective", "step"])
def test_late_read_stopping_rule_keeps_each_frames_result(cam, stop):
    """The batch reads its stopping rule STOP_LAG iterations late (no wait for the host in
    the loop) and takes a stopped frame's image from the device's ring of recent iterates:
    each frame's iterations, image and history are still those of its own solve, for both
    rules that read sums, with the frames stopping at different iterations."""
    from clfza.solvers._driver import STOP_LAG

    assert STOP_LAG >= 1
    ys = _frames(cam, 4, seed=3)
    taus = [0.002, 0.005, 0.01, 0.03]
    kw = dict(model="tf", backend="opencl", iters=60, tol=1e-3, stop=stop)
    out = run_solver_batch(ys, cam, "admm", tau=taus, **kw)
    its = set()
    for y, t, b in zip(ys, taus, out, strict=True):
        _same(b, run_solver(y, cam, "admm", tau=t, **kw))
        its.add(b.info.iterations)
    assert len(its) > 1
