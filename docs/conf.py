"""Sphinx configuration of clfza's documentation site.

Build: ``pip install -e ".[docs]"`` then ``python -m sphinx -W -b html docs docs/_build/html``.

Generated at each build (git-ignored): ``api/*.rst`` (an autosummary page per subpackage, from
its public ``__all__``), ``performance/*.md`` (one page per ``bench/results/*.md`` with its
figures), ``auto_examples/`` (the gallery: ``examples/plot_*.py`` run at build time).
"""

from __future__ import annotations

import importlib
import inspect
import os
import re
import shutil
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")

import clfza  # noqa: E402

project = "clfza"
author = "the clfza authors"
copyright = "clfza authors, MIT licence"
version = release = clfza.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.doctest",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "sphinxarg.ext",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py",
                    "auto_examples/*.zip", "auto_examples/*.json", "auto_examples/*.md5",
                    "examples/README.rst", "examples/GALLERY_HEADER.rst", "README.md"]
templates_path = ["_templates"]

html_theme = "pydata_sphinx_theme"
html_title = f"clfza {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path = []
html_show_sourcelink = False

# API pages
autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"members": False}
autodoc_typehints = "none"  # numpydoc's Parameters sections say the types
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# Markdown: the design notes, measurements and logs of docs/*.md, the performance pages
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3
myst_ref_domains = ["std", "py"]  # not sphinx-argparse's, which reports every miss itself
suppress_warnings = [
    # docs/*.md and bench/results/*.md link files of the repository (bench/..., clfza/...,
    # README.md) that are not pages of this site; GitHub resolves them, Sphinx cannot
    "myst.xref_missing",
    # bench/results/*.md start at level-2 headings in places
    "myst.header",
]

# the examples gallery: each script runs at build time (a few seconds each, small cameras)
sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "abort_on_example_error": True,
    "show_memory": False,
    "plot_gallery": "True",
}

# ----- generated pages ---------------------------------------------------------------------
API_PACKAGES = [
    ("clfza", "The top-level API: the camera, simulation, reconstruction and the method options."),
    ("clfza.camera", None), ("clfza.simulation", None), ("clfza.models", None),
    ("clfza.solvers", None), ("clfza.reconstruction", None), ("clfza.focus", None),
    ("clfza.io", None), ("clfza.distributed", None), ("clfza.backends", None),
    ("clfza.cl", None), ("clfza.fft", None), ("clfza.metrics", None),
    ("clfza.denoisers", None),
]


def public_names(modname: str) -> list[str]:
    """A module's ``__all__``; for a module without one (clfza.simulation, clfza.metrics),
    its public functions and classes defined there."""
    mod = importlib.import_module(modname)
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n, v in vars(mod).items() if not n.startswith("_")
                 and getattr(v, "__module__", None) == modname
                 and (callable(v) or isinstance(v, type))]
    return sorted(n for n in names if not n.startswith("__"))


def write_api_pages() -> None:
    out = DOCS / "api"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    for modname, blurb in API_PACKAGES:
        mod = importlib.import_module(modname)
        lines = [f"``{modname}``", "=" * (len(modname) + 4), "",
                 f".. currentmodule:: {modname}", "",
                 f".. automodule:: {modname}", "   :no-members:", ""]
        if blurb:
            lines += [blurb, ""]
        kinds: dict[str, list[str]] = {"Classes": [], "Functions": [], "Constants": []}
        elsewhere: list[str] = []
        for n in public_names(modname):
            v = getattr(mod, n)
            home = owner(v)
            if home is not None and home != modname:  # documented on its own package's page
                there = f"{home}.{getattr(v, '__name__', n)}"  # clfza.ADMM: AdmmOptions
                elsewhere.append(f"* ``{modname}.{n}``: :py:obj:`{there}`")
                continue
            kind = ("Classes" if isinstance(v, type) else "Functions" if callable(v)
                    else "Constants")
            kinds[kind].append(n)
        for kind, names in kinds.items():
            if not names:
                continue
            lines += [kind, "-" * len(kind), ""]
            if kind == "Constants":
                for n in names:
                    lines += [f".. autodata:: {n}", "   :annotation:", ""]
                continue
            lines += [".. autosummary::", "   :toctree: generated", "   :nosignatures:", ""]
            lines += [f"   {n}" for n in names] + [""]
        if elsewhere:
            lines += ["From the subpackages", "-" * 20, ""] + elsewhere + [""]
        (out / f"{modname}.rst").write_text("\n".join(lines))


def owner(obj) -> str | None:
    """The listed package whose module defines ``obj`` (the longest prefix), if any."""
    mod = getattr(obj, "__module__", None) or ""
    hits = [m for m, _ in API_PACKAGES if m != "clfza" and (mod == m or mod.startswith(m + "."))]
    return max(hits, key=len) if hits and hasattr(getattr(importlib.import_module(
        max(hits, key=len)), getattr(obj, "__name__", ""), None), "__module__") else None


