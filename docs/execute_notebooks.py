"""Execute the notebooks of ``notebooks/`` once and store the executed copies, with their
outputs, as the documentation's tutorials (``docs/tutorials/<name>.ipynb``).

The docs build does not execute notebooks (myst-nb ``nb_execution_mode = "off"``): it shows
the outputs stored here. Refresh them after a notebook or the renderer changes::

    flock /tmp/draaw-heavy.lock .venv/bin/python docs/execute_notebooks.py            # all
    flock /tmp/draaw-heavy.lock .venv/bin/python docs/execute_notebooks.py sdf_csg    # one

Each notebook runs top to bottom in a fresh ``python3`` kernel with ``notebooks/`` as its
working directory, in the notebooks' full configuration unless ``--small`` is given (the
CI-sized one, ``DRAAW_MI_NOTEBOOK_SMALL=1``: seconds, tiny images). Outputs are made to fit
a static page: figures as PNG at a modest resolution, each cell's interactive widgets (a panel,
a progress bar: they need a live kernel) replaced by one line saying so (``ipywidgets.interact``
runs once with each control's first value), widget state and execution timings dropped, so the
stored copies stay small and the pages load without fetching widget scripts from the web.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import nbformat
from nbclient import NotebookClient

DOCS = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(DOCS)
NOTEBOOKS = os.path.join(ROOT, "notebooks")
TUTORIALS = os.path.join(DOCS, "tutorials")
NAMES = ("accuracy_vs_time", "inverse_fitting", "material_tuning", "sdf_csg", "texture_capture", "voxels_smoke")
WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"
# Run first in the kernel: PNG figures at a resolution that reads well and stays small.
# ``ipywidgets.interact`` becomes one call with each control's first (or current) value: a
# static page cannot move a slider, and nbclient hangs on interact's Output widget.
SETUP = """%config InlineBackend.figure_formats = ['png']
%config InlineBackend.rc = {'figure.dpi': 72, 'savefig.dpi': 72}
try:
    import ipywidgets as _widgets

    def _static_interact(_f=None, **kwargs):
        def first(v):
            if isinstance(v, _widgets.ValueWidget):
                return v.value
            return v[0] if isinstance(v, (list, tuple)) and v else v
        return _f(**{k: first(v) for k, v in kwargs.items()})

    _widgets.interact = _static_interact
