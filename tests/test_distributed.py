"""Batches on Dask (clfza.distributed), frame streams (clfza.io._stream) and ``clfza sweep``.

The cluster tests share one LocalCluster of 2 worker *processes* (OpenCL contexts are per
process); the test that kills a worker runs last on it.
"""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

import clfza
from clfza import Camera, ClfzaError
from clfza.distributed._batch import FrameResult, frame_state, reconstruct_many
from clfza.io import write_array
from clfza.io._stream import expand_frames, read_ref, write_stack

N = 64
OPTS = {"iters": 15}


def _camera(n: int = N) -> Camera:
    p, z1, z2 = 0.01, 20.0, 3.0
    return Camera(pitch=p, shape=(n, n), r1=np.sqrt(n) * p / (1 + z2 / z1), z1=z1, z2=z2,
                  R=None, mask="gzp")


def _raw_frames(k: int, n: int = N, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    cam = _camera(n)
    out = []
    for _ in range(k):
        f = clfza.simulate(rng.random((16, 16)), cam, object_width=2.0).frame
        out.append(np.round(f / f.max() * 60000).astype(np.uint16))
    return out


@pytest.fixture(scope="module")
def frames_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("frames")
    for i, f in enumerate(_raw_frames(7)):
        write_array(d / f"f{i}.npy", f)
    return d


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    import dask

    with dask.config.set({"distributed.scheduler.allowed-failures": 3}):
        lc = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None, silence_logs=40)
    client = distributed.Client(lc)
    yield client
    client.close()
    lc.close()


def _npys(d: Path, names) -> list[np.ndarray]:
    return [np.load(d / f"{n}.npy") for n in names]


# ----------------------------------------------------------------------------------------
# no Dask needed
# ----------------------------------------------------------------------------------------
def test_local_batch_equals_reconstruct():
    cam = _camera()
    ys = [clfza.simulate(f.astype(float), cam).y for f in
          (np.random.default_rng(1).random((3, 16, 16)))]
    res = reconstruct_many(np.stack(ys), cam, "admm", kind="y", **OPTS)
    assert [r.ok for r in res.results] == [True] * 3 and res.where == "this process"
    for y, r in zip(ys, res.results, strict=True):
        ref = clfza.reconstruct(y, cam, "admm", **OPTS).image
        np.testing.assert_array_equal(r.image, ref)


def test_stream_inputs(tmp_path):
    fr = _raw_frames(3)
    import tifffile

    tifffile.imwrite(tmp_path / "pages.tif", np.stack(fr), photometric="minisblack")
    np.save(tmp_path / "stack.npy", np.stack(fr))
    np.savez(tmp_path / "arch.npz", a=np.stack(fr[:2]), b=fr[2])
    write_array(tmp_path / "single.png", fr[0])
    refs, missing = expand_frames([tmp_path, str(tmp_path / "nope*.png")])
    assert missing == [(str(tmp_path / "nope*.png"), "the pattern matches no file")]
    assert [r.name for r in refs] == ["arch-a-0000", "arch-a-0001", "arch-b", "pages-0000",
                                      "pages-0001", "pages-0002", "single", "stack-0000",
                                      "stack-0001", "stack-0002"]
    for r, want in zip(refs, [fr[0], fr[1], fr[2], *fr, fr[0], *fr], strict=True):
        np.testing.assert_array_equal(read_ref(r)[0], want)
    gif = write_stack(tmp_path / "r.gif", [f.astype(float) for f in fr])
    assert [r.index for r in expand_frames([gif])[0]] == [0, 1, 2]
    with pytest.raises(ClfzaError, match="exists"):
        write_stack(gif, [f.astype(float) for f in fr])