def write_performance_pages() -> None:
    """One page per bench/results/*.md, its figures beside it."""
    src = ROOT / "bench" / "results"
    out = DOCS / "performance"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    for md in sorted(src.glob("*.md")):
        text = md.read_text(encoding="utf-8")
        for img in re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", text):
            p = src / img
            if p.is_file():
                shutil.copy(p, out / p.name)
                text = text.replace(f"]({img})", f"]({p.name})")
        if not text.lstrip().startswith("# "):
            text = f"# {md.stem}\n\n{text}"
        text += (f"\n\n---\n\n*Source: `bench/results/{md.name}` (the JSON beside it holds the "
                 "raw numbers, the machine, the implementation and the date).*\n")
        (out / md.name).write_text(text, encoding="utf-8")
        for png in src.glob(md.stem + "*.png"):
            if not (out / png.name).exists() and png.name not in text:
                shutil.copy(png, out / png.name)
                (out / md.name).write_text(
                    (out / md.name).read_text() + f"\n![{png.stem}]({png.name})\n")


def write_design_notes() -> None:
    """docs/*.md at the site's root are pages themselves (myst-parser); nothing to copy."""


write_api_pages()
write_performance_pages()


# ----- cross-references: public names under their documented homes ------------------------
# The API pages document each object once, on its own subpackage's page
# (``clfza.reconstruction.reconstruct``); docstrings and pages also name it by its short
# public alias (``clfza.reconstruct``, ``clfza.ADMM``), by the private module that defines it
# (``clfza.models._exact.choose_model``), relative to the page's module (``ClfzaError`` on a
# ``clfza.focus`` page) or by a method of a documented class (``Camera.at_depth``: the class's
# members are not pages of their own). Those references resolve here to the page that
# documents the same object; a reference to something without a page still warns (nitpicky).
def _import_dotted(name: str):
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for p in parts[i:]:
                obj = getattr(obj, p)
        except AttributeError:
            return None
        return obj
    return None


_DOCUMENTED: dict[int, str] = {}


def _documented(env) -> dict[int, str]:
    """id(object) -> its documented name, for the modules, classes and functions with a page."""
    if not _DOCUMENTED:
        for name in env.get_domain("py").objects:
            obj = _import_dotted(name)
            if obj is not None and (isinstance(obj, type) or callable(obj)
                                    or inspect.ismodule(obj)):
                _DOCUMENTED.setdefault(id(obj), name)
    return _DOCUMENTED


def _home(obj, documented: dict[int, str]) -> str | None:
    if id(obj) in documented:
        return documented[id(obj)]
    if inspect.ismodule(obj):  # a private module: its public package's page
        name = obj.__name__
        while "._" in name:
            name = name.rsplit(".", 1)[0]
            pkg = importlib.import_module(name)
            if id(pkg) in documented:
                return documented[id(pkg)]
        return None
    owner = getattr(obj, "fget", obj)  # a method or property: its class's page
    qual = getattr(owner, "__qualname__", "")
    if "." in qual and "<" not in qual:
        cls = _import_dotted(f"{owner.__module__}.{qual.rsplit('.', 1)[0]}")
        if cls is not None and id(cls) in documented:
            return documented[id(cls)]
    return None


def _resolve_alias(app, env, node, contnode):
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip("~.")
    mod, cls = node.get("py:module"), node.get("py:class")
    candidates = [target]
    if mod and cls:
        candidates.append(f"{mod}.{cls}.{target}")
    if mod:
        # the page's module, the top level, and the package's private modules (where the
        # docstring was written: ``get_runtime`` in clfza.models._device_operator)
        candidates += [f"{mod}.{target}", f"clfza.{target}"]
        candidates += [f"{m}.{target}" for m in sorted(sys.modules) if m.startswith(mod + "._")]
    documented = _documented(env)
    for cand in candidates:
        obj = _import_dotted(cand)
        if "." in cand and not (isinstance(obj, type) or callable(obj) or inspect.ismodule(obj)
                                or isinstance(obj, property)):
            # an attribute or dataclass field of a documented class: the class's page
            head, attr = cand.rsplit(".", 1)
            owner = _import_dotted(head)
            if (isinstance(owner, type) and id(owner) in documented
                    and (hasattr(owner, attr) or attr in getattr(owner, "__annotations__", {}))):
                return env.get_domain("py").resolve_xref(
                    env, node["refdoc"], app.builder, "obj", documented[id(owner)], node,
                    contnode)
        if obj is None:
            continue
        if not (isinstance(obj, type) or callable(obj) or inspect.ismodule(obj)
                or isinstance(obj, property)):
            continue
        if isinstance(obj, property):
            obj = obj.fget
        home = _home(obj, documented)
        if home is not None and home != target:
            return env.get_domain("py").resolve_xref(env, node["refdoc"], app.builder, "obj",
                                                      home, node, contnode)
    return None


def setup(app):
    app.connect("missing-reference", _resolve_alias)
