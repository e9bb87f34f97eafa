"""Execute the Jupyter-tuning notebooks in their small CI configuration (DRAAW_MI_NOTEBOOK_SMALL=1).

Same protocol as tests/test_notebooks.py: generated from ``notebooks/make_<name>.py``,
committed without outputs, run top to bottom in a fresh ``python3`` kernel.
"""
from __future__ import annotations

import os

import pytest
from conftest import notebook_generator

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipywidgets")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOKS = os.path.join(ROOT, "notebooks")
CASES = {  # name -> (generator, text that shows the small configuration ran, min. images)
    "material_tuning": ("make_material_tuning.py", "48x48 preview", 1),
    "accuracy_vs_time": ("make_accuracy_vs_time.py", "small study: 32x32", 1),
}
# name -> files the small configuration writes, all under DRAAW_MI_NOTEBOOK_OUT/<name>
WRITES = {"material_tuning": {"material_tuning/cornell_tuned.toml"},
          "accuracy_vs_time": {"accuracy_vs_time/results.csv"}}


@pytest.mark.parametrize("name", sorted(CASES))
def test_notebook_is_generated_and_has_no_outputs(name):
    nb = nbformat.read(os.path.join(NOTEBOOKS, f"{name}.ipynb"), as_version=4)
    nbformat.validate(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, "commit notebooks without outputs"
    fresh = notebook_generator(CASES[name][0]).build()
    assert [(c.cell_type, c.source) for c in nb.cells] == [(c.cell_type, c.source) for c in fresh.cells],\
        f"{name}.ipynb is out of date: run python notebooks/{CASES[name][0]}"


@pytest.mark.parametrize("name", sorted(CASES))
def test_notebook_executes_small(name, monkeypatch, tmp_path):
    monkeypatch.setenv("DRAAW_MI_NOTEBOOK_SMALL", "1")
    monkeypatch.setenv("DRAAW_MI_NOTEBOOK_OUT", str(tmp_path))       # the folder its files go to
    nb = nbformat.read(os.path.join(NOTEBOOKS, f"{name}.ipynb"), as_version=4)
    client = nbclient.NotebookClient(nb, kernel_name="python3", timeout=180,
                                     resources={"metadata": {"path": NOTEBOOKS}})
    client.execute()                   # raises CellExecutionError with the cell and traceback
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    assert CASES[name][1] in text
    assert sum("image/png" in o.get("data", {}) for o in outputs) >= CASES[name][2]
    written = {os.path.relpath(os.path.join(d, f), tmp_path) for d, _, fs in os.walk(tmp_path) for f in fs}
    assert written >= WRITES[name] and all(p.startswith(name + os.sep) for p in written), sorted(written)
    if name == "material_tuning":
        views = [o for o in outputs if "application/vnd.jupyter.widget-view+json" in o.get("data", {})]
        assert views, "the tuner panel was displayed as a widget"
        assert "change -> new frame: median" in text and "saved" in text
