"""Sphinx configuration of the compact-distributions site.

Build (warnings are errors): ``sphinx-build -W -b html docs OUT`` after
``pip install -e ".[all,docs]"``.  The pages under ``_generated/`` (the commands'
reference, result.json, the reports, the method records) are written at build time
by ``_ext/cd_docs.py`` from the parsers, the shipped schema and ``reports/*.csv``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))

import compact_distributions  # noqa: E402

project = "compact-distributions"
author = "the compact-distributions authors"
copyright = "2019-2026, the compact-distributions authors (MIT)"
release = compact_distributions.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.intersphinx",
    "numpydoc",
    "myst_parser",
    "sphinx_design",
    "sphinx_copybutton",
    "sphinx_gallery.gen_gallery",
    "cd_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "generated", "examples", "auto_examples/*.ipynb", "auto_examples/*.py"]
templates_path = ["_templates"]
html_static_path = ["_static"]
html_css_files = ["cd.css"]

# -- MyST ------------------------------------------------------------------
myst_enable_extensions = ["colon_fence", "dollarmath", "deflist", "attrs_inline"]
myst_heading_anchors = 3

# -- autodoc, autosummary, numpydoc ------------------------------------------
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"  # numpydoc writes the types into the parameter lists too
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
# numpydoc validates the declared API (the names of compact_distributions.__all__, their
# members, and the Shape record) with the checks below; a failing check is a warning, so
# -W fails the build on it.  CD_NUMPYDOC_CHECKS (comma-separated codes, or "all") widens
# or narrows the set without editing this file.
# Until the declared API's numpydoc docstrings land (the typed-API issue), the default set
# is empty; then it becomes "GL08,PR01,PR02,PR03,PR06,RT03" (every parameter documented,
# none unknown, a type for each, a described return value, a docstring on every member).
NUMPYDOC_CHECKS = ""
numpydoc_validation_checks = set(os.environ.get("CD_NUMPYDOC_CHECKS", NUMPYDOC_CHECKS).split(",")) - {""}
numpydoc_validation_exclude = {
    # everything documented under a subpackage path, except the Shape record
    r"^compact_distributions\.(?!cvt\.metrics\.Shape\b)(cvt|backends|baselines|bench)\.",
    r"\.__init__$",
    r"\.__call__$",
    r"\.__post_init__$",
    r"\._[a-z]",  # private members
}

# -- intersphinx: only what the site's own builds reach without the network ---
intersphinx_mapping: dict = {}

# -- sphinx-gallery ---------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": ["examples"],
    "gallery_dirs": ["auto_examples"],
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "image_scrapers": ("matplotlib",),
    "remove_config_comments": True,
    "download_all_examples": False,
    "show_signature": False,
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "plot_gallery": "True",
    "reference_url": {},
    "matplotlib_animations": False,
    "capture_repr": (),
}

# -- HTML ------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = "compact-distributions"
html_theme_options = {
    "navbar_align": "left",
    "show_toc_level": 2,
    "navigation_with_keys": False,
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
    "secondary_sidebar_items": ["page-toc"],
}
html_sidebars = {"index": []}
html_show_sourcelink = False
html_last_updated_fmt = None
