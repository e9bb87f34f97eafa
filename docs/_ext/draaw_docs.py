"""Sphinx extension of draaw-mi's docs.

* ``.. draaw-plugin:: dotted.Class`` — a plugin's reference section from its docstring, written
  in Mitsuba's style (a label, a title, a ``.. pluginparameters::`` table); ``:doc-of: module``
  takes the module's docstring instead, ``:title:`` and ``:label:`` give one a docstring lacks.
* ``pluginparameters``, ``tabs`` / ``code-tab`` and the ``monosp`` role: the directives of
  Mitsuba's plugin docs, rendered as a table, plain code blocks and literal text.
* ``.. draaw-autoall:: module`` — autodoc entries for every name in ``module.__all__`` (functions,
  classes with their members, data, and a link for a submodule), so the API pages list exactly
  the public names and follow ``__all__`` as it changes.
* Reference checks: a ``py`` cross-reference to a draaw-mi object that exists but has no page
  of its own renders as code without a warning; one to a name that does not exist stays a
  nitpicky warning (an error under ``-W``). A DeprecationWarning raised by a moved draaw-mi
  module while the docs import the package is a warning too.
* The benchmark pages: ``docs/benchmarks/*.md`` are written at each build from
  ``benchmarks/results/*.md`` and the studies' ``summary.md`` (never edited by hand).
"""
from __future__ import annotations

import importlib
import inspect
import os
import re
import types
import warnings

from docutils import nodes
from docutils.parsers.rst import Directive, directives
from docutils.statemachine import StringList
from sphinx.directives.code import CodeBlock
from sphinx.util import logging
from sphinx.util.nodes import nested_parse_with_titles

from draaw_mi.io import write_text

logger = logging.getLogger(__name__)
DOCS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROOT = os.path.dirname(DOCS)


# -- Mitsuba's plugin-doc vocabulary -----------------------------------------------------------

def monosp_role(name, rawtext, text, lineno, inliner, options=None, content=None):
    return [nodes.literal(rawtext, text)], []


class PluginParameters(Directive):
    """Mitsuba's ``.. pluginparameters::``: a two-level bullet list of (name, type, meaning)."""
    has_content = True

    def run(self):
        lines = [".. list-table::", "   :header-rows: 1", "   :widths: 18 12 70", "",
                 "   * - Parameter", "     - Type", "     - Description", ""]
        lines += ["   " + line for line in self.content]
        node = nodes.container(classes=["draaw-plugin-parameters"])
        self.state.nested_parse(StringList(lines, source=self.content.source(0) if self.content else ""),
                                self.content_offset, node)
        return node.children


class Tabs(Directive):
    """sphinx-tabs' ``.. tabs::`` as Mitsuba's docstrings use it: its tabs one after another."""
    has_content = True

    def run(self):
        node = nodes.container()
        self.state.nested_parse(self.content, self.content_offset, node)
        return node.children


class CodeTab(CodeBlock):
    """``.. code-tab:: python``: a code block (the tab's label is its language)."""


# -- plugins -----------------------------------------------------------------------------------

