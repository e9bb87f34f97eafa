"""The house of docs/layout.md: wings that import down the stack, no circles, few plain modules,
imports at the top of modules, and no module named like a public function.

Every import of the package's own modules is counted, the ones inside functions too (an
import moved into a function to dodge a circle is still a circle).
"""
from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import os
import pkgutil
import shutil
import subprocess
import sys
import warnings

import pytest

import draaw_mi
from conftest import ROOT

PACKAGE = os.path.join(ROOT, "draaw_mi")
#: at most this many imports of the package's own modules inside functions, each commented
MAX_LOCAL_IMPORTS = 10
#: at most this many plain modules directly in draaw_mi/ (the ground floor of docs/layout.md)
MAX_PLAIN_MODULES = 8


def module_files(root: str = PACKAGE) -> dict:
    """``{dotted module name: file}`` of every module under ``root`` (a package folder)."""
    out = {}
    base = os.path.dirname(root)
    for folder, _, files in os.walk(root):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(folder, f)
                name = os.path.relpath(path, base)[:-3].replace(os.sep, ".")
                out[name.removesuffix(".__init__")] = path
    return out


def internal_imports(files: dict) -> list:
    """``(importer, imported, line, in a function, the source line)`` for every import of a
    module of ``files`` (an imported name that is a module counts as that module, any other
    name as the module it comes from)."""
    out = []
    for mod, path in files.items():
        source = open(path, encoding="utf-8").read()
        lines = source.splitlines()
        package = mod if path.endswith("__init__.py") else mod.rpartition(".")[0]

        def targets(node):
            if isinstance(node, ast.Import):
                return [a.name for a in node.names]
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1])
                base = base + "." + node.module if node.module else base
            else:
                base = node.module or ""
            return [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]

        def walk(node, in_function):
            for child in ast.iter_child_nodes(node):
                local = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
                if isinstance(child, (ast.Import, ast.ImportFrom)):
                    for target in targets(child):
                        while target not in files and "." in target:
                            target = target.rpartition(".")[0]
                        if target in files and target != mod:
                            out.append((mod, target, child.lineno, in_function, lines[child.lineno - 1]))
                walk(child, local)
        walk(ast.parse(source), False)
    return out


def circles(edges) -> list:
    """The strongly connected components of more than one module (Tarjan)."""
    graph: dict = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
    index, low, stack, on, found, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for v in list(graph):
        if v not in index:
            visit(v)
    return found


