"""Subpackages reachable as attributes without being imported up front (PEP 562)."""
from __future__ import annotations

import importlib


def on_first_use(package: str, names: tuple):
    """A module ``__getattr__`` for ``package`` that imports the submodule ``names`` the first
    time one is read as an attribute (importing sets it on the package, so later reads are
    plain attribute reads), and raises the usual ``AttributeError`` for anything else.

    >>> getattr_ = on_first_use("json", ("decoder",))
    >>> getattr_("decoder").__name__
    'json.decoder'
    """
    def __getattr__(name: str):
        if name in names:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return __getattr__
