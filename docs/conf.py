"""Sphinx configuration of draaw-mi's documentation site (``make docs`` -> docs/_build/html).

Built with warnings as errors (``sphinx-build -W --keep-going -n``): a broken cross-reference,
a docstring that is not valid reStructuredText or a DeprecationWarning from a moved draaw-mi
module fails the build. The notebooks are not executed here: ``docs/tutorials/*.ipynb`` hold
their stored outputs (``docs/execute_notebooks.py`` refreshes them).
"""
from __future__ import annotations

import os
import sys

DOCS = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(DOCS)
sys.path.insert(0, os.path.join(DOCS, "_ext"))
sys.path.insert(0, ROOT)

project = "draaw-mi"
author = "the draaw-mi authors"
copyright = "draaw-mi authors; BSD-3-Clause"
release = version = "0.1.0"

extensions = [
    "myst_nb",                     # MyST markdown pages and the stored notebooks
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",         # the package's numpy/Google-style sections
    "sphinxarg.ext",               # the CLI reference from draaw_mi.cli.parser.build_parser()
    "draaw_docs",                  # docs/_ext: plugin tables, API pages from __all__, reference checks
]

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**/.ipynb_checkpoints", "execute_notebooks.py",
                    "make_gallery.py"]
templates_path: list[str] = []

# -- MyST / myst-nb ---------------------------------------------------------------------------
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
suppress_warnings = ["myst.header"]     # recorded benchmark results skip heading levels
nb_execution_mode = "off"          # outputs are stored in docs/tutorials/*.ipynb
nb_merge_streams = True

# -- autodoc ----------------------------------------------------------------------------------
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autodoc_inherit_docstrings = False     # a Mapping's keys() would show dict's docstring
napoleon_google_docstring = True
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True

# -- nitpicky references ----------------------------------------------------------------------
# Names of other packages (no intersphinx: the site builds offline) are not ours to resolve;
# every draaw_mi name must exist (docs/_ext/draaw_docs.py resolves the ones with no page of
# their own and reports the rest).
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(mi|mitsuba|dr|drjit|np|numpy|nbformat|ipywidgets|widgets|trimesh|pathlib|os|"
               r"collections|typing|concurrent|threading|argparse|enum|dataclasses|types|json|io|"
               r"matplotlib|distributed|dask|jupyter_rfb|pyoidn|OpenEXR|colour|tomllib|tomli_w)(\..*)?"),
    (r"py:.*", r"(TensorXf|Float|UInt32|Bool|Array3f|Point3f|Vector3f|Color3f|ScalarFloat|Spectrum|"
               r"ndarray|ArrayLike|NDArray|PathLike|Path|Callable|Iterable|Iterator|Sequence|Mapping|"
               r"t\..*|Any|Self|Literal|Union|Optional|TextIO|Lock|RLock|Event|Thread|Future|"
               r"np\.ndarray|np\.float32|numpy\.typing.*)"),
    (r"py:.*", r"(Properties|Scene|Sensor|SurfaceInteraction3f|Ray3f|RayDifferential3f|BSDFContext|"
               r"BSDFSample3f|Sampler|Medium|Emitter|Shape|Film|Texture|ADIntegrator|RBIntegrator|"
               r"SamplingIntegrator|BSDF|Integrator|SceneParameters|Transform4f|ScalarTransform4f|"
               r"Frame3f|Point2f|Vector2f|Mask|Loop|Color0f)"),
]

# -- HTML -------------------------------------------------------------------------------------
html_theme = "furo"
html_title = "draaw-mi"
html_static_path = ["_static"]
html_favicon = "_static/favicon.png"     # else browsers ask for /favicon.ico (a 404 in the console)
html_last_updated_fmt = None
html_show_sourcelink = False

# Mitsuba's plugin docstrings use these substitutions and the ``monosp`` role (draaw_docs.py).
rst_prolog = """
.. |int| replace:: *int*
.. |float| replace:: *float*
.. |bool| replace:: *boolean*
.. |string| replace:: *string*
.. |spectrum| replace:: *spectrum*
.. |texture| replace:: *texture*
.. |true| replace:: ``true``
.. |false| replace:: ``false``
.. |exposed| replace:: **P**
.. |differentiable| replace:: **∂**
"""
