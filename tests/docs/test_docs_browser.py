"""The documentation site in a real browser (slow): Debian's Chromium through Playwright.

The site is built into a temporary folder (``sphinx-build -W -n``, as ``make docs``) and served
on 127.0.0.1; Chromium opens the home page, a user guide, the API page, the plugin reference
and a tutorial, and each must load without a console error, a page error or a failed request
(nothing may be fetched from outside the machine). The search page must find "roughness", and
the tutorial's images (stored notebook outputs) must be decoded, not broken. Screenshots are
kept in ``out/test-artifacts/docs-*.png``. Skipped, with the reason, when Playwright, Chromium
or Sphinx is missing (``make test-all`` installs the ``browser`` extra; ``apt-get install
chromium``).
"""
from __future__ import annotations

import functools
import http.server
import os
import shutil
import subprocess
import sys
import threading

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DOCS = os.path.join(ROOT, "docs")
ARTEFACTS = os.path.join(ROOT, "out", "test-artifacts")
CHROMIUM = "/usr/bin/chromium"
PAGES = {"index": "index.html", "guide": "guides/versions.html", "api": "api/index.html",
         "plugins": "reference/plugins.html", "tutorial": "tutorials/sdf_csg.html"}

pytestmark = pytest.mark.slow


def _chromium() -> str:
    path = CHROMIUM if os.path.exists(CHROMIUM) else shutil.which("chromium")
    if not path:
        pytest.skip(f"Chromium is not installed ({CHROMIUM} missing): apt-get install chromium")
    return path


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """Build the site and serve it on a free port of 127.0.0.1: yields the base URL."""
    pytest.importorskip("sphinx", reason="Sphinx is not installed (pip install -e '.[docs]')")
    pytest.importorskip("myst_nb", reason="myst-nb is not installed (pip install -e '.[docs]')")
    out = tmp_path_factory.mktemp("docs") / "html"
    r = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-q", "-b", "html",
                        DOCS, str(out)], capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    handler = functools.partial(_QuietHandler, directory=str(out))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture(scope="module")
def browser():
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="Playwright is not installed (pip install -e '.[browser]')")
    chromium = _chromium()
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium, args=["--no-sandbox", "--disable-gpu"])
        try:
            yield b
        finally:
            b.close()


def _open(browser, url: str, shot: str):
    """Open ``url``; returns (page, problems) with every console error, page error and failed
    request seen while it loaded, and saves a screenshot as ``shot``."""
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    problems = []
    page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
    page.on("requestfailed", lambda q: problems.append(f"request failed: {q.url} ({q.failure})"))
    page.on("response", lambda q: problems.append(f"HTTP {q.status}: {q.url}") if q.status >= 400 else None)
    page.goto(url, wait_until="networkidle")
    os.makedirs(ARTEFACTS, exist_ok=True)
    page.screenshot(path=os.path.join(ARTEFACTS, f"docs-{shot}.png"), full_page=False)
    return page, problems


@pytest.mark.parametrize("name", sorted(PAGES))
def test_page_loads_without_console_errors(served, browser, name):
    page, problems = _open(browser, f"{served}/{PAGES[name]}", name)
    try:
        assert not problems, problems
        assert page.title() and "draaw-mi" in page.title()
        assert page.locator("article h1").count() >= 1
    finally:
        page.close()


def test_tutorial_images_are_shown(served, browser):
    """The stored outputs' figures are decoded images of real size, not broken icons."""
    page, problems = _open(browser, f"{served}/{PAGES['tutorial']}", "tutorial-images")
    try:
        assert not problems, problems
        sizes = page.eval_on_selector_all(
            "article img", "imgs => imgs.map(i => [i.complete, i.naturalWidth, i.naturalHeight])")
        assert len(sizes) >= 2, sizes
        assert all(done and w > 16 and h > 16 for done, w, h in sizes), sizes
    finally:
        page.close()


def test_search_finds_roughness(served, browser):
    page, problems = _open(browser, f"{served}/search.html?q=roughness", "search")
    try:
        page.wait_for_selector("ul.search li", timeout=30_000)
        hits = page.locator("ul.search li").count()
        assert hits >= 3, hits
        page.screenshot(path=os.path.join(ARTEFACTS, "docs-search.png"))
        assert not problems, problems
    finally:
        page.close()
