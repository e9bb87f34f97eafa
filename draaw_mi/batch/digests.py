"""Digests of what a frame's pixels depend on besides its spec: the scene file and the files
it reads (by content), and the versions of draaw-mi, Mitsuba and Dr.Jit."""
from __future__ import annotations

import hashlib
import os

import drjit as dr
import mitsuba as mi

from .. import __version__


def file_hash(path: str) -> str:
    """SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def versions() -> dict:
    """The versions that make a frame's pixels: draaw-mi's, Mitsuba's, Dr.Jit's and the variant."""
    return {"draaw_mi": __version__, "mitsuba": mi.__version__, "drjit": dr.__version__, "variant": mi.variant()}


def files_hash(paths) -> str | None:
    """One SHA-256 over the files a scene reads besides its own file (textures, meshes and
    their material libraries, environment maps, volume grids: ``scene.info["files"]``), by
    content and name; ``None`` for a scene that reads none."""
    if not paths:
        return None
    h = hashlib.sha256()
    for path in sorted(paths):
        h.update(f"{os.path.basename(path)}\0{file_hash(path)}\n".encode())
    return h.hexdigest()
