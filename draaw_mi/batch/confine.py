"""Every file a batch writes lies under its output folder (``--out``, else the current folder).

Manifests come from other people on a render farm. So an output pattern or log name that
climbs out (``../``) or starts at the file system's root is refused when the manifest is read
(:func:`check_relative`), every frame's file is checked once its fields are filled in
(:func:`check_inside`: a field value cannot smuggle ``..`` in either), and the check follows
symbolic links: a folder under the root that links elsewhere is not written through
(:func:`inside` compares real paths). ``allow_outside_out`` (``--allow-outside-out``) lifts
all of it for manifests the user trusts.

>>> inside("/r/out/job/0001.exr", "/r/out"), inside("/r/out/../x.exr", "/r/out")
(True, False)
"""
from __future__ import annotations

import os

from ..errors import SceneError

#: what a refusal suggests
ALLOW_FLAG = "--allow-outside-out (batch.run(..., allow_outside_out=True))"


def check_relative(name: str, where, what: str) -> None:
    """Refuse ``name`` (an output pattern or a log file name, as the manifest writes it) when it
    is absolute or has a ``..`` part: it would put files outside the output folder."""
    parts = name.replace("\\", "/").split("/")
    if os.path.isabs(name) or name.startswith(("/", "\\")):
        raise where.error(f"{name!r} is an absolute path; {what} must lie under the output folder "
                          f"(--out): give a relative one, or pass {ALLOW_FLAG}")
    if ".." in parts:
        raise where.error(f"{name!r} climbs out of the output folder (--out) with '..'; give a path "
                          f"under it, or pass {ALLOW_FLAG}")


def inside(path: str, root: str) -> bool:
    """Whether ``path`` lies under the folder ``root``, symbolic links followed (a part of
    ``path`` that does not exist yet is taken as written)."""
    real_root = os.path.realpath(root)
    real = os.path.realpath(path)
    return real == real_root or real.startswith(real_root.rstrip(os.sep) + os.sep)


def check_inside(path: str, root: str | None, where: str, what: str) -> None:
    """Raise :class:`~draaw_mi.errors.SceneError` when ``path`` lies outside ``root`` (None:
    no confinement). ``what`` names the file (``"job 'a' frame 3"``, ``"the log"``)."""
    if root is None or inside(path, root):
        return
    real = os.path.realpath(path)
    how = ("through a symbolic link" if os.path.normpath(os.path.abspath(path)).startswith(
        os.path.abspath(root).rstrip(os.sep) + os.sep) else "")
    raise SceneError(f"{where}: {what} would be written to {real!r}, outside the output folder "
                     f"{os.path.realpath(root)!r}{' ' + how if how else ''}; pass {ALLOW_FLAG} to allow it")