def test_npy_stack_with_more_frames_than_columns(tmp_path):
    # (N, H, W) with N > W is a stack (the soak test's 200 frames of 64 x 64); a last axis
    # of 1, 3 or 4, or one shorter than both others, is a frame's channel axis
    fr = _raw_frames(1)[0][:8, :8]
    np.save(tmp_path / "many.npy", np.stack([fr] * 12))
    np.save(tmp_path / "five.npy", np.ones((16, 16, 5)))
    np.save(tmp_path / "rgb.npy", np.ones((16, 16, 3)))
    refs = expand_frames([tmp_path / "many.npy"])[0]
    assert [r.index for r in refs] == list(range(12))
    np.testing.assert_array_equal(read_ref(refs[11])[0], fr)
    for name in ("five", "rgb"):
        assert [r.index for r in expand_frames([tmp_path / f"{name}.npy"])[0]] == [None]


def test_video_input(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    fr = [(f // 256).astype(np.uint8) for f in _raw_frames(3)]
    mp4 = write_stack(tmp_path / "v.mp4", [f.astype(float) for f in fr])
    refs, _ = expand_frames([mp4])
    assert [r.name for r in refs] == ["v-0000", "v-0001", "v-0002"]
    a, info = read_ref(refs[1])
    assert a.shape == (N, N) and info.format == "video"  # grey video frames read as grey


def test_without_dask_local_works_and_dask_error_names_extra(monkeypatch, frames_dir,
                                                             tmp_path):
    monkeypatch.setitem(sys.modules, "distributed", None)
    res = reconstruct_many(sorted(frames_dir.glob("f[01].npy")), _camera(), "bp",
                           out_dir=tmp_path)
    assert len(res.succeeded) == 2
    with pytest.raises(ClfzaError, match=r"clfza\[dask\]"):
        reconstruct_many(frames_dir, _camera(), "bp", workers=2)


def test_bad_arguments(frames_dir):
    with pytest.raises(ClfzaError, match="unknown method"):
        reconstruct_many(frames_dir, _camera(), "nope")
    with pytest.raises(ClfzaError, match="needs out_dir"):
        reconstruct_many(frames_dir, _camera(), resume=True)
    with pytest.raises(ClfzaError, match="camera must be"):
        reconstruct_many(frames_dir, "simulation")


def test_cli_stack_and_corrupt_frame_local(tmp_path, capsys, cli_logging):
    import tifffile

    from clfza.cli import main

    fr = _raw_frames(3)
    tifffile.imwrite(tmp_path / "pages.tif", np.stack(fr), photometric="minisblack")
    (tmp_path / "bad.npy").write_bytes(b"not an array")
    cam = tmp_path / "cam.toml"
    c = _camera()
    cam.write_text(f"[camera]\npitch = {c.pitch}\nshape = [{N}, {N}]\nr1 = {c.r1}\n"
                   f"z1 = {c.z1}\nz2 = {c.z2}\nmask = \"gzp\"\n")
    out = tmp_path / "out"
    rc = main(["reconstruct", str(tmp_path / "pages.tif"), str(tmp_path / "bad.npy"),
               "--camera", str(cam), "--out", str(out), "--stack-out", str(out / "s.tif"),
               "--method", "admm", "--iters", "5"])
    text = capsys.readouterr()
    assert rc == 1 and "bad.npy" in text.err and "failed" in text.out
    summary = json.loads((out / "batch-001.json").read_text())
    assert summary["succeeded"] == 3 and summary["failed"] == 1
    assert summary["failures"][0]["input"].endswith("bad.npy'")
    import tifffile as tf

    assert tf.imread(out / "s.tif").shape == (3, N, N)
    # every option works on every input: --plan on a stack (one path, reconstruct_many)
    assert main(["reconstruct", str(tmp_path / "pages.tif"), "--camera", str(cam), "--out",
                 str(tmp_path / "planned"), "--plan"]) == 0, capsys.readouterr().err
    recs = [json.loads((tmp_path / "planned" / f"pages-{i:04d}.json").read_text())
            for i in range(3)]
    assert all("plan" in r["parameters"] for r in recs)


# ----------------------------------------------------------------------------------------
# on a 2-process LocalCluster
# ----------------------------------------------------------------------------------------
def test_dask_ordered_identical_to_single_process(cluster, frames_dir, tmp_path):
    files = sorted(frames_dir.glob("*.npy"))
    one = reconstruct_many(files, _camera(), "admm", out_dir=tmp_path / "one", **OPTS)
    many = reconstruct_many(files, _camera(), "admm", client=cluster, out_dir=tmp_path / "two",
                            **OPTS)
    names = [f.stem for f in files]
    assert [r.name for r in many.results] == names and all(r.ok for r in many.results)
    for a, b in zip(_npys(tmp_path / "one", names), _npys(tmp_path / "two", names),
                    strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-9 * np.abs(a).max())
    pids = {r.record["worker"]["pid"] for r in many.results}
    assert os.getpid() not in pids and len(pids) <= 2
    for pid in pids:  # kernels compile on a worker's first frame of a kind only
        compiled = [r for r in many.results if r.record["worker"]["pid"] == pid
                    and r.timings["compile"] > 0]
        assert len(compiled) <= 1
    assert one.results[0].timings["read"] >= 0 and "solve" in many.results[0].timings


def test_dask_corrupt_frame_named_rest_complete(cluster, frames_dir, tmp_path):
    files = sorted(frames_dir.glob("*.npy"))
    bad = tmp_path / "f3x.npy"
    bad.write_bytes(files[3].read_bytes()[:100])  # truncated
    batch = files[:3] + [bad] + files[3:]
    res = reconstruct_many(batch, _camera(), "bp", client=cluster, out_dir=tmp_path / "o")
    assert [r.ok for r in res.results] == [True] * 3 + [False] + [True] * 4
    assert "f3x.npy" in res.results[3].error and "corrupt" in res.results[3].error
    assert frame_state(_spec(tmp_path / "o"), "f3x") == "absent"


def _spec(d):
    from clfza.distributed._batch import OutputSpec

    return OutputSpec(str(d))


def test_dask_resume_after_interrupt_redoes_only_missing(cluster, frames_dir, tmp_path):
    files = sorted(frames_dir.glob("*.npy"))
    out = tmp_path / "o"
    seen: list[FrameResult] = []

    def stop_after_two(r: FrameResult) -> None:
        seen.append(r)
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        reconstruct_many(files, _camera(), "admm", client=cluster, out_dir=out,
                         progress=stop_after_two, **OPTS)
    import time

    time.sleep(1.0)  # a cancelled task already running on a worker still finishes
    (out / f"{files[0].stem}.json").unlink(missing_ok=True)  # frame 0: partial at most
    states = {f.stem: frame_state(_spec(out), f.stem) for f in files}
    assert list(states.values()).count("complete") >= 1
    assert states[files[0].stem] != "complete"
    res = reconstruct_many(files, _camera(), "admm", client=cluster, out_dir=out, resume=True,
                           **OPTS)
    assert all(r.ok for r in res.results), [r.error for r in res.failed]
    skipped = {r.name for r in res.results if r.skipped}
    assert skipped == {n for n, s in states.items() if s == "complete"}
    assert all(frame_state(_spec(out), f.stem) == "complete" for f in files)
    again = reconstruct_many(files, _camera(), "admm", client=cluster, out_dir=out,
                             resume=True, **OPTS)
    assert len(again.skipped) == len(files) and again.where == "nothing to do"


# ----------------------------------------------------------------------------------------
# set-up reuse and chunks (issue 15: per-frame overhead)
# ----------------------------------------------------------------------------------------
def test_embedded_cluster_workers_keep_glibcs_adaptive_malloc(frames_dir, tmp_path):
    """The embedded LocalCluster (workers=N) undoes Dask's MALLOC_TRIM_THRESHOLD_ in its
    workers (it made every large array a fresh mmap: a 512^2 ADMM stream ran 30 % slower per
    frame, clfza.distributed._cluster.adaptive_malloc) -- also after another cluster's nanny has put
    the variable into this process's environment; the batch it runs equals the single-process
    one."""
    pytest.importorskip("distributed")
    from clfza.distributed._cluster import adaptive_malloc, open_client

    assert adaptive_malloc() is True  # glibc here; the call is idempotent
    with open_client(workers=1) as (client, desc, n):
        assert (n, desc) == (1, "LocalCluster(1 processes)")
        done = client.run(lambda dask_worker: getattr(dask_worker, "clfza_malloc", None))
        assert list(done.values()) == [True]
    frames = sorted(frames_dir.glob("f[0-2].npy"))
    a = reconstruct_many(frames, _camera(), "admm", workers=1, out_dir=tmp_path / "a", **OPTS)
    b = reconstruct_many(frames, _camera(), "admm", out_dir=tmp_path / "b", **OPTS)
    assert all(r.ok for r in a.results + b.results) and len(a.results) == 3
    names = [f.stem for f in frames]
    for x, y in zip(_npys(tmp_path / "a", names), _npys(tmp_path / "b", names), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-6, atol=1e-9 * np.abs(y).max())


def test_backend_cache_reuses_setup_identically():
    from clfza.backends import BackendCache, get_backend, reuse_backends

    cam = _camera()
    rng = np.random.default_rng(2)
    ys = [clfza.simulate(rng.random((16, 16)), cam, object_width=2.0).y for _ in range(3)]
    for method in ("admm", "twist"):
        ref = [clfza.reconstruct(y, cam, method, **OPTS) for y in ys]
        with reuse_backends(BackendCache()) as cache:
            got = [clfza.reconstruct(y, cam, method, **OPTS) for y in ys]
        assert (cache.hits, cache.misses) == (2, 1)
        for a, b in zip(ref, got, strict=True):
            np.testing.assert_array_equal(b.image, a.image)
            assert b.info.ffts == a.info.ffts
        assert got[1].info.timings["compile"] == 0.0
    cache = BackendCache(maxsize=1)
    with reuse_backends(cache):
        a = get_backend("numpy", cam)
        assert get_backend("numpy", cam) is a
        get_backend("numpy", _camera(32))  # evicts the first
        assert get_backend("numpy", cam) is not a and len(cache) == 1
    assert get_backend("numpy", cam) is not get_backend("numpy", cam)  # outside: fresh
    with pytest.raises(ClfzaError, match="maxsize"):
        BackendCache(0)


def test_chunk_sizer_and_early_stop(monkeypatch):
    from clfza.distributed import _batch as D

    s = D.ChunkSizer(2, "auto", target_s=1.0)
    assert s.size(100) == 1  # nothing measured yet
    for _ in range(3):
        s.observe(FrameResult(0, "a", "a", ok=True, record={"timings_s": {"task": 0.2}}))
    assert s.size(100) == 5 and s.size(24) == 3 and s.size(7) == 1
    assert D.ChunkSizer(2, 3).size(100) == 3 and D.ChunkSizer(2, 3).size(2) == 2
    with pytest.raises(ClfzaError, match="chunk"):
        reconstruct_many(np.zeros((2, N, N)), _camera(), kind="y", chunk=0)

    def fake(i, src, name, job, overwrite=False):
        if i == 1:
            raise RuntimeError("device lost")
        return FrameResult(i, name, name, ok=True)

    monkeypatch.setattr(D, "run_frame", fake)
    items = [(i, None, f"f{i}", False) for i in range(3)]
    job = D.Job(_camera(), frames_per_solve=1)
    assert [r.index for r in D.run_chunk(items, job)] == [0]  # stops at the failing frame
    with pytest.raises(RuntimeError):
        D.run_chunk(items[1:], job)  # the first frame raising: Dask retries the chunk


def test_dask_chunks_ordered_with_corrupt_frame(cluster, frames_dir, tmp_path):
    files = sorted(frames_dir.glob("*.npy"))
    bad = tmp_path / "f2x.npy"
    bad.write_bytes(b"not an array")
    batch = files[:2] + [bad] + files[2:]
    ref = reconstruct_many(batch, _camera(), "admm", out_dir=tmp_path / "one",
                           cache_backends=False, **OPTS)
    res = reconstruct_many(batch, _camera(), "admm", client=cluster, out_dir=tmp_path / "o",
                           chunk=3, **OPTS)
    assert [r.name for r in res.results] == [f.stem for f in batch]
    assert [r.ok for r in res.results] == [True] * 2 + [False] + [True] * 5
    assert "f2x.npy" in res.results[2].error
    names = [f.stem for f in files]
    for a, b in zip(_npys(tmp_path / "one", names), _npys(tmp_path / "o", names),
                    strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-9 * np.abs(a).max())
    batches = {r.record["batch"] for r in res.succeeded}
    assert len(batches) == 1 and batches != {r.record["batch"] for r in ref.succeeded}
    # a retried chunk skips frames this batch completed; another batch's outputs are refused
    from clfza.distributed._batch import Job, OutputSpec, run_chunk

    job = Job(_camera(), "admm", dict(OPTS), output=OutputSpec(str(tmp_path / "o")),
              batch=batches.pop())
    from clfza.io._stream import FrameRef

    again = run_chunk([(0, FrameRef(str(files[0]), name=files[0].stem), files[0].stem,
                        False)], job)
    assert again[0].ok and again[0].record["outputs"] == res.results[0].record["outputs"]
    other = run_chunk([(0, FrameRef(str(files[0]), name=files[0].stem), files[0].stem,
                        False)], Job(_camera(), "admm", dict(OPTS),
                                     output=OutputSpec(str(tmp_path / "o")), batch="x"))
    assert not other[0].ok and "exists" in other[0].error


def test_dask_job_carries_psf_roi_and_plan(cluster, frames_dir, tmp_path):
    """Every option travels with the job to the workers: a measured PSF (its array inside
    the pickled job), roi and orient, the planner with its explanation."""
    from clfza.models import load_psf

    cam = _camera()
    point = np.zeros(cam.shape)
    point[N // 2, N // 2] = 1.0  # a point source's capture is the PSF
    psf = load_psf(clfza.simulate(point, cam, sensor_plane=True).frame, psf_pitch=cam.pitch,
                   frame_pitch=cam.pitch, center="centroid")
    files = sorted(frames_dir.glob("f[0-2].npy"))
    kw = {"psf": psf, "roi": (4, 4, 32, 32), "orient": "upright", "iters": 5,
          "return_images": True}
    here = reconstruct_many(files, cam, "admm", **kw)
    there = reconstruct_many(files, cam, "admm", client=cluster, out_dir=tmp_path / "o", **kw)
    assert all(r.ok for r in here.results + there.results), [r.error for r in there.failed]
    for a, b in zip(here.images, there.images, strict=True):
        assert b.shape == (32, 32)
        np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-9 * np.abs(a).max())
    rec = there.results[0].record
    assert rec["psf"]["shape"] == list(psf.shape) and rec["parameters"]["model"] == "exact"
    assert rec["output_geometry"] == {"orient": "upright", "roi": [4, 4, 32, 32]}
    planned = reconstruct_many(files, cam, "fista", client=cluster, plan=True, explain=True,
                               iters=5)
    assert all(r.ok and "plan" in r.record["parameters"] and "ran: " in r.explain
               for r in planned.results)


def test_dask_worker_killed_mid_batch_is_replaced(cluster, tmp_path):
    d = tmp_path / "frames"
    for i, f in enumerate(_raw_frames(8, n=128, seed=5)):
        write_array(d / f"k{i}.npy", f)
    killed: list[int] = []

    def kill_first_worker(r: FrameResult) -> None:
        if not killed and r.ok:
            killed.append(r.record["worker"]["pid"])
            os.kill(killed[0], signal.SIGKILL)

    files = sorted(d.glob("*.npy"))
    res = reconstruct_many(files, _camera(128), "admm", client=cluster, out_dir=tmp_path / "o",
                           progress=kill_first_worker, iters=60)
    assert killed and all(r.ok for r in res.results), [r.error for r in res.failed]
    assert [r.name for r in res.results] == [f.stem for f in files]
    pids = {r.record["worker"]["pid"] for r in res.results}
    assert len(cluster.scheduler_info()["workers"]) >= 1
    assert pids - {killed[0]}, "no frame ran on another (or a replacement) worker"


@pytest.mark.slow
def test_soak_200_frames_two_workers(cluster, tmp_path):
    frames = _raw_frames(200, seed=9)
    np.save(tmp_path / "stack.npy", np.stack(frames))
    res = reconstruct_many(tmp_path / "stack.npy", _camera(), "admm", client=cluster,
                           out_dir=tmp_path / "o", **OPTS)
    assert len(res.succeeded) == 200
    assert [r.name for r in res.results] == [f"stack-{i:04d}" for i in range(200)]


# ----------------------------------------------------------------------------------------
# sweeps
# ----------------------------------------------------------------------------------------
def test_sweep_values_and_cli(tmp_path, capsys, cli_logging):
    from clfza.cli import main
    from clfza.distributed._sweep import parse_values

    assert parse_values("1e-4:1e-1:4", "--tau", log=True) == [1e-4, 1e-3, 1e-2, 1e-1]
    assert parse_values("250:350:3", "--z1", log=False) == [250.0, 300.0, 350.0]
    assert parse_values("1,2.5", "--z1", log=False) == [1.0, 2.5]
    with pytest.raises(ClfzaError, match="--tau"):
        parse_values("1:x:3", "--tau", log=True)
    cam = _camera()
    m = clfza.simulate(np.random.default_rng(3).random((16, 16)), cam, object_width=2.0)
    write_array(tmp_path / "raw.npy", np.round(m.frame / m.frame.max() * 6e4).astype(np.uint16))
    np.save(tmp_path / "truth.npy", m.truth)
    camf = tmp_path / "cam.toml"
    camf.write_text(f"[camera]\npitch = {cam.pitch}\nshape = [{N}, {N}]\nr1 = {cam.r1}\n"
                    f"z1 = {cam.z1}\nz2 = {cam.z2}\nmask = \"gzp\"\n")
    rc = main(["sweep", str(tmp_path / "raw.npy"), "--camera", str(camf), "--tau",
               "1e-3:1e-1:2", "--z1", "15,20", "--method", "admm", "--iters", "10", "--truth",
               str(tmp_path / "truth.npy"), "--out", str(tmp_path / "o")])
    assert rc == 0, capsys.readouterr().err
    d = tmp_path / "o" / "sweep-001"
    js = json.loads((d / "sweep.json").read_text())
    assert [(p["z1"], p["tau"]) for p in js["points"]] == [(15, 1e-3), (15, 0.1), (20, 1e-3),
                                                           (20, 0.1)]
    assert js["suggested"]["by"] == "psnr" and js["suggested"]["z1"] == 20
    assert (d / "sweep.png").stat().st_size > 0
    assert (d / "sweep.csv").read_text().splitlines()[0].startswith("z1,tau,")


def test_sweep_on_dask_matches_local(cluster, tmp_path):
    from clfza.distributed._sweep import sweep

    cam = _camera()
    write_array(tmp_path / "raw.npy", _raw_frames(1, seed=4)[0])
    kw = {"method": "admm", "iters": 10}
    a = sweep(tmp_path / "raw.npy", cam, [1e-3, 1e-2], [18.0, 20.0], **kw)
    b = sweep(tmp_path / "raw.npy", cam, [1e-3, 1e-2], [18.0, 20.0], client=cluster, **kw)
    assert [p["metrics"]["z1"] for p in b] == [18.0, 18.0, 20.0, 20.0]
    for p, q in zip(a, b, strict=True):
        assert q["metrics"]["focus"] == pytest.approx(p["metrics"]["focus"], rel=1e-5)
