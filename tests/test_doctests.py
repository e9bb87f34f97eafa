"""Every docstring example in the package runs and shows what it says (``doctest`` over each
module of ``draaw_mi``; examples marked ``+SKIP`` are not run)."""
from __future__ import annotations

import doctest
import importlib
import os
import pkgutil

import pytest

import draaw_mi

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MODULES = sorted(m.name for m in pkgutil.walk_packages(draaw_mi.__path__, "draaw_mi."))


def test_the_walk_finds_the_package():
    assert len(MODULES) > 50 and "draaw_mi.batch.planner" in MODULES and "draaw_mi.media.mitsuba_dicts" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name, monkeypatch):
    monkeypatch.chdir(ROOT)                  # examples name files such as scenes/cornell.toml
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                             report=True)
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed (output above)"
