"""Collect the fenced code blocks of a Markdown page and run them as a reader would.

A page's blocks run in order, in one Python interpreter (a ``python`` block sees the names of
the ones before it) with its shell blocks (``sh``, ``bash``, ``console``) run by bash in
between, all in one folder laid out like the project's: ``scenes/`` and ``notebooks/`` (and ``.venv``) of
the project, and ``../shared/data/go-draaw`` beside it (GO-Draaw's files, not shipped) when this
machine has them. So a block may use what an earlier block wrote (``out/cornell.exr``).
``toml`` and ``json`` blocks are parsed. ``text`` blocks (command synopses, output) are not code.

A block that cannot run as written says why in an HTML comment on the line before its fence::

    <!-- not run: make runs the whole set-up; CI runs `make test` itself -->

A marker without a reason is an error, as is an unknown language: a block is run, parsed or
declared ``text``.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tomllib
from dataclasses import dataclass

RUN = {"python": "python", "py": "python", "sh": "sh", "bash": "sh", "console": "sh", "shell": "sh"}
PARSED = {"toml", "json"}
NOT_CODE = {"text", "none", "output"}
_FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>```+|~~~+)(?P<info>[^\n`]*)$")
_MARKER = re.compile(r"^\s*<!--\s*not run:(?P<reason>.*?)-->\s*$")


@dataclass
class Block:
    """One fenced block: its page, the line of its opening fence, language, text and, when it is
    not run, why."""
    page: str
    line: int
    lang: str
    code: str
    skip: str | None = None

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def collect(path: str, name: str | None = None) -> list[Block]:
    """The fenced blocks of the Markdown file ``path`` (MyST directives such as ``{code-cell}``
    or ``{eval-rst}`` count by their first word)."""
    name = name or path
    lines = open(path, encoding="utf-8").read().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, info = m.group("fence"), m.group("info").strip()
        lang = info.split()[0].lower() if info else ""
        body, j = [], i + 1
        while j < len(lines) and not lines[j].strip().startswith(fence):
            body.append(lines[j][len(m.group("indent")):])
            j += 1
        skip = None
        if i > 0 and (mk := _MARKER.match(lines[i - 1])):
            skip = mk.group("reason").strip()
            if not skip:
                raise ValueError(f"{name}:{i}: a 'not run' marker needs a reason")
        if lang.startswith("{"):
            lang = "directive"
        blocks.append(Block(name, i + 1, lang, "\n".join(body) + "\n", skip))
        i = j + 1
    return blocks


def check_languages(blocks: list[Block]) -> None:
    """Every block is run, parsed, declared not code, or a MyST directive."""
    known = set(RUN) | PARSED | NOT_CODE | {"directive"}
    for b in blocks:
        if b.lang not in known:
            raise ValueError(f"{b.where}: code block language {b.lang!r} is neither run nor parsed; "
                             f"expected one of {sorted(known)} (use 'text' for a synopsis)")


def parse(block: Block) -> None:
    """Parse a ``toml`` or ``json`` block; a syntax error names the block."""
    try:
        if block.lang == "toml":
            tomllib.loads(block.code)
        else:
            json.loads(block.code)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as e:
        raise AssertionError(f"{block.where}: the {block.lang} block does not parse: {e}") from None


_DRIVER = r'''
import json, os, subprocess, sys, traceback
blocks = json.load(open(sys.argv[1], encoding="utf-8"))
ns = {"__name__": "__main__"}
env = dict(os.environ, PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ["PATH"])
for b in blocks:
    print(f"=== {b['where']} ({b['lang']})", flush=True)
    if b["lang"] == "python":
        try:
            exec(compile(b["code"], b["where"], "exec"), ns)
        except BaseException:
            traceback.print_exc()
            print(f"FAILED {b['where']}", flush=True)
            sys.exit(1)
    else:
        r = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", b["code"]], env=env)
        if r.returncode != 0:
            print(f"FAILED {b['where']}: exit status {r.returncode}", flush=True)
            sys.exit(1)
print("ALL BLOCKS RAN", flush=True)
'''


def project_like_folder(tmp: str, root: str) -> str:
    """A working folder in ``tmp`` laid out like the project (links to its ``scenes``,
    ``notebooks`` and ``.venv``; ``../shared/data/go-draaw`` when this machine has it); its
    path. Blocks write under it (``out/``), not into the project."""
    work = os.path.join(tmp, "project")
    os.makedirs(work)
    for d in ("scenes", "notebooks", ".venv"):
        if os.path.exists(os.path.join(root, d)):
            os.symlink(os.path.join(root, d), os.path.join(work, d))
    go = os.path.normpath(os.path.join(root, "..", "shared", "data", "go-draaw"))
    if os.path.isdir(go):
        os.makedirs(os.path.join(tmp, "shared", "data"))
        os.symlink(go, os.path.join(tmp, "shared", "data", "go-draaw"))
    return work


def run_blocks(blocks: list[Block], tmp: str, root: str, timeout: float = 900) -> subprocess.CompletedProcess:
    """Run the runnable blocks in order in a project-like folder under ``tmp``; the completed
    process (its stdout says which block failed)."""
    work = project_like_folder(tmp, root)
    todo = [dict(where=b.where, lang=RUN[b.lang], code=b.code) for b in blocks
            if b.skip is None and b.lang in RUN]
    spec = os.path.join(tmp, "blocks.json")
    with open(spec, "w", encoding="utf-8") as f:
        json.dump(todo, f)
    driver = os.path.join(tmp, "driver.py")
    with open(driver, "w", encoding="utf-8") as f:
        f.write(_DRIVER)
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""),
               MPLBACKEND="Agg")
    return subprocess.run([sys.executable, driver, spec], cwd=work, capture_output=True, text=True,
                          env=env, timeout=timeout)