except ImportError:
    pass"""
WIDGET_NOTE = "(an interactive widget: run the notebook to use it)"
MAX_OUTPUT_BYTES = 1_500_000        # a stored tutorial above this is refused: shrink its figures


def static_outputs(nb: nbformat.NotebookNode) -> int:
    """Make ``nb``'s outputs fit a static page, in place: a cell's widget views become one
    output saying :data:`WIDGET_NOTE` (their text/plain, a repr or a progress bar at 0 %, says
    nothing on a page), widget state and per-cell timing metadata go. Returns how many widget
    outputs were replaced.

    >>> nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("w")])
    >>> nb.cells[0].outputs = [nbformat.v4.new_output("display_data",
    ...     data={WIDGET_VIEW: {"model_id": "x"}, "text/plain": "Tuner(...)"})]
    >>> static_outputs(nb), nb.cells[0].outputs[0].data
    (1, {'text/plain': '(an interactive widget: run the notebook to use it)'})
    """
    replaced = 0
    nb.metadata.pop("widgets", None)
    for cell in nb.cells:
        cell.metadata.pop("execution", None)
        if cell.cell_type != "code":
            continue
        kept, noted = [], False
        for out in cell.outputs:
            if WIDGET_VIEW in out.get("data", {}):
                replaced += 1
                if not noted:                       # one line for the cell's widgets
                    kept.append(nbformat.v4.new_output("display_data", data={"text/plain": WIDGET_NOTE}))
                    noted = True
                continue
            kept.append(out)
        cell.outputs = kept
    return replaced


NOTE_ID = "docs-stored-outputs"


def add_stored_note(nb: nbformat.NotebookNode, name: str) -> None:
    """Put a note after the notebook's first cell (its title) saying that the outputs shown are
    stored and how to refresh them; replaces an earlier note, so it is never doubled.

    >>> nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# T")])
    >>> add_stored_note(nb, "t"); add_stored_note(nb, "t")
    >>> [c.id for c in nb.cells], "execute_notebooks.py t" in nb.cells[1].source
    (['...', 'docs-stored-outputs'], True)
    """
    nb.cells = [c for c in nb.cells if c.get("id") != NOTE_ID]
    text = ("```{note}\n"
            "The outputs on this page are **stored**: this notebook (`notebooks/" + name + ".ipynb`) was "
            "executed once, in its full configuration, and the documentation shows what it printed and "
            "drew then; interactive widgets appear as a line saying so. Refresh them with "
            "`.venv/bin/python docs/execute_notebooks.py " + name + "`, or run the notebook yourself "
            "with `make notebook`.\n```")
    cell = nbformat.v4.new_markdown_cell(text)
    cell.id = NOTE_ID
    nb.cells.insert(1, cell)


def execute(name: str, small: bool = False, timeout: int = 1800) -> str:
    """Execute ``notebooks/<name>.ipynb`` and write ``docs/tutorials/<name>.ipynb`` (atomically)."""
    source = os.path.join(NOTEBOOKS, f"{name}.ipynb")
    if not os.path.isfile(source):
        raise SystemExit(f"execute_notebooks: no notebook {source!r}; known: {', '.join(NAMES)}")
    nb = nbformat.read(source, as_version=4)
    setup = nbformat.v4.new_code_cell(SETUP)
    nb.cells.insert(0, setup)
    env_before = os.environ.get("DRAAW_MI_NOTEBOOK_SMALL")
    if small:
        os.environ["DRAAW_MI_NOTEBOOK_SMALL"] = "1"
    else:
        os.environ.pop("DRAAW_MI_NOTEBOOK_SMALL", None)
    try:
        t0 = time.perf_counter()
        NotebookClient(nb, kernel_name="python3", timeout=timeout, store_widget_state=True,
                       resources={"metadata": {"path": NOTEBOOKS}}).execute()
        seconds = time.perf_counter() - t0
    finally:
        if env_before is None:
            os.environ.pop("DRAAW_MI_NOTEBOOK_SMALL", None)
        else:
            os.environ["DRAAW_MI_NOTEBOOK_SMALL"] = env_before
    nb.cells.pop(0)                                   # the set-up cell is not the tutorial's
    widgets = static_outputs(nb)
    add_stored_note(nb, name)
    nb.metadata["draaw_mi_executed"] = {"configuration": "small" if small else "full",
                                        "seconds": round(seconds, 1)}
    text = nbformat.writes(nb)
    if len(text.encode()) > MAX_OUTPUT_BYTES:
        raise SystemExit(f"execute_notebooks: {name}'s outputs take {len(text.encode()):,} bytes, above "
                         f"{MAX_OUTPUT_BYTES:,}: make its figures smaller")
    os.makedirs(TUTORIALS, exist_ok=True)
    path = os.path.join(TUTORIALS, f"{name}.ipynb")
    fd, tmp = tempfile.mkstemp(prefix=f".{name}-", suffix=".ipynb", dir=TUTORIALS)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp, path)
    print(f"{name}: executed in {seconds:.0f} s ({'small' if small else 'full'}), "
          f"{widgets} widget output(s) made static, {len(text.encode()) / 1024:.0f} KiB -> {path}")
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("names", nargs="*", help=f"notebooks to execute (default: all of {', '.join(NAMES)})")
    p.add_argument("--small", action="store_true", help="the CI-sized configuration (DRAAW_MI_NOTEBOOK_SMALL=1)")
    p.add_argument("--timeout", type=int, default=1800, help="seconds per cell (default 1800)")
    args = p.parse_args(argv)
    for name in args.names or NAMES:
        execute(name, small=args.small, timeout=args.timeout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
