"""The code base stays ruff clean (configuration in pyproject.toml)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_clean():
    ruff = shutil.which("ruff") or str(Path(sys.executable).parent / "ruff")
    if not Path(ruff).exists():
        pytest.skip("ruff is not installed (pip install -e '.[test]')")
    targets = [d for d in ("clfza", "tests", "bench") if (ROOT / d).is_dir()]
    res = subprocess.run([ruff, "check", *targets], cwd=ROOT,
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_package_structure_clean():
    """tools/check_structure.py (issue 32): no import cycle, no private name or private module
    imported across packages, function-level imports only with a '# lazy:' reason, at most 17
    top-level entries in clfza/."""
    res = subprocess.run([sys.executable, str(ROOT / "tools" / "check_structure.py"), str(ROOT)],
                         cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.strip() == "structure: clean"


def test_structure_check_finds_a_cycle_and_a_private_import(tmp_path):
    """The check itself fails on what it forbids (a two-module cycle through a package
    ``__init__``, a private name imported across modules, an unexplained lazy import)."""
    pkg = tmp_path / "clfza" / "a"
    pkg.mkdir(parents=True)
    (tmp_path / "clfza" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("from ._x import f\n")
    (pkg / "_x.py").write_text("from ..b import g\n\ndef f():\n    return g\n")
    (tmp_path / "clfza" / "b.py").write_text(
        "from .a._x import _hidden\n\ndef g():\n    import json\n    from . import a\n"
        "    return a, json, _hidden\n")
    res = subprocess.run([sys.executable, str(ROOT / "tools" / "check_structure.py"),
                          str(tmp_path)], capture_output=True, text=True)
    assert res.returncode == 1
    out = res.stdout
    assert "import cycle" in out and "clfza.a" in out and "clfza.b" in out
    assert "private name _hidden" in out and "a private module of clfza.a" in out
    assert "function-level import of json without a '# lazy:' reason" in out
