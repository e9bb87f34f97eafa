"""The documentation site builds with warnings as errors (``sphinx-build -W -n``, as ``make
docs``), and its pages cover what they promise: every public name, every plugin, every CLI
subcommand, every sample scene and every stored tutorial.

The full build goes to a temporary folder (the docs' own ``docs/_build`` is left alone). A
second, tiny build with the site's configuration shows that a cross-reference to a draaw-mi
name that does not exist fails the build while one to a real but unlisted object does not.
Skipped when Sphinx is not installed (``pip install -e '.[docs]'``; the ``dev`` extra has it).
"""
from __future__ import annotations

import glob
import json
import os
import re
import subprocess
import sys
from html import unescape

import pytest
import tomllib

pytest.importorskip("sphinx", reason="Sphinx is not installed (pip install -e '.[docs]')")
pytest.importorskip("myst_nb", reason="myst-nb is not installed (pip install -e '.[docs]')")
pytest.importorskip("sphinxarg", reason="sphinx-argparse is not installed (pip install -e '.[docs]')")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DOCS = os.path.join(ROOT, "docs")


def _sphinx(src: str, out: str, builder: str = "html", conf_dir: str | None = None):
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-q", "-b", builder,
           "-d", os.path.join(out, ".doctrees")]
    if conf_dir:
        cmd += ["-c", conf_dir]
    return subprocess.run(cmd + [src, out], capture_output=True, text=True, timeout=900, cwd=ROOT)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The whole site, built once for this module's tests: (html folder, sphinx's output)."""
    out = tmp_path_factory.mktemp("docs") / "html"
    r = _sphinx(DOCS, str(out))
    return out, r


def test_the_site_builds_without_a_warning(site):
    out, r = site
    assert r.returncode == 0 and "WARNING" not in r.stderr and "ERROR" not in r.stderr, r.stderr[-4000:]
    assert (out / "index.html").is_file()


def _text(out, page: str) -> str:
    return (out / page).read_text(encoding="utf-8")


def _words(html: str) -> str:
    """The page's text: tags (such as the highlighter's spans) removed, entities decoded."""
    return unescape(re.sub(r"<[^>]+>", "", html))


def test_every_public_name_has_an_entry(site):
    """Each name of ``draaw_mi.__all__`` and of each wing's face is documented (an ``id`` anchor
    of its full dotted name), and the package's own docs import without a moved-module warning
    (the build would fail on one)."""
    import draaw_mi
    out, r = site
    assert r.returncode == 0, r.stderr[-2000:]
    pages = {"draaw_mi": "api/index.html"}
    pages.update({f"draaw_mi.{w}": f"api/{w}.html" for w in
                  ("post", "scene", "rendering", "fitting", "media", "sdf", "batch", "widgets")})
    missing = []
    for modname, page in pages.items():
        html = _text(out, page)
        module = sys.modules.get(modname) or __import__(modname, fromlist=["_"])
        for name in module.__all__:
            if f'id="{modname}.{name}"' not in html and f"{modname}.{name}" not in html:
                missing.append(f"{modname}.{name} ({page})")
    assert not missing, missing
    assert set(draaw_mi.__all__) >= {"render", "load_scene", "fit", "post"}


def test_every_plugin_and_subcommand_has_a_section(site):
    out, _ = site
    plugins = _text(out, "reference/plugins.html")
    for anchor in ("integrator-draaw-v1", "integrator-draaw-v2", "integrator-draaw-v3",
                   "integrator-draaw-v4", "bsdf-draaw"):
        assert f'id="{anchor}"' in plugins, anchor
    # the parameter tables are real tables, with Mitsuba's columns
    assert plugins.count("<th class=\"head\"><p>Parameter</p></th>") >= 5
    for parameter in ("scatter", "max_depth", "roughness", "normalmap_encoding"):
        assert f"<p>{parameter}</p>" in plugins, parameter
    cli = _text(out, "reference/cli.html")
    for command in ("render", "info", "fit", "bench", "post", "batch"):
        assert re.search(rf'<section id="draaw-mi-{command}"', cli), command
    assert "--time-budget" in cli and "--dry-run" in cli


def test_gallery_tutorials_and_benchmarks_are_shown(site):
    """The gallery shows every sample scene's stored image, each tutorial page has images from
    its stored outputs, and every recorded benchmark result has a page."""
    out, _ = site
    gallery = _text(out, "gallery.html")
    scenes = []
    for path in glob.glob(os.path.join(ROOT, "scenes", "*.toml")):
        with open(path, "rb") as fh:
            if "jobs" not in tomllib.load(fh):              # a batch manifest is not a scene
                scenes.append(os.path.basename(path)[:-5])
    assert len(scenes) >= 5
    for name in scenes:
        assert f"draaw-mi render scenes/{name}.toml -o out/{name}.exr" in _words(gallery), name
        assert f'src="_images/{name}.png"' in gallery and (out / "_images" / f"{name}.png").is_file(), name
    for nb in glob.glob(os.path.join(DOCS, "tutorials", "*.ipynb")):
        name = os.path.basename(nb)[:-6]
        stored = json.load(open(nb, encoding="utf-8"))
        n_png = sum("image/png" in o.get("data", {}) for c in stored["cells"] for o in c.get("outputs", []))
        html = _text(out, f"tutorials/{name}.html")
        assert html.count("<img") >= n_png, name
    # (the four records beside the scripts had no page; a script's *_latest.md run is not one)
    results = [p for p in glob.glob(os.path.join(ROOT, "benchmarks", "results", "*.md"))
               + glob.glob(os.path.join(ROOT, "benchmarks", "*.md"))
               if not p.endswith(("_latest.md", "README.md"))]
    assert any(p.endswith("bsdf_speed.md") for p in results)
    for path in results:
        assert (out / "benchmarks" / (os.path.basename(path)[:-3] + ".html")).is_file(), path
    assert not list((out / "benchmarks").glob("*_latest.html"))


def test_stored_tutorials_have_outputs():
    """Every notebook has an executed copy with outputs in docs/tutorials (the build shows them:
    it executes nothing), and the copies stay small."""
    names = sorted(os.path.basename(p)[:-6] for p in glob.glob(os.path.join(ROOT, "notebooks", "*.ipynb")))
    assert names
    for name in names:
        path = os.path.join(DOCS, "tutorials", f"{name}.ipynb")
        assert os.path.isfile(path), f"{path} missing: run docs/execute_notebooks.py {name}"
        nb = json.load(open(path, encoding="utf-8"))
        outputs = [o for c in nb["cells"] if c["cell_type"] == "code" for o in c["outputs"]]
        assert outputs and not [o for o in outputs if o["output_type"] == "error"], name
        assert os.path.getsize(path) < 1_500_000, name


def _tiny_site(tmp_path, body: str):
    """A one-page site with the real configuration (extensions, nitpicky settings) that
    documents ``draaw_mi.render`` and then ``body`` (MyST)."""
    src = tmp_path / "src"
    src.mkdir(parents=True)
    (src / "conf.py").write_text(
        f"import os\n_real = {os.path.join(DOCS, 'conf.py')!r}\n"
        "_ns = {'__file__': _real, '__name__': 'conf'}\n"
        "exec(compile(open(_real).read(), _real, 'exec'), _ns)\n"
        "globals().update({k: v for k, v in _ns.items() if not k.startswith('__')})\n"
        "html_static_path = []\nhtml_favicon = None\n", encoding="utf-8")
    (src / "index.md").write_text("# Tiny\n\n```{eval-rst}\n.. autofunction:: draaw_mi.render\n```\n\n"
                                  + body + "\n", encoding="utf-8")
    return _sphinx(str(src), str(tmp_path / "out"))


@pytest.mark.slow          # a second build (9 s): that the check above can fail
def test_a_broken_cross_reference_fails_the_build(tmp_path):
    """A ``{py:func}`` reference to a draaw-mi name that does not exist fails the build and the
    message names it; the same page with references to a documented function and to a real
    object without a page of its own builds cleanly (so the failure is the broken reference's)."""
    good = ("See {py:func}`draaw_mi.render` and {py:class}`draaw_mi.integrators.phong.PhongMaterial`"
            " (real, no page of its own).")
    ok = _tiny_site(tmp_path / "ok", good)
    assert ok.returncode == 0, ok.stderr[-3000:]
    bad = _tiny_site(tmp_path / "bad", good + " And {py:func}`draaw_mi.no_such_function`.")
    assert bad.returncode != 0
    assert "draaw_mi.no_such_function" in bad.stderr and "reference target not found" in bad.stderr, bad.stderr[-3000:]


@pytest.mark.slow          # the same, for a moved module path (5 s)
def test_documenting_a_moved_module_path_fails_the_build(tmp_path):
    """The API pages must name the modules' real homes: autodoc of an old flat path such as
    ``draaw_mi.preview`` (served with a DeprecationWarning) fails the build, naming the new one."""
    r = _tiny_site(tmp_path, "```{eval-rst}\n.. automodule:: draaw_mi.preview\n   :no-members:\n```")
    assert r.returncode != 0
    assert "DeprecationWarning" in r.stderr and "draaw_mi.rendering.preview" in r.stderr, r.stderr[-3000:]
