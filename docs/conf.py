"""Sphinx configuration of overcon's documentation (built by
``sphinx-build -W -n -b html docs docs/_build/html``; .ci/run does, warnings as errors).

MyST reads the Markdown pages, sphinx-argparse generates the CLI reference from
``overcon.cli.build_parser`` and autodoc the Python API from ``overcon.__all__``."""
from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "fmu_src"))  # a source tree that is installed editable finds it anyway

import overcon  # noqa: E402

project = "overcon"
author = "the overcon developers"
release = version = overcon.__version__

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.mathjax", "sphinxarg.ext"]
source_suffix = {".md": "markdown"}
master_doc = root_doc = "index"
exclude_patterns = ["_build", "**/_build", "examples/*.md"]
myst_heading_anchors = 4
myst_enable_extensions = ["colon_fence"]
html_theme = "furo"
html_title = f"overcon {release}"
autodoc_typehints = "description"
autodoc_member_order = "bysource"
# Python names in docstrings that are not pages of this site (internal modules, numpy, pathlib):
# nitpicky mode checks the site's own links (pages, headings), not those.
nitpick_ignore_regex = [(r"py:.*", r".*")]

OPTIONAL_PAGES = ("coupling", "platforms", "limits", "untrusted-input")
"""Pages the index lists that arrive with other work (docs/<name>.md): an entry whose page does
not exist yet is dropped from the index before it is parsed, so the site builds with and without
them (a toctree entry of a missing page would be a warning, and warnings are errors here)."""


def _optional_pages(app, docname, source):
    if docname == "index":
        for name in OPTIONAL_PAGES:
            if not (HERE / f"{name}.md").is_file():
                source[0] = source[0].replace(f"\n{name}\n", "\n")


def setup(app):
    app.connect("source-read", _optional_pages)
os.environ.setdefault("COLUMNS", "100")  # argparse's help text width in the CLI reference
