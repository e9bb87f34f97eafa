"""Mitsuba's binary ``.vol`` grid format: read (validated) and write (atomic).

Layout (Mitsuba 3 ``src/volumes/grid.cpp``, format version 3): the bytes ``'V' 'O' 'L'``, the
version byte ``3``, an int32 encoding (``1`` = float32; the only one written by Mitsuba 3),
int32 ``xres, yres, zres, channels``, six float32 ``xmin, ymin, zmin, xmax, ymax, zmax``
(the grid's box; Mitsuba 3's ``gridvolume`` ignores it and maps the unit cube with its
``to_world``), then ``xres * yres * zres * channels`` float32 values, x fastest
(``data[((z * yres + y) * xres + x) * channels + c]``). Everything little-endian.

Example::

    >>> import numpy as np, tempfile, os
    >>> from draaw_mi.media.volfile import read_vol, write_vol
    >>> p = os.path.join(tempfile.mkdtemp(), "g.vol")
    >>> write_vol(p, np.ones((2, 3, 4, 1), np.float32), (0, 0, 0), (1, 1, 1))
    >>> data, lo, hi = read_vol(p)
    >>> data.shape, hi.tolist()
    ((2, 3, 4, 1), [1.0, 1.0, 1.0])
"""
from __future__ import annotations

import os
import struct

import numpy as np

from ..errors import IOFailure, ParameterError
from ..io import atomic_path

_HEADER = struct.Struct("<3sBiiiii6f")          # 48 bytes


def vol_box(path: str, lo, hi, bbox_min=None, bbox_max=None) -> tuple:
    """The world box of a grid read from ``path``: ``bbox_min`` / ``bbox_max`` where given, else
    the header's ``lo .. hi``; a header box that is empty on some axis (Mitsuba ignores it and
    may write zeros) is refused when no bounds replace it, saying where it came from."""
    if bbox_min is None and bbox_max is None and (np.asarray(hi) <= np.asarray(lo)).any():
        raise ParameterError(f"VoxelGrid.from_vol({path!r}): the file's header box "
                             f"{np.asarray(lo).tolist()}..{np.asarray(hi).tolist()} is empty (Mitsuba "
                             "ignores it and may leave it so); expected bbox_min < bbox_max on every axis: "
                             "give the grid's bounds (bbox_min=, bbox_max=; 'bounds' in a [[volumes]] entry)")
    return (lo if bbox_min is None else bbox_min), (hi if bbox_max is None else bbox_max)


def read_vol(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a ``.vol`` file: ``(data (Z, Y, X, C) float32, bbox_min (3,), bbox_max (3,))``.

    Raises :class:`IOFailure` for a missing/unreadable file and :class:`ParameterError` for a
    malformed one (bad magic, unsupported encoding, non-positive sizes, truncated data, bytes
    after the data). The header box is returned as stored, even when empty (Mitsuba ignores it).
    """
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as e:
        raise IOFailure(f"read_vol({path!r}): {e.strerror}") from None
    if len(raw) < _HEADER.size:
        raise ParameterError(f"read_vol({path!r}): file is {len(raw)} bytes, shorter than the "
                             f"{_HEADER.size}-byte .vol header (truncated?)")
    magic, version, enc, xr, yr, zr, ch, *box = _HEADER.unpack_from(raw)
    if magic != b"VOL":
        raise ParameterError(f"read_vol({path!r}): magic {magic!r}; expected b'VOL'")
    if version != 3:
        raise ParameterError(f"read_vol({path!r}): format version {version}; expected 3")
    if enc != 1:
        raise ParameterError(f"read_vol({path!r}): encoding {enc}; only 1 (float32) is supported")
    if min(xr, yr, zr, ch) < 1:
        raise ParameterError(f"read_vol({path!r}): size {xr}x{yr}x{zr}x{ch}; expected positive sizes")
    n = xr * yr * zr * ch
    body = len(raw) - _HEADER.size
    if body < 4 * n:
        raise ParameterError(f"read_vol({path!r}): {body} data bytes for a {xr}x{yr}x{zr}x{ch} grid; "
                             f"expected {4 * n} (truncated file)")
    if body > 4 * n:
        # (a size field written wrong, or two grids in one file: not to be read as this one)
        raise ParameterError(f"read_vol({path!r}): {body} data bytes for a {xr}x{yr}x{zr}x{ch} grid; "
                             f"expected {4 * n} ({body - 4 * n} bytes after the data)")
    data = np.frombuffer(raw, dtype="<f4", count=n, offset=_HEADER.size)
    data = data.reshape(zr, yr, xr, ch).astype(np.float32)
    lo = np.array(box[:3], dtype=np.float64)
    hi = np.array(box[3:], dtype=np.float64)
    return data, lo, hi


def write_vol(path: str, data: np.ndarray, bbox_min, bbox_max) -> None:
    """Write ``data`` of shape (Z, Y, X, C) (or (Z, Y, X)) as a float32 ``.vol``, atomically.

    The data must be real, finite and >= 0 (densities, albedos: what a grid volume holds) and
    the box ``bbox_min < bbox_max``, two 3-vectors; anything else is a :class:`ParameterError`
    (:meth:`VoxelGrid.from_vol <draaw_mi.media.VoxelGrid.from_vol>` would refuse the file)."""
    path = os.fspath(path)
    if np.iscomplexobj(data):
        raise ParameterError(f"write_vol({path!r}): complex data; expected real values")
    arr = np.asarray(data, dtype=np.float32)
    if arr.ndim == 3:
        arr = arr[..., None]
    if arr.ndim != 4 or min(arr.shape) < 1:
        raise ParameterError(f"write_vol({path!r}): data of shape {arr.shape}; expected (Z, Y, X[, C])")
    bad = ~np.isfinite(arr) | (arr < 0)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ParameterError(f"write_vol({path!r}): data{list(first)} = {float(arr[first])!r}; expected finite "
                             "values >= 0")
    try:
        lo = np.asarray(bbox_min, dtype=np.float64).reshape(-1)
        hi = np.asarray(bbox_max, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        lo = hi = np.empty(0)
    if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)) \
            or np.any(hi <= lo):
        raise ParameterError(f"write_vol({path!r}): box {bbox_min!r}..{bbox_max!r}; expected two finite "
                             "3-vectors with bbox_min < bbox_max on every axis")
    zr, yr, xr, ch = arr.shape
    lo, hi = lo.tolist(), hi.tolist()
    header = _HEADER.pack(b"VOL", 3, 1, xr, yr, zr, ch, *lo, *hi)
    with atomic_path(path, ".vol") as tmp:
        with open(tmp, "wb") as f:
            f.write(header)
            f.write(np.ascontiguousarray(arr, dtype="<f4").tobytes())
