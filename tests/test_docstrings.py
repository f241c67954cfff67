"""Every docstring example of the package runs and prints what it shows (the API reference
renders them; the suite is where they would otherwise rot unseen)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import clfza


def _modules() -> list[str]:
    names = [clfza.__name__]
    for info in pkgutil.walk_packages(clfza.__path__, prefix="clfza."):
        names.append(info.name)
    return sorted(names)


def _examples(name: str) -> list[doctest.DocTest]:
    module = importlib.import_module(name)
    tests = doctest.DocTestFinder().find(module, name)
    return [t for t in tests if t.examples]


MODULES = [m for m in _modules() if not m.endswith("__main__") and _examples(m)]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # an example that writes a file writes it here
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for test in _examples(name):
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"
