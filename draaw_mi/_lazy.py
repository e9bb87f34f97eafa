"""Names reached without being imported up front: subpackages on first use (PEP 562) and the
old module paths of moved modules (PEP 451 aliases that warn)."""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings


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


class MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """An import hook that serves each old module path in ``moved`` (``{old: new}``) as the
    module at its new path, with a :class:`DeprecationWarning` that names the new path. The
    module object is the new one (``draaw_mi.preview.Preview is
    draaw_mi.rendering.preview.Preview``), so patches and ``isinstance`` see one thing.

    >>> hook = MovedModules({"json_old_decoder": "json.decoder"})
    >>> sys.meta_path.insert(0, hook)
    >>> with warnings.catch_warnings(record=True) as said:
    ...     warnings.simplefilter("always")
    ...     import json_old_decoder
    >>> json_old_decoder.__name__, said[0].category.__name__
    ('json.decoder', 'DeprecationWarning')
    >>> sys.meta_path.remove(hook); del sys.modules["json_old_decoder"]
    """
    def __init__(self, moved: dict):
        self.moved = dict(moved)

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in self.moved:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        new = self.moved[spec.name]
        warnings.warn(f"{spec.name} is now {new}: import it from there ({spec.name} goes in the next "
                      "release)", DeprecationWarning, stacklevel=_caller_level())
        module = importlib.import_module(new)
        self._spec = module.__spec__           # the import system sets the old name's spec on it
        return module

    def exec_module(self, module):
        module.__spec__ = self._spec


def _caller_level() -> int:
    """The ``stacklevel`` that points a warning at the code that imports (past the import
    system's own frames and this module's), so a notebook shows it."""
    frame, level = sys._getframe(1), 1
    while frame is not None and (frame.f_code.co_filename.startswith("<frozen importlib")
                                 or frame.f_code.co_filename == __file__):
        frame, level = frame.f_back, level + 1
    return level
