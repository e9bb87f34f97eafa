"""Every code block of the README and of the documentation's pages runs as written, in order,
in a folder laid out like the project (see ``code_blocks.py``): the files a block names ship
with the project or are made by an earlier block on the same page."""
from __future__ import annotations

import glob
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from code_blocks import check_languages, collect, parse, run_blocks  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _pages() -> list[str]:
    """README.md and the docs' own pages (not those the build writes: docs/benchmarks/ holds
    copies of benchmarks/results/, docs/_build/ the site)."""
    pages = [os.path.join(ROOT, "README.md")]
    generated = [os.path.join(ROOT, "docs", d) + os.sep for d in ("_build", "benchmarks")]
    pages += sorted(p for p in glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True)
                    if not p.startswith(tuple(generated)))
    return pages


def _name(page: str) -> str:
    return os.path.relpath(page, ROOT)


def _runnable(page: str) -> bool:
    from code_blocks import RUN
    return any(b.lang in RUN and b.skip is None for b in collect(page))


PAGES = _pages()
# Pages whose blocks take more than ~10 s (the gallery renders seven scenes at full size, the
# fitting page fits, the batch page renders 36 frames) run with `make test-all`; the others
# (about 15 s together) in the default suite.
HEAVY = {os.path.join("docs", "gallery.md"), os.path.join("docs", "guides", "fitting.md"),
         os.path.join("docs", "guides", "batch.md")}
RUNNABLE = [pytest.param(p, marks=[pytest.mark.slow] if _name(p) in HEAVY else [])
            for p in PAGES if _runnable(p)]


@pytest.mark.parametrize("page", PAGES, ids=_name)
def test_each_block_is_code_parsed_or_declared_text(page):
    """An unknown fence language, a ``not run`` marker without a reason, or a TOML/JSON block
    that does not parse (a typo in a documented scene) fails here."""
    blocks = collect(page, _name(page))
    check_languages(blocks)
    for b in blocks:
        if b.lang in ("toml", "json") and b.skip is None:
            parse(b)


@pytest.mark.parametrize("page", RUNNABLE, ids=_name)
def test_the_pages_blocks_run(page, tmp_path):
    """The page's Python and shell blocks run in order without an error (a snippet naming a file
    that does not ship, or an API it calls that changed, fails here and names the block)."""
    blocks = collect(page, _name(page))
    go_draaw = os.path.normpath(os.path.join(ROOT, "..", "shared", "data", "go-draaw"))
    if not os.path.isdir(go_draaw):         # GO-Draaw's data is not shipped: its blocks wait for it
        for b in blocks:
            if "shared/data/go-draaw" in b.code and b.skip is None:
                b.skip = f"GO-Draaw's data is not at {go_draaw}"
    r = run_blocks(blocks, str(tmp_path), ROOT)
    assert r.returncode == 0 and "ALL BLOCKS RAN" in r.stdout, (r.stdout[-3000:] + r.stderr[-3000:])


def test_the_runner_reports_the_block_that_fails(tmp_path):
    """The runner itself: a later block sees an earlier one's names and files; a failing Python
    block and a failing shell command each stop the run naming their line; a marked block is
    not run."""
    page = tmp_path / "page.md"
    page.write_text(
        "```python\nx = 41\nopen('made.txt', 'w').write('ok')\n```\n\n"
        "```sh\ntest -s made.txt\n```\n\n"
        "<!-- not run: shows a failure -->\n```python\nraise SystemExit(9)\n```\n\n"
        "```python\nassert x == 41\nraise RuntimeError('boom')\n```\n", encoding="utf-8")
    r = run_blocks(collect(str(page), "page.md"), str(tmp_path / "a"), ROOT, timeout=120)
    assert r.returncode == 1 and "FAILED page.md:15" in r.stdout, r.stdout + r.stderr
    assert "RuntimeError: boom" in r.stderr and "=== page.md:11" not in r.stdout

    page.write_text("```sh\ntrue\nfalse\necho never\n```\n", encoding="utf-8")
    r = run_blocks(collect(str(page), "page.md"), str(tmp_path / "b"), ROOT, timeout=120)
    assert r.returncode == 1 and "FAILED page.md:1: exit status 1" in r.stdout
    assert "never" not in r.stdout


def test_the_collector_refuses_unmarked_unknown_languages_and_empty_reasons(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("```ruby\nputs 1\n```\n", encoding="utf-8")
    with pytest.raises(ValueError, match="'ruby' is neither run nor parsed"):
        check_languages(collect(str(page)))
    page.write_text("<!-- not run: -->\n```python\npass\n```\n", encoding="utf-8")
    with pytest.raises(ValueError, match="needs a reason"):
        collect(str(page))
    page.write_text("```toml\n[render\nspp = 4\n```\n", encoding="utf-8")
    with pytest.raises(AssertionError, match="page.md:1: the toml block does not parse"):
        parse(collect(str(page), "page.md")[0])
