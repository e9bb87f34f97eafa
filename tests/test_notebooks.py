"""Execute the notebooks in their small CI configuration (DRAAW_MI_NOTEBOOK_SMALL=1).

Each notebook runs top to bottom in a fresh ``python3`` kernel (ipykernel in this virtual
environment; jupyter_client maps the kernelspec's ``python`` to ``sys.executable``) with the
working directory ``notebooks/``. The notebooks in the repository carry no outputs; a
generator script (``notebooks/make_<name>.py``) writes each one and must be in sync with it.
"""
from __future__ import annotations

import importlib.util
import os
import time

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOKS = os.path.join(ROOT, "notebooks")
# name -> generator script
CASES = {"inverse_fitting": "make_inverse_fitting.py"}


def _generator(script):
    spec = importlib.util.spec_from_file_location(script[:-3], os.path.join(NOTEBOOKS, script))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", sorted(CASES))
def test_notebook_is_generated_and_has_no_outputs(name):
    path = os.path.join(NOTEBOOKS, f"{name}.ipynb")
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, "commit notebooks without outputs"
    fresh = _generator(CASES[name]).build()
    assert [(c.cell_type, c.source) for c in nb.cells] == [(c.cell_type, c.source) for c in fresh.cells], \
        f"{name}.ipynb is out of date: run python notebooks/{CASES[name]}"


@pytest.mark.parametrize("name", sorted(CASES))
def test_notebook_executes_small(name, monkeypatch):
    monkeypatch.setenv("DRAAW_MI_NOTEBOOK_SMALL", "1")
    nb = nbformat.read(os.path.join(NOTEBOOKS, f"{name}.ipynb"), as_version=4)
    client = nbclient.NotebookClient(nb, kernel_name="python3", timeout=120,
                                     resources={"metadata": {"path": NOTEBOOKS}})
    t0 = time.perf_counter()
    client.execute()                   # raises CellExecutionError with the cell and traceback
    print(f"{name}: executed in {time.perf_counter() - t0:.1f} s (small configuration)")
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs
                   if o.output_type == "stream")
    assert "32x32" in text and "fit" in text                   # the small configuration ran
    if name == "inverse_fitting":
        _check_fitted_values(text)
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
              if "image/png" in o.get("data", {})]
    assert len(images) >= 2                                     # side by side + convergence


# The notebook's ground truth (scenes/fit_two_spheres.toml), typed here independently of it.
TRUTH = {"left.roughness": 0.2, "left.metallic": 0.9, "right.roughness": 0.6, "right.metallic": 0.1}


def _check_fitted_values(text):
    """The fit cell prints ``name truth T fit F error E`` per parameter: the fit recovers the
    truth as tests/test_fit.py::test_two_materials_jointly requires of the same scene (0.05)."""
    import re
    found = {m[0]: (float(m[1]), float(m[2]), float(m[3])) for m in
             re.findall(r"^(\S+)\s+truth ([-\d.]+)\s+fit ([-\d.]+)\s+error ([-+\d.]+)$", text, re.M)}
    assert set(found) == set(TRUTH), f"fitted values not printed: {found}"
    for name, (truth, fit, err) in found.items():
        assert truth == pytest.approx(TRUTH[name], abs=5e-4), name
        assert err == pytest.approx(fit - truth, abs=2e-4), name
        assert abs(fit - TRUTH[name]) < 0.05, (name, fit, TRUTH[name])
