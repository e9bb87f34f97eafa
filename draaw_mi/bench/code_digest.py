"""A hash of the code that a reference render runs, for the names of cached references.

The benches cache their high-spp references on disk (:func:`draaw_mi.bench.ground_truth`,
:func:`draaw_mi.bench.speed.reference`) under a hash of the scene. A reference also depends on
the code that renders it: the ``draaw`` BSDF that Mitsuba's ``path`` calls, and for SDF and
media scenes the draaw integrators; after a fix there, a cached reference would go on showing
the old result and every error measured against it would be wrong. :func:`code_digest` hashes
the sources of the subpackages that shape a rendered image, with the Mitsuba and Dr.Jit
versions, so such a change renders the reference anew (a change elsewhere, the CLI or the
plots, keeps it).

>>> len(code_digest())
12
"""
from __future__ import annotations

import functools
import hashlib
import os

import drjit as dr
import mitsuba as mi

#: the subpackages of draaw_mi whose code shapes a rendered image (``rendering``: a reference of
#: many passes is their weighted mean, made there)
RENDER_CODE = ("integrators", "materials", "media", "rendering", "scene", "sdf")


def code_digest(root: str | None = None) -> str:
    """A short hash of the ``.py`` sources under :data:`RENDER_CODE` of the package at
    ``root`` (default: this draaw_mi), with the Mitsuba and Dr.Jit versions."""
    return _this_package() if root is None else _digest(os.path.abspath(root))


@functools.lru_cache(maxsize=1)
def _this_package() -> str:
    # (read once per process: a study asks for each of its references)
    return _digest(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))     # draaw_mi/


def _digest(root: str) -> str:
    h = hashlib.sha256(f"mitsuba {mi.__version__} drjit {dr.__version__}".encode())
    for sub in RENDER_CODE:
        for folder, dirs, files in sorted(os.walk(os.path.join(root, sub))):
            dirs.sort()
            for name in sorted(f for f in files if f.endswith(".py")):
                path = os.path.join(folder, name)
                h.update(os.path.relpath(path, root).encode() + b"\0")
                with open(path, "rb") as f:
                    h.update(f.read() + b"\0")
    return h.hexdigest()[:12]
