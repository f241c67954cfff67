"""pyproject.toml's package list: every folder of clfza that ships files is a listed package,
and its data files match its package-data patterns, so a wheel (and ``pip install .``) holds
them and setuptools builds without its "Package ... is absent from the `packages`
configuration" warning (issue 36: a quiet first run starts at install)."""

from __future__ import annotations

import fnmatch
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]


def _config() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _folder(package: str, package_dir: dict) -> Path:
    for name in sorted(package_dir, key=len, reverse=True):
        if package == name or package.startswith(name + "."):
            rest = package[len(name):].lstrip(".")
            return ROOT / package_dir[name] / Path(*rest.split(".")) if rest else \
                ROOT / package_dir[name]
    return ROOT / Path(*package.split("."))


def _shipped_folders(top: Path) -> set[Path]:
    """Folders under ``top`` that hold files a user needs (not caches or build output)."""
    out = set()
    for f in top.rglob("*"):
        if f.is_file() and "__pycache__" not in f.parts and not f.name.endswith(".pyc"):
            out.add(f.parent)
    return out


def test_every_folder_that_ships_files_is_a_package():
    cfg = _config()
    folders = {_folder(p, cfg["package-dir"]) for p in cfg["packages"]}
    missing = sorted(str(d.relative_to(ROOT)) for d in _shipped_folders(ROOT / "clfza")
                     if d not in folders)
    assert not missing, f"folders of clfza absent from pyproject's packages: {missing}"


def test_data_files_match_package_data():
    cfg = _config()
    data = cfg["package-data"]
    for package in cfg["packages"]:
        folder = _folder(package, cfg["package-dir"])
        for f in folder.iterdir():
            if not f.is_file() or f.suffix in (".py", ".pyc"):
                continue
            pats = data.get(package, [])
            assert any(fnmatch.fnmatch(f.name, p) for p in pats), \
                f"{f.relative_to(ROOT)} is not in package-data {package!r} ({pats})"


def test_weights_are_package_data():
    """The DnCNN weights and their licence ship (clfza.denoisers loads them through
    importlib.resources from the installed package)."""
    data = _config()["package-data"]["clfza.denoisers.weights"]
    folder = ROOT / "clfza" / "denoisers" / "weights"
    names = [f.name for f in folder.iterdir() if f.is_file()]
    assert "LICENSE" in names and any(n.endswith(".npz") for n in names)
    for n in names:
        assert any(fnmatch.fnmatch(n, p) for p in data), n
