"""The README's Python examples run as written (issue 32: every documented path is public)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import tifffile

import clfza

README = Path(__file__).resolve().parents[1] / "README.md"


def _blocks() -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", README.read_text(), flags=re.S | re.M)


def _block(first_line: str) -> str:
    found = [b for b in _blocks() if first_line in b]
    assert len(found) == 1, f"README block with {first_line!r}: {len(found)} found"
    return found[0]


def _blob(n: int, sigma: float, amp: float = 4000.0) -> np.ndarray:
    yy, xx = np.mgrid[:n, :n] - n / 2
    return (amp * np.exp(-(yy**2 + xx**2) / (2 * sigma**2)) + 100).astype(np.uint16)


def test_python_api_example(rt, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exec(_block('cam = clfza.Camera.preset("simulation")'), {})
    out = capsys.readouterr().out
    assert "psnr" in out.lower() and "magnification" in out.lower()


def test_stack_example(rt, capsys):
    """The stack block: two frames solved as one batch."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exec(_block('sim = clfza.Camera.preset("simulation")'), {})
    assert capsys.readouterr().out.strip() == "(2, 512, 512) [2, 2]"


def test_measured_psf_example(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    tifffile.imwrite("psf.tif", _blob(64, 3.0))
    tifffile.imwrite("dark.tif", np.full((64, 64), 100, np.uint16))
    np.save("psfs.npy", np.stack([_blob(32, s) for s in (1.0, 1.5, 2.0, 3.0, 4.0)]))
    y = clfza.simulate(np.random.default_rng(0).random((16, 16)),
                       clfza.Camera(pitch=0.0075, shape=(32, 32), r1=0.05, z1=20.0, z2=3.0,
                                    R=None)).y
    ns = {"y": y}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exec(_block("from clfza.models import load_psf, load_psf_stack"), ns)
    assert ns["psf"].pitch == pytest.approx(0.0075) and ns["psf"].array.shape == (32, 32)
    assert len(ns["stack"]) == 5 and 0 <= ns["k"] < 5 and len(ns["scores"]) == 5


def test_real_camera_example_names_resolve(tmp_path, monkeypatch):
    """The exact-model block's calls, with the solve itself stubbed (it is an 800^2 frame)."""
    monkeypatch.chdir(tmp_path)
    tifffile.imwrite("psf.tif", _blob(64, 3.0))
    calls = []
    monkeypatch.setattr(clfza, "reconstruct",
                        lambda y, cam, method, **kw: calls.append((cam.shape, method, kw))
                        or (np.zeros(cam.shape), None))
    exec(_block('cam = clfza.Camera.preset("experiment")'),
         {"clfza": clfza, "frame_y": np.zeros((800, 800))})
    assert [c[1] for c in calls] == ["admm", "admm"] and calls[0][0] == (800, 800)
    assert isinstance(calls[1][2]["psf"], clfza.models.PSF)
