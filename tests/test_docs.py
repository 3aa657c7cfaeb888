"""The documentation site: the Extending guide's plug-in, and the built site itself.

The plug-in example (``docs/extending/cvt_plugin_example.py``, the very file the guide
shows) is imported from a temporary folder and run through the registry's
``records_of``, as its entry point would be; nothing is installed.

The built site is read from ``CD_DOCS_HTML`` (default ``docs/_build/html``; ``.ci/run``
builds it there with ``sphinx-build -W``); the tests that need it skip, with the reason,
where it is missing.  Every HTML file is parsed and each internal link (its file, and the
anchor it names) and each image, stylesheet and script is checked to exist.  Then the
index, an API page and a gallery page are opened in headless Chromium (``CD_CHROMIUM``,
else ``chromium`` on the PATH; skipped where there is none) from a local HTTP server: a
checking page loads each into a frame, loads every image of it again and fetches every
internal link, waits for MathJax to typeset the formulas, and Chromium prints the result
with ``--dump-dom``.  The measures page is opened too: its formulas must be typeset.
"""

from __future__ import annotations

import functools
import html.parser
import http.server
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import threading
import zlib
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np
import pytest

import compact_distributions as cd
from compact_distributions.cvt.registry import records_of

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
SITE = Path(os.environ.get("CD_DOCS_HTML", DOCS / "_build" / "html"))

__all__: list[str] = []


