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
    "sphinx-mathjax-offline",  # MathJax 3 served from the site itself: formulas render offline
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
# members, and the Shape record) as tests/test_api_docs.py does: every check but those
# that test ignores (its IGNORED) and EX01 (that test runs the top-level examples itself;
# members need none), on every name but those it marks pending (its PENDING).  A failing
# check is a warning, so -W fails the build on it.  Where that test is absent (before the
# typed-API change), nothing is validated and the build says so.  CD_NUMPYDOC_CHECKS
# (comma-separated codes; "all,CODE,..." means all but those) overrides the set.
API_DOCS_TEST = ROOT / "tests" / "test_api_docs.py"


def _api_docs_policy() -> tuple[set[str], set[str]]:
    """(the checks tests/test_api_docs.py ignores, the names it marks pending)."""
    import ast

    values = {}
    for node in ast.parse(API_DOCS_TEST.read_text()).body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            target = node.targets[0] if isinstance(node, ast.Assign) else node.target
            if isinstance(target, ast.Name) and target.id in ("IGNORED", "PENDING"):
                values[target.id] = ast.literal_eval(node.value)
    return set(values["IGNORED"]), set(values["PENDING"])


if API_DOCS_TEST.exists():
    _ignored, _pending = _api_docs_policy()
    NUMPYDOC_CHECKS = ",".join(["all", *sorted(_ignored | {"EX01"})])
else:
    _pending = set()
    NUMPYDOC_CHECKS = ""
    print("numpydoc validation off: tests/test_api_docs.py (the declared API's policy) is absent")
numpydoc_validation_checks = set(os.environ.get("CD_NUMPYDOC_CHECKS", NUMPYDOC_CHECKS).split(",")) - {""}
numpydoc_validation_exclude = {
    # everything documented under a subpackage path, except the Shape record
    r"^compact_distributions\.(?!cvt\.metrics\.Shape\b)(cvt|backends|baselines|bench)\.",
    # MosaicResult's own members: the API test checks the record, not them
    r"^compact_distributions\.MosaicResult\.",
    *(rf"^compact_distributions\.(cvt\.metrics\.)?{name}$" for name in _pending),
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
