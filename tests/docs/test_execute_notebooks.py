"""docs/execute_notebooks.py makes executed notebooks fit a static page: a cell's widgets become
one line saying what they are, not their text form (a tqdm bar stuck at ``0%``, a panel's repr
with memory addresses), and the stored tutorials hold no such text."""
from __future__ import annotations

import glob
import importlib.util
import os

import pytest

nbformat = pytest.importorskip("nbformat")
pytest.importorskip("nbclient")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_spec = importlib.util.spec_from_file_location("execute_notebooks", os.path.join(ROOT, "docs", "execute_notebooks.py"))
execute_notebooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(execute_notebooks)
VIEW = execute_notebooks.WIDGET_VIEW
# what a widget's text/plain looked like on the stored pages
WIDGET_TEXTS = ("RFBOutputContext(", "HBox(children=", "VBox(children=", " object at 0x", "0%|")


def _widget(text: str):
    return nbformat.v4.new_output("display_data", data={VIEW: {"model_id": text[:4]}, "text/plain": text})


def test_a_cells_widgets_become_one_line_and_other_outputs_stay():
    """A fit cell's tqdm bar and a panel cell's two widgets (as executed: widget view plus text/plain)."""
    image = nbformat.v4.new_output("display_data", data={"image/png": "iVBOR", "text/plain": "<Figure>"})
    fit = nbformat.v4.new_code_cell("fit()")
    fit.outputs = [_widget("fit:   0%|          | 0/800 [00:00<?, ?it/s]"),
                   nbformat.v4.new_output("stream", name="stdout", text="fit: 148.7 s\n"), image]
    panel = nbformat.v4.new_code_cell("tuner")
    panel.outputs = [_widget("RFBOutputContext()"),
                     _widget("HBox(children=(VBox(children=(<OrbitCanvas object at 0x7f96387b48d0>,")]
    plain = nbformat.v4.new_code_cell("print(1)")
    plain.outputs = [nbformat.v4.new_output("stream", name="stdout", text="1\n")]
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# T"), fit, panel, plain])
    nb.metadata["widgets"] = {"state": {}}

    assert execute_notebooks.static_outputs(nb) == 3
    shown = [str(o.get("data", {}).get("text/plain", "")) for c in (fit, panel) for o in c.outputs]
    assert not [t for t in shown if any(w in t for w in WIDGET_TEXTS)], shown
    note = {"text/plain": "(an interactive widget: run the notebook to use it)"}
    assert [o.get("data") or o.get("text") for o in fit.outputs] == [note, "fit: 148.7 s\n", image.data]
    assert [o.data for o in panel.outputs] == [note]                  # one line for the cell
    assert plain.outputs[0].text == "1\n" and "widgets" not in nb.metadata
    nbformat.validate(nb)


@pytest.mark.parametrize("path", sorted(glob.glob(os.path.join(ROOT, "docs", "tutorials", "*.ipynb"))),
                         ids=os.path.basename)
def test_stored_tutorials_show_no_widget_text(path):
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for out in cell.outputs:
            text = str(out.get("data", {}).get("text/plain", "")) if "image/png" not in out.get("data", {}) else ""
            assert VIEW not in out.get("data", {}) and not any(w in text for w in WIDGET_TEXTS), \
                (os.path.basename(path), cell.source[:60], text[:120])
