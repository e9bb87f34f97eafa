"""Shared by the ``make_*.py`` generators: turn a list of ``("md" | "code", source)`` cells
into a notebook without outputs and write it atomically beside the generators.

>>> nb = build([("md", "# Title"), ("code", "1 + 1")])
>>> [c.cell_type for c in nb.cells]
['markdown', 'code']
"""
from __future__ import annotations

import os
import tempfile

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = os.path.dirname(os.path.abspath(__file__))


def build(cells) -> nbformat.NotebookNode:
    """A validated notebook of ``cells`` (``("md", text)`` or ``("code", text)``), no outputs."""
    nb = new_notebook()
    for kind, _ in cells:
        if kind not in ("md", "code"):
            raise ValueError(f"_nbgen.build: cell kind {kind!r}; expected 'md' or 'code'")
    nb.cells = [new_markdown_cell(src) if kind == "md" else new_code_cell(src) for kind, src in cells]
    for i, cell in enumerate(nb.cells):
        cell.id = f"cell-{i:02d}"           # stable ids: regenerating changes nothing in git
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.metadata["language_info"] = {"name": "python"}
    nbformat.validate(nb)
    return nb


def write(cells, name: str) -> str:
    """Write ``notebooks/<name>.ipynb`` (temp file + rename: never half a notebook)."""
    path = os.path.join(HERE, f"{name}.ipynb")
    nb = build(cells)
    fd, tmp = tempfile.mkstemp(prefix=f".{name}-", suffix=".ipynb", dir=HERE)
    try:
        with os.fdopen(fd, "w") as fh:
            nbformat.write(nb, fh)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
    print(f"wrote {path}")
    return path