def lint_imports(cwd: str, package_parent: str):
    env = dict(os.environ, PYTHONPATH=package_parent)
    exe = os.path.join(os.path.dirname(sys.executable), "lint-imports")
    return subprocess.run([exe, "--config", os.path.join(ROOT, "pyproject.toml"), "--no-cache"], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


def test_the_wings_import_down_the_stack():
    """import-linter's layers contract (pyproject.toml) over every import, inside functions too."""
    out = lint_imports(ROOT, ROOT)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert "1 kept, 0 broken" in out.stdout


def test_an_upward_import_inside_a_function_breaks_the_contract(tmp_path):
    """The contract can fail: a copy of the package whose sdf/ imports widgets/ inside a
    function (a lower wing reaching up) is reported, naming both modules."""
    copy = tmp_path / "draaw_mi"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    node = copy / "sdf" / "node.py"
    node.write_text(node.read_text() + "\n\ndef _reaches_up():\n    from ..widgets import tuning\n    return tuning\n")
    out = lint_imports(str(tmp_path), str(tmp_path))
    assert out.returncode != 0
    assert "draaw_mi.sdf.node -> draaw_mi.widgets.tuning" in out.stdout, out.stdout[-3000:]


def test_no_import_circles_counting_imports_inside_functions():
    edges = {(a, b) for a, b, *_ in internal_imports(module_files())}
    assert len(edges) > 300                   # (the scan sees the package's imports)
    assert circles(edges) == []


def test_circles_are_found():
    """The circle finder finds a circle through a function-local import."""
    assert circles({("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")}) == [["a", "b", "c"]]
    assert circles({("a", "b"), ("b", "c")}) == []


def test_few_function_local_imports_each_with_its_reason():
    local = [(a, b, line, text) for a, b, line, inside, text in internal_imports(module_files()) if inside]
    assert len(local) <= MAX_LOCAL_IMPORTS, "\n".join(f"{a}:{line} -> {b}" for a, b, line, _ in local)
    for a, b, line, text in local:
        assert "#" in text, f"{a}:{line} imports {b} inside a function without a comment that says why"


def test_the_ground_floor_has_few_plain_modules():
    plain = sorted(m for m, p in module_files().items()
                   if m.count(".") == 1 and not p.endswith("__init__.py"))
    assert len(plain) <= MAX_PLAIN_MODULES, plain


def test_no_module_carries_the_dotted_name_of_a_public_function():
    """``draaw_mi.render`` is the function; a module of that dotted name would be shadowed by
    it (``mock.patch("draaw_mi.render.x")`` could not work)."""
    packages = ["draaw_mi"] + [m.name for m in pkgutil.walk_packages(draaw_mi.__path__, "draaw_mi.") if m.ispkg
                               and "widgets" not in m.name]
    clashes = []
    for name in packages:
        package = importlib.import_module(name)
        modules = {m.name for m in pkgutil.iter_modules(package.__path__)}
        for attr in set(getattr(package, "__all__", ())) | {a for a in vars(package) if not a.startswith("_")}:
            obj = getattr(package, attr, None)
            if attr in modules and obj is not None and not inspect.ismodule(obj):
                clashes.append(f"{name}.{attr}")
    assert clashes == []


def _python(code: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter in the project's folder; it must exit 0."""
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out


def test_the_old_module_paths_work_for_one_release_with_a_warning():
    """Notebooks' imports of the flat layout keep working (the same module objects) and say
    where things are now."""
    code = ("import warnings; warnings.simplefilter('error', DeprecationWarning)\n"
            "import draaw_mi\n"
            "from draaw_mi.rendering.preview import Preview\n"
            "try:\n    import draaw_mi.preview\nexcept DeprecationWarning as e:\n    print('warned:', e)\n"
            "warnings.simplefilter('ignore', DeprecationWarning)\n"
            "import draaw_mi.preview, draaw_mi.tuning, draaw_mi.fit_views\n"
            "from draaw_mi.fit_result import FitResult\n"
            "print(draaw_mi.preview.Preview is Preview, draaw_mi.tuning.__name__, draaw_mi.fit_views.__name__,\n"
            "      FitResult is draaw_mi.FitResult, callable(draaw_mi.render), callable(draaw_mi.fit))\n")
    out = _python(code)
    said = out.stdout.splitlines()
    assert said[0] == ("warned: draaw_mi.preview is now draaw_mi.rendering.preview: import it from there "
                       "(draaw_mi.preview goes in the next release)")
    assert said[1] == "True draaw_mi.widgets.tuning draaw_mi.fitting.views True True True"


@pytest.mark.parametrize("old, new", sorted(draaw_mi.MOVED.items()))
def test_every_old_path_names_a_module_that_exists(old, new):
    """Each alias leads to a module of the new house, and no file of the old name is left."""
    assert importlib.util.find_spec(new) is not None, (old, new)
    assert not os.path.exists(os.path.join(ROOT, *old.split(".")) + ".py")


# (what a notebook of the flat layout imports, the module that has it now); draaw_mi.render,
# .fit, .denoise and .batch.plan name functions, so their old modules are stand-ins
OLD_NAMES = [
    ("draaw_mi.render", "MAX_PASS_SPP", "draaw_mi.rendering.renderer"),
    ("draaw_mi.render", "FREEZE_MAX_SPP", "draaw_mi.rendering.session"),
    ("draaw_mi.render", "sample_passes", "draaw_mi.rendering.passes"),
    ("draaw_mi.fit", "ZERO_GRADIENT_ITERATIONS", "draaw_mi.fitting.fitter"),
    ("draaw_mi.denoise", "denoise_aovs", "draaw_mi.rendering.denoiser"),
    ("draaw_mi.batch.plan", "plan", "draaw_mi.batch.planner"),
    ("draaw_mi.bench", "measure_group", "draaw_mi.bench.study"),
    ("draaw_mi.bench", "estimate_bias", "draaw_mi.bench.bias"),
    ("draaw_mi.cli", "CliError", "draaw_mi.cli.common"),
    ("draaw_mi.batch", "Manifest", "draaw_mi.batch.manifest"),
    ("draaw_mi.batch", "remove_temp_files", "draaw_mi.batch.runner"),
    ("draaw_mi.scene", "build_mitsuba_dict", "draaw_mi.scene.description"),
    ("draaw_mi.scene", "filter_plugin", "draaw_mi.integrators.features"),
    ("draaw_mi.materials", "FOV_RANGE", "draaw_mi.limits"),
    ("draaw_mi.integrators", "RenderError", "draaw_mi.errors"),
]


@pytest.mark.parametrize("old, name, new", OLD_NAMES)
def test_the_old_names_of_faces_and_shadowed_modules_work_with_a_warning_at_the_callers_line(old, name, new):
    importlib.import_module(old)
    names = {}
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("default")                 # once per line, as a notebook shows them
        exec(compile(f"from {old} import {name} as value", __file__, "exec"), names)
    assert names["value"] is getattr(importlib.import_module(new), name)
    assert [w.category for w in said] == [DeprecationWarning], [str(w.message) for w in said]
    assert str(said[0].message) == (f"{old}.{name} is now {new}.{name}: import it from there "
                                    f"({old}.{name} goes in the next release)")
    assert said[0].filename == __file__                    # the line that named it, in a notebook too


def test_the_shadowed_modules_leave_the_functions_alone_and_say_what_is_gone():
    """``import draaw_mi.render`` (the old module) must not turn ``draaw_mi.render`` into a
    module; a constant set through the old path is set where it is read now; a name the new
    house has no more says what replaced it."""
    import draaw_mi.batch
    import draaw_mi.render  # noqa: F401  (the old module path)
    from draaw_mi.rendering import session
    assert callable(draaw_mi.render) and callable(draaw_mi.fit) and callable(draaw_mi.batch.plan)
    old = sys.modules["draaw_mi.render"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        old.FREEZE = False
        try:
            assert session.FREEZE is False
        finally:
            old.FREEZE = True
        with pytest.raises(ImportError, match=r"draaw_mi.render.make_integrator is gone: session_of\(scene\) "
                                              r".*\.integrator\(version, max_depth"):
            from draaw_mi.render import make_integrator  # noqa: F401
        with pytest.raises(ImportError, match="cannot import name 'no_such_name'"):
            from draaw_mi.render import no_such_name  # noqa: F401
    assert session.FREEZE is True


def test_a_plain_import_leaves_the_heavy_and_optional_parts_unloaded():
    """``import draaw_mi`` (about 0.35 s) loads no wing that only some work needs, no media
    code (loaded with the first scene that has media) and none of the libraries that cost
    0.1-0.9 s to import or are optional; each is loaded where it is used."""
    code = ("import sys, draaw_mi\n"
            "print(' '.join(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('trimesh', 'colour', 'matplotlib', 'OpenEXR', 'distributed', 'dask', 'pyoidn', 'ipywidgets', "
            "'tqdm', 'scipy') or m.startswith(('draaw_mi.batch', 'draaw_mi.bench', 'draaw_mi.cli', 'draaw_mi.media', "
            "'draaw_mi.widgets', 'draaw_mi.integrators.volume')))))\n")
    out = _python(code)
    assert out.stdout.strip() == "", out.stdout
