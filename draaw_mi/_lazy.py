"""Names reached without being imported up front: subpackages on first use (PEP 562), the
old module paths of moved modules (PEP 451 aliases that warn) and the names an earlier
release had where a module or package face has them no more (forwards that warn)."""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
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
        self._specs: dict = {}                 # old name -> the new module's own spec, meanwhile

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in self.moved:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        new = self.moved[spec.name]
        _moved_warning(spec.name, new)
        module = importlib.import_module(new)
        self._specs[spec.name] = module.__spec__   # the import system sets the old name's spec on it
        return module

    def exec_module(self, module):
        module.__spec__ = self._specs.pop(module.__spec__.name)


def _moved_warning(old: str, new: str) -> None:
    """Warn that ``old`` is now ``new``, at the line that named it."""
    warnings.warn(f"{old} is now {new}: import it from there ({old} goes in the next release)",
                  DeprecationWarning, stacklevel=_caller_level())


def old_names(package: str, moved: dict, then=None):
    """A module ``__getattr__`` for ``package`` that serves each name of an earlier release in
    ``moved`` (``{name: module that defines it now}``) from its new module with a
    :class:`DeprecationWarning`; any other name goes to ``then`` (another ``__getattr__``) or
    raises the usual ``AttributeError``.

    >>> getattr_ = old_names("json", {"JSONDecodeError": "json.decoder"})
    >>> with warnings.catch_warnings(record=True) as said:
    ...     warnings.simplefilter("always")
    ...     getattr_("JSONDecodeError").__module__, said[0].category.__name__
    ('json.decoder', 'DeprecationWarning')
    """
    def __getattr__(name: str):
        if name in moved:
            _moved_warning(f"{package}.{name}", f"{moved[name]}.{name}")
            return getattr(importlib.import_module(moved[name]), name)
        if then is not None:
            return then(name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return __getattr__


class ShadowedModule(types.ModuleType):
    """The old module path ``old`` of a module whose name in its package is now a function
    (``draaw_mi.render`` is the function; ``draaw_mi/render.py`` moved to
    ``draaw_mi/rendering/renderer.py``). Put in ``sys.modules``, it makes ``from draaw_mi.render
    import X`` read ``X`` from ``new`` (or from ``elsewhere[X]``) with a
    :class:`DeprecationWarning`; assigning a module constant (``FREEZE``) assigns it there. A
    name in ``gone`` raises ``ImportError`` with its hint (an ``AttributeError`` would lose it:
    ``from ... import`` turns that into "cannot import name").

    >>> sys.modules["json_old"] = ShadowedModule("json_old", "json.decoder", gone={"x": "use y"})
    >>> with warnings.catch_warnings(record=True) as said:
    ...     warnings.simplefilter("always")
    ...     from json_old import JSONDecodeError
    >>> JSONDecodeError.__module__, said[0].category.__name__
    ('json.decoder', 'DeprecationWarning')
    >>> from json_old import x
    Traceback (most recent call last):
    ImportError: json_old.x is gone: use y
    >>> del sys.modules["json_old"]
    """
    def __init__(self, old: str, new: str, elsewhere: dict | None = None, gone: dict | None = None):
        super().__init__(old, f"{old} is now {new} (a DeprecationWarning says so on use)")
        vars(self).update(_new=new, _elsewhere=dict(elsewhere or {}), _gone=dict(gone or {}))

    def _home(self, name: str):
        if name in self._gone:
            raise ImportError(f"{self.__name__}.{name} is gone: {self._gone[name]}")
        home = self._elsewhere.get(name, self._new)
        module = importlib.import_module(home)
        if not hasattr(module, name):
            raise AttributeError(f"module {self.__name__!r} (now {self._new}) has no attribute {name!r}")
        _moved_warning(f"{self.__name__}.{name}", f"{home}.{name}")
        return module

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(self._home(name), name)

    def __setattr__(self, name: str, value) -> None:
        setattr(self._home(name), name, value)


def _caller_level() -> int:
    """The ``stacklevel`` that points a warning given in this module at the code that imports
    or names the old path (past this module's frames and the import system's), so a notebook
    shows it. ``warnings.warn`` itself steps over the import system's frames: they do not
    count."""
    frame, level = sys._getframe(1), 1
    while frame is not None:
        name = frame.f_code.co_filename
        if name == __file__:
            level += 1
        elif not name.startswith("<frozen importlib"):
            break
        frame = frame.f_back
    return level