def _import(dotted: str):
    """The object at ``dotted`` (a module, or an attribute path inside one)."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(f"no module in {dotted!r}")


class DraawPlugin(Directive):
    required_arguments = 1
    option_spec = {"doc-of": directives.unchanged, "title": directives.unchanged,
                   "label": directives.unchanged}

    def run(self):
        target = self.arguments[0]
        try:
            obj = _import(self.options.get("doc-of", target))
        except (ImportError, AttributeError) as e:
            raise self.error(f"draaw-plugin: cannot import {target!r}: {e}")
        doc = inspect.getdoc(obj) or ""
        if not doc.strip():
            raise self.error(f"draaw-plugin: {target!r} has no docstring")
        lines = []
        if "title" in self.options:
            if "label" in self.options:
                lines += [f".. _{self.options['label']}:", ""]
            title = self.options["title"]
            lines += [title, "-" * len(title), ""]
        lines += doc.splitlines()
        lines += ["", f"Implemented by ``{target}``."]
        node = nodes.container()
        nested_parse_with_titles(self.state, StringList(lines, source=f"docstring of {target}"), node)
        return node.children


# -- API pages from __all__ --------------------------------------------------------------------

def _kind(obj) -> str:
    if isinstance(obj, types.ModuleType):
        return "module"
    if inspect.isclass(obj):
        return "exception" if issubclass(obj, BaseException) else "class"
    if callable(obj):
        return "function"
    return "data"


class DraawAutoAll(Directive):
    required_arguments = 1
    option_spec = {"exclude": directives.unchanged, "aliases-from": directives.unchanged}

    def run(self):
        modname = self.arguments[0]
        module = importlib.import_module(modname)
        names = list(getattr(module, "__all__", ()))
        if not names:
            raise self.error(f"draaw-autoall: {modname} has no __all__")
        exclude = set((self.options.get("exclude") or "").split())
        aliases = {}                     # id(class) -> its full name on a wing's page
        for wing in (self.options.get("aliases-from") or "").split():
            face = importlib.import_module(wing)
            for n in getattr(face, "__all__", ()):
                aliases.setdefault(id(getattr(face, n)), f"{wing}.{n}")
        lines = [f".. py:currentmodule:: {modname}", ""]
        for name in names:
            if name in exclude:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("error", DeprecationWarning)   # __all__ names are real ones
                obj = getattr(module, name)
            kind = _kind(obj)
            full = f"{modname}.{name}"
            if kind == "module":
                page = obj.__name__.rsplit(".", 1)[-1]
                if os.path.isfile(os.path.join(DOCS, "api", f"{page}.md")):
                    lines += [f":mod:`{full}` — {(inspect.getdoc(obj) or '').splitlines()[0]} "
                              f"(its own page: :doc:`/api/{page}`)", ""]
                else:
                    lines += [f".. automodule:: {obj.__name__}", "   :members:", ""]
            elif kind in ("class", "exception") and id(obj) in aliases:
                lines += [f".. py:{kind}:: {full}", "   :no-index-entry:", "",
                          f"   The same {kind} as :class:`{aliases[id(obj)]}` (documented there).", ""]
            elif kind in ("class", "exception"):
                lines += [f".. auto{kind}:: {full}", "   :members:", ""]
            elif kind == "function":
                lines += [f".. autofunction:: {full}", ""]
            else:                        # a constant: its own __doc__ is its type's, so not shown
                shown = repr(obj)
                value = shown if len(shown) <= 70 else f"a {type(obj).__name__} of {len(obj)} entries" \
                    if hasattr(obj, "__len__") else f"a {type(obj).__name__}"
                lines += [f".. py:data:: {full}", f"   :type: {type(obj).__name__}", "",
                          f"   Value: ``{value}``" if value is shown else f"   Value: {value}.", ""]
        node = nodes.container()
        self.state.nested_parse(StringList(lines, source=f"__all__ of {modname}"), self.content_offset, node)
        return node.children


# -- references to objects without a page -----------------------------------------------------

def _exists(dotted: str) -> bool:
    if not dotted.startswith("draaw_mi"):
        return False
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            _import(dotted)
            return True
        except Exception:
            return False


_NAMES: dict[str, list[str]] = {}


def _name_index() -> dict[str, list[str]]:
    """{top-level name: modules of draaw_mi that define or import it}, built once."""
    if not _NAMES:
        import pkgutil

        import draaw_mi
        for info in pkgutil.walk_packages(draaw_mi.__path__, "draaw_mi."):
            try:
                module = importlib.import_module(info.name)
            except Exception:                     # an optional dependency missing: its names unknown
                continue
            for name in vars(module):
                if not name.startswith("__"):
                    _NAMES.setdefault(name, []).append(info.name)
    return _NAMES


def _exists_somewhere(target: str) -> bool:
    """``target`` (``name`` or ``Class.attr``, as a docstring writes it relative to its own
    module) names an object of some draaw_mi module."""
    head, _, rest = target.partition(".")
    for modname in _name_index().get(head, ()):
        if _exists(f"{modname}.{target}"):
            return True
    return False


def missing_reference(app, env, node, contnode):
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "")
    target = target.lstrip("~.")
    module, cls = node.get("py:module"), node.get("py:class")
    candidates = [target]
    if module:
        candidates += [f"{module}.{target}"]
        if cls:
            candidates += [f"{module}.{cls}.{target}"]
        parent = module.rsplit(".", 1)[0]
        candidates += [f"{parent}.{target}"]
    candidates += [f"draaw_mi.{target}"]
    if any(_exists(c) for c in candidates) or (not target.startswith("draaw_mi.") and _exists_somewhere(target)):
        return contnode                  # a real draaw-mi object with no page: shown as code
    return None


# -- DeprecationWarnings of moved modules ------------------------------------------------------

_deprecations: list[str] = []


def _record_deprecations():
    original = warnings.showwarning

    def showwarning(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, DeprecationWarning) and "draaw_mi" in str(message):
            _deprecations.append(f"{message} ({filename}:{lineno})")
        return original(message, category, filename, lineno, file, line)

    warnings.showwarning = showwarning
    warnings.filterwarnings("always", message=r".*draaw_mi.*", category=DeprecationWarning)


def report_deprecations(app, env):
    for text in dict.fromkeys(_deprecations):
        logger.warning(f"DeprecationWarning while importing draaw-mi for the docs: {text}")
    _deprecations.clear()


# -- benchmark pages ---------------------------------------------------------------------------

IMAGE = re.compile(r"!\[([^\]]*)\]\(([^)\s]+)\)")


def _results_pages() -> list[tuple[str, str]]:
    """(page name, source Markdown path) of every recorded result, sorted."""
    pages = []
    for folder in (os.path.join(ROOT, "benchmarks", "results"), os.path.join(ROOT, "benchmarks")):
        # (the four records beside the scripts were left out; a script's *_latest.md run is not
        # a record, and the folder's README is its index, not a result)
        for name in sorted(os.listdir(folder)):
            if name.endswith(".md") and not name.endswith("_latest.md") and name != "README.md":
                pages.append((name[:-3], os.path.join(folder, name)))
    for study in sorted(os.listdir(os.path.join(ROOT, "benchmarks"))):
        summary = os.path.join(ROOT, "benchmarks", study, "summary.md")
        if study.startswith("study") and os.path.isfile(summary):
            pages.append((study, summary))
    return pages


def write_benchmark_pages(app):
    """Write docs/benchmarks/<name>.md from each recorded result (images linked in place:
    Sphinx copies them; one the result names but the repository lacks is said so in text)."""
    out = os.path.join(DOCS, "benchmarks")
    os.makedirs(out, exist_ok=True)
    wanted = set()
    for page, source in _results_pages():
        text = open(source, encoding="utf-8").read()
        here = os.path.dirname(source)

        def image(m):
            path = os.path.normpath(os.path.join(here, m.group(2)))
            if not os.path.isfile(path):
                return f"*(plot not kept in the repository: `{m.group(2)}`)*"
            return f"![{m.group(1)}]({os.path.relpath(path, out)})"

        rel = os.path.relpath(source, ROOT)
        body = IMAGE.sub(image, text)
        body = (f"<!-- written by docs/_ext/draaw_docs.py from {rel}: edit that file -->\n" + body.rstrip()
                + f"\n\n---\n\n*Recorded in `{rel}`.*\n")
        path = os.path.join(out, f"{page}.md")
        wanted.add(path)
        if not os.path.isfile(path) or open(path, encoding="utf-8").read() != body:
            write_text(path, body)      # atomic: a build beside this one never reads half a page;
                                        # unchanged pages keep their mtime
    for name in os.listdir(out):
        path = os.path.join(out, name)
        if name.endswith(".md") and path not in wanted:
            os.unlink(path)


def setup(app):
    _record_deprecations()
    app.add_role("monosp", monosp_role)
    app.add_directive("pluginparameters", PluginParameters)
    app.add_directive("tabs", Tabs)
    app.add_directive("code-tab", CodeTab)
    app.add_directive("draaw-plugin", DraawPlugin)
    app.add_directive("draaw-autoall", DraawAutoAll)
    app.connect("builder-inited", write_benchmark_pages)
    app.connect("missing-reference", missing_reference)
    app.connect("env-updated", report_deprecations)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