# ---------------------------------------------------------------- the plug-in example
@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    """The guide's plug-in module, imported from a copy in a temporary folder."""
    folder = tmp_path_factory.mktemp("plugin")
    shutil.copy(DOCS / "extending" / "cvt_plugin_example.py", folder)
    spec = importlib.util.spec_from_file_location("cvt_plugin_example", folder / "cvt_plugin_example.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["cvt_plugin_example"] = module
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop("cvt_plugin_example", None)


def test_the_guide_shows_the_example_files():
    page = (DOCS / "extending" / "index.md").read_text()
    assert "{literalinclude} cvt_plugin_example.py" in page and "{literalinclude} pyproject.toml" in page
    toml = (DOCS / "extending" / "pyproject.toml").read_text()
    assert 'shrunk = "cvt_plugin_example:METHOD"' in toml
    assert 'brute = "cvt_plugin_example:BruteBackend"' in toml


def test_plugin_method_goes_through_the_registry(plugin):
    (record,) = records_of(plugin.METHOD, "shrunk")
    assert record.name == "shrunk" and [o.flag for o in record.options] == ["--shrink"]
    assert record.parse_options({"shrink": "0.5"}) == {"shrink": 0.5}
    with pytest.raises(cd.InputError, match="shrink"):
        record.parse_options({"shrink": 1.5})  # the option's own check: 0 < shrink <= 1


def test_plugin_method_and_backend_run(plugin):
    """Its backend labels as the NumPy reference does, and its method scales ours'
    elements by ``shrink`` (areas by shrink²) about their centres."""
    (record,) = records_of(plugin.METHOD, "shrunk")
    problem = cd.problem(n_elements=24, size=48, element="square", seed=3)
    with plugin.BruteBackend() as brute, cd.create_backend("numpy") as reference:
        ours = cd.run(problem, "ours", backend=reference, iterations=4)
        mine = cd.run(problem, record, backend=brute, iterations=4, shrink=0.5)
        sites = ours.distribution.sites
        grid = problem.grid
        np.testing.assert_array_equal(
            brute.label(sites, metric=problem.metric, grid=grid),
            reference.label(sites, metric=problem.metric, grid=grid),
        )
    assert mine.method == "shrunk" and mine.method_options == {"shrink": 0.5}
    np.testing.assert_allclose(mine.distribution.sites, ours.distribution.sites)
    for a, b in zip(ours.elements, mine.elements, strict=True):
        assert (a is None) == (b is None)
        if a is not None:
            assert b.area == pytest.approx(0.25 * a.area, rel=1e-9)
            assert b.centroid.distance(a.centroid) < 1e-9
    assert mine.coverage == pytest.approx(0.25 * ours.coverage, rel=1e-6)


# ---------------------------------------------------------------- the built site
def _site():
    if not (SITE / "index.html").is_file():
        pytest.skip(
            f"no built site at {SITE} (build it: sphinx-build -W -b html docs {SITE}; or set CD_DOCS_HTML)"
        )
    return SITE


class _Page(html.parser.HTMLParser):
    """The ids of an HTML page and the URLs it refers to."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.refs: list[tuple[str, str]] = []  # (tag, url)

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        for key in ("id", "name") if tag == "a" else ("id",):
            if attrs.get(key):
                self.ids.add(attrs[key])
        url = {"a": "href", "link": "href", "img": "src", "script": "src", "source": "src"}.get(tag)
        if url and attrs.get(url):
            self.refs.append((tag, attrs[url]))


@functools.lru_cache(maxsize=None)
def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8", errors="replace"))
    return page


def _internal(url: str) -> bool:
    parts = urlsplit(url)
    return not parts.scheme and not parts.netloc and not url.startswith(("mailto:", "javascript:", "data:"))


def test_every_internal_link_and_image_of_the_site_resolves():
    site = _site()
    # the pages, not the theme's templates under _static
    pages = sorted(p for p in site.rglob("*.html") if not p.relative_to(site).parts[0].startswith("_static"))
    assert len(pages) > 30, f"only {len(pages)} pages in {site}"
    broken, checked = [], 0
    for path in pages:
        for tag, url in _parse(path).refs:
            if not _internal(url):
                continue
            parts = urlsplit(url)
            target = (path.parent / unquote(parts.path)).resolve() if parts.path else path
            if target.is_dir():
                target = target / "index.html"
            checked += 1
            if not target.is_file():
                broken.append(f"{path.relative_to(site)}: <{tag}> {url} (no file)")
            elif (
                parts.fragment
                and target.suffix == ".html"
                and unquote(parts.fragment) not in _parse(target).ids
            ):
                broken.append(f"{path.relative_to(site)}: <{tag}> {url} (no anchor)")
    assert checked > 1000, f"only {checked} internal references found"
    assert not broken, f"{len(broken)} broken of {checked}:\n" + "\n".join(broken[:40])


def _inventory(site: Path) -> set[str]:
    """The names of the Python objects the site documents (its objects.inv)."""
    data = (site / "objects.inv").read_bytes()
    header_end = 0
    for _ in range(4):  # four header lines, then the zlib-compressed body
        header_end = data.index(b"\n", header_end) + 1
    body = zlib.decompress(data[header_end:]).decode()
    return {line.split(" ", 1)[0] for line in body.splitlines() if " py:" in line}


def test_every_declared_name_has_an_index_entry():
    site = _site()
    documented = _inventory(site)
    index = _parse(site / "genindex.html")
    targets = {unquote(urlsplit(url).fragment) for tag, url in index.refs if tag == "a"}
    missing = [n for n in cd.__all__ if f"compact_distributions.{n}" not in documented]
    unindexed = [n for n in cd.__all__ if f"compact_distributions.{n}" not in targets]
    assert not missing, f"not documented: {missing}"
    assert not unindexed, f"not in genindex.html: {unindexed}"
    assert "compact_distributions.cvt.metrics.Shape" in documented  # the fifth record


def test_the_gallery_holds_eight_executed_examples_with_pictures():
    site = _site()
    pages = sorted((site / "auto_examples").glob("plot_*.html"))
    assert len(pages) >= 8, [p.name for p in pages]
    for page in pages:
        images = [url for tag, url in _parse(page).refs if tag == "img" and "sphx_glr_" in url]
        assert images, f"{page.name} has no picture"
        for url in images:
            assert (page.parent / url).stat().st_size > 2000, f"{page.name}: {url} is empty"


@pytest.mark.parametrize("page, csv", [("table2", "table2.csv"), ("table3", "table3.csv")])
def test_each_report_row_links_its_method_to_its_api_entry_and_paper(page, csv):
    """One link to the method's callable and one to its paper per row of the CSV (the
    link test above checks that their anchors exist)."""
    import pandas as pd

    site = _site()
    rows = pd.read_csv(ROOT / "reports" / csv)
    rows = rows[rows["status"].isin(["ok", "partial"])]
    hrefs = [url for tag, url in _parse(site / "reports" / f"{page}.html").refs if tag == "a"]
    api = [h for h in hrefs if "methods.html#compact_distributions." in h]
    paper = [h for h in hrefs if "methods.html#method-" in h]
    assert len(api) == len(rows) and len(paper) == len(rows), (len(api), len(paper), len(rows))
    named = {urlsplit(h).fragment.removeprefix("method-") for h in paper}
    assert named == {m.split(" ")[0] for m in rows["method"]}


def test_commands_reference_holds_every_option_of_every_parser():
    """The generated reference names every option string of every subparser (but the
    hidden ones: an old name kept for a release)."""
    import argparse

    from compact_distributions.bench.commands.cli import build_parser

    site = _site()
    text = (site / "guide" / "commands.html").read_text(encoding="utf-8")
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    missing = [
        f"{name} {flag}"
        for name, p in sub.choices.items()
        for action in p._actions
        for flag in action.option_strings
        if flag.startswith("--") and action.help != argparse.SUPPRESS and f"{flag}" not in text
    ]
    assert f'id="cmd-{next(iter(sub.choices))}"' in text
    assert not missing, missing


# ---------------------------------------------------------------- headless Chromium
CHECK_PAGE = """<!doctype html><html><head><meta charset="utf-8"></head><body>
<pre id="result">pending</pre>
<script>
const page = new URLSearchParams(location.search).get("page");
const frame = document.createElement("iframe");
frame.style.width = "1400px";
frame.style.height = "4000px";
const pause = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
frame.onload = async () => {
  const doc = frame.contentDocument;
  // MathJax typesets after the load event: wait (at most 10 s) for every formula
  const formulas = doc.querySelectorAll(".math").length;
  for (let k = 0; k < 100 && doc.querySelectorAll("mjx-container").length < formulas; k++) await pause(100);
  const probe = (src) => new Promise((resolve) => {
    const img = new Image();
    img.onload = () => resolve({src, ok: img.naturalWidth > 0});
    img.onerror = () => resolve({src, ok: false});
    img.src = src;
  });
  const images = await Promise.all(Array.from(doc.images).map((img) => probe(img.currentSrc || img.src)));
  const hrefs = Array.from(new Set(Array.from(doc.querySelectorAll("a[href]"))
    .map((a) => a.href.split("#")[0]).filter((h) => h.startsWith(location.origin))));
  const links = await Promise.all(hrefs.map((h) => fetch(h).then((r) => ({href: h, status: r.status}))
    .catch(() => ({href: h, status: 0}))));
  const heading = doc.querySelector("h1");
  const main = doc.querySelector("main") || doc.body;
  document.getElementById("result").textContent = JSON.stringify({
    title: doc.title,
    h1: heading ? heading.textContent.trim() : null,
    text: main.innerText.length,
    width: doc.documentElement.scrollWidth,
    styled: getComputedStyle(doc.body).fontFamily,
    formulas, typeset: doc.querySelectorAll("mjx-container").length,
    images, links,
  });
};
frame.src = page;
document.body.appendChild(frame);
</script></body></html>"""


def _chromium() -> str:
    for name in (os.environ.get("CD_CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and shutil.which(name):
            return shutil.which(name)
    pytest.skip("no Chromium (set CD_CHROMIUM, or apt-get install chromium)")


@pytest.fixture(scope="module")
def served():
    """The built site on a local HTTP server, with the checking page beside it."""
    site = _site()

    class Handler(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, directory=str(site), **kwargs)

        def do_GET(self):  # noqa: N802 (http.server's name)
            if self.path.startswith("/__check__.html"):
                body = CHECK_PAGE.encode()
                self.send_response(200)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)
                return
            super().do_GET()

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


def _open_in_chromium(base: str, page: str, tmp_path: Path) -> tuple[dict, str]:
    chromium = _chromium()
    done = subprocess.run(
        [
            chromium,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--virtual-time-budget=20000",
            "--enable-logging=stderr",
            "--v=0",
            "--dump-dom",
            f"{base}/__check__.html?page=/{page}",
        ],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    start = done.stdout.index('<pre id="result">') + len('<pre id="result">')
    text = html.unescape(done.stdout[start : done.stdout.index("</pre>", start)])
    assert text != "pending", f"the checking page did not finish on {page}"
    return json.loads(text), done.stderr


@pytest.mark.parametrize(
    "page, heading, pictured",
    [
        ("index.html", "compact-distributions", True),
        ("api/_autosummary/compact_distributions.run.html", "compact_distributions.run", False),
        ("auto_examples/plot_mosaic_edges.html", "A photograph to a mosaic, with its edges", True),
        ("guide/measures.html", "fidelity measures", False),
    ],
)
def test_page_renders_in_chromium_with_no_broken_image_or_link(served, page, heading, pictured, tmp_path):
    result, log = _open_in_chromium(served, page, tmp_path)
    assert result["h1"] and heading in result["h1"], result["h1"]
    assert result["text"] > 200, "the page's main part is (nearly) empty"
    assert "sans" in result["styled"].lower(), f"the theme's stylesheet did not apply: {result['styled']}"
    assert result["images"] or not pictured, f"{page}: no image"
    broken = [i["src"] for i in result["images"] if not i["ok"]]
    assert not broken, f"{page}: broken images {broken}"
    dead = [link for link in result["links"] if link["status"] != 200]
    assert result["links"] and not dead, f"{page}: dead links {dead}"
    # formulas are typeset by the MathJax the site serves itself (no network)
    assert result["typeset"] >= result["formulas"], (
        f"{result['typeset']} of {result['formulas']} formulas typeset"
    )
    errors = [line for line in log.splitlines() if "Uncaught" in line]
    assert not errors, errors
