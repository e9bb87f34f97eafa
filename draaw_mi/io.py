"""Image I/O: float32 multi-channel EXR (atomic writes, OpenEXR channel naming) and sRGB PNG.

Channel naming follows OpenEXR conventions: the colour channels are ``R, G, B`` (and ``A``),
AOVs use ``layer.channel`` names such as ``depth.Z``, ``N.X`` or ``albedo.R``. Writes go to a
temporary file in the target folder and are renamed into place, so a crash never leaves a
truncated image behind.

Example::

    >>> import numpy as np, draaw_mi, tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "x.exr")
    >>> draaw_mi.write_exr(path, np.ones((4, 5, 3), np.float32))
    >>> draaw_mi.read_exr(path).shape
    (4, 5, 3)
"""
from __future__ import annotations

import contextlib
import ctypes
import io
import os
import stat
import sys
import tempfile
import threading
from typing import Sequence

import mitsuba as mi
import numpy as np

from .errors import IOFailure

DEFAULT_NAMES = {1: ["Y"], 2: ["Y", "A"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}


def to_numpy(image, where: str = "to_numpy") -> np.ndarray:
    """An (H, W, C) float32 numpy copy of a TensorXf, Bitmap or array (2-D gets C = 1);
    ``where`` names the caller in the error."""
    arr = np.array(image, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3 or arr.shape[0] < 1 or arr.shape[1] < 1 or arr.shape[2] < 1:
        raise IOFailure(f"{where}: image of shape {arr.shape}; expected (H, W) or (H, W, C) with "
                        "H, W, C >= 1")
    return arr


def channel_names(n_channels: int, aov_names: Sequence[str] | None = None) -> list[str]:
    """Names for an image whose first channels are colour and the rest named AOVs.

    >>> channel_names(5, ['depth.Z', 'depth_log.Z'])
    ['R', 'G', 'B', 'depth.Z', 'depth_log.Z']
    """
    aov_names = list(aov_names or [])
    n_color = n_channels - len(aov_names)
    if n_color not in DEFAULT_NAMES:
        raise IOFailure(f"{n_channels} channels with {len(aov_names)} AOV names leaves {n_color} colour "
                        "channels; expected 1 to 4 (name every channel with channels=, e.g. the "
                        "'channels' of render(..., return_info=True))")
    return DEFAULT_NAMES[n_color] + aov_names


def _fsync(path: str, folder: bool = False) -> None:
    """Flush ``path``'s data (or a folder's entries) to the disk; best effort (some file
    systems refuse to sync a folder)."""
    try:
        fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if folder else 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str, suffix: str):
    """Yield a temporary path next to ``path``; rename it onto ``path`` if the block succeeds.

    The data is flushed to the disk before the rename and the folder after it: a rename alone
    survives a killed process, not a power cut or OS crash, after which a renamed file can
    hold an intact header over zeroed data (a batch would then count a broken frame as done).
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as e:
            raise IOFailure(f"cannot create folder {folder!r} for {path!r}: {e.strerror}") from None
    if os.path.isdir(path):
        raise IOFailure(f"cannot write {path!r}: it is a folder")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".draaw-", suffix=suffix, dir=folder)
    except OSError as e:
        raise IOFailure(f"cannot write {path!r}: {e.strerror}") from None
    os.close(fd)
    try:
        yield tmp
        try:                                 # a file replaced keeps its mode (as sed -i does:
            mode = stat.S_IMODE(os.stat(path).st_mode)      # a read-only or group-readable
        except OSError:                                     # output stays so, not 0644)
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o666 & ~umask            # mkstemp makes 0600 files; give the usual mode
        os.chmod(tmp, mode)
        _fsync(tmp)
        os.replace(tmp, path)
        _fsync(folder, folder=True)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_text(path: str, text: str) -> None:
    """Write ``text`` to ``path`` atomically (:func:`atomic_path`): reports, TOML, JSON, CSV.

    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "a", "r.md")
    >>> write_text(p, "# ok"); open(p).read()
    '# ok'
    """
    with atomic_path(path, ".tmp") as tmp:
        with open(tmp, "w") as fh:
            fh.write(text)


def print_report(text: str, path: str | None) -> None:
    """Print a benchmark's report and, when ``path`` is given, write it there atomically."""
    print(text)
    if path:
        write_text(path, text)


# names that promise another format: an EXR written under them opens nowhere
OTHER_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".hdr", ".webp")


def write_exr(path: str, image, channels: Sequence[str] | None = None, half: bool = False,
              metadata: dict | None = None) -> None:
    """Write an (H, W, C) image as a float32 (or half) scanline EXR, atomically.

    ``channels`` names every channel (default ``R, G, B[, A]`` then error); values that overflow
    float32 become ``inf`` as in any EXR writer — they are not clipped silently. ``metadata``:
    extra header attributes (str, int or float values), e.g. draaw-mi's ``draaw:*`` keys. An
    EXR attribute holds a 32-bit int or float: an int outside int32 is stored as its decimal
    string (as an int, a seed of 3000000000 reads back as -1294967296), a float is rounded to float32.
    """
    if os.fspath(path).lower().endswith(OTHER_IMAGE_SUFFIXES):
        raise IOFailure(f"write_exr({path!r}): the name says another image format; expected a "
                        "'.exr' name (write_png writes PNGs)")
    arr = to_numpy(image, f"write_exr({path!r})")
    try:
        names = list(channels) if channels is not None else channel_names(arr.shape[2])
    except IOFailure as e:
        raise IOFailure(f"write_exr({path!r}): {e}") from None
    if len(names) != arr.shape[2]:
        raise IOFailure(f"write_exr({path!r}): {len(names)} channel names for an image with "
                        f"{arr.shape[2]} channels")
    if len(set(names)) != len(names):
        raise IOFailure(f"write_exr({path!r}): duplicate channel names {names}")
    dtype = np.float16 if half else np.float32
    chans = {n: np.ascontiguousarray(arr[..., i].astype(dtype)) for i, n in enumerate(names)}
    import OpenEXR  # (15 ms to import: paid by EXR files only)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (metadata or {}).items():
        if key in header or not isinstance(value, (str, int, float)) or isinstance(value, bool):
            raise IOFailure(f"write_exr({path!r}): metadata {key!r} = {value!r}; expected a new "
                            "attribute name and a str, int or float value")
        if isinstance(value, int) and not -2 ** 31 <= value < 2 ** 31:
            value = str(value)      # (an EXR int is 32-bit: 3000000000 would read back -1294967296)
        header[key] = value
    with atomic_path(path, ".exr") as tmp:
        try:
            with OpenEXR.File(header, chans) as f:
                f.write(tmp)
        except Exception as e:  # noqa: BLE001 - OpenEXR raises bare RuntimeErrors
            raise IOFailure(f"write_exr({path!r}): {e}") from None


_FD_LOCK = threading.Lock()


@contextlib.contextmanager
def quiet_fds():
    """Send what C++ libraries write to file descriptors 1 and 2 and to Python's
    ``sys.stdout`` / ``sys.stderr`` (OpenEXR's ``Warning: ...`` and ``(EXR_ERR_...)`` lines, up
    to 18 for one cut-short file) to a buffer instead of the terminal; yields a list that holds
    the captured text once the block ends. The descriptors and streams are the process's:
    output of other threads during the block goes to the buffer too (an EXR read is short;
    concurrent reads take turns)."""
    captured: list[str] = []
    with _FD_LOCK, tempfile.TemporaryFile() as buf:
        _flush_all()
        try:
            saved = [os.dup(1), os.dup(2)]
        except OSError:                         # (no descriptors 1 and 2: nothing to quieten)
            yield captured
            return
        # (pybind11's py::print writes to sys.stdout, which need not be descriptor 1)
        python_streams, text = (sys.stdout, sys.stderr), io.StringIO()
        try:
            os.dup2(buf.fileno(), 1)
            os.dup2(buf.fileno(), 2)
            sys.stdout = sys.stderr = text
            yield captured
        finally:
            sys.stdout, sys.stderr = python_streams
            _flush_all()                # (C's stdout is buffered in a pipe or file)
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            buf.seek(0)
            captured.append(buf.read().decode("utf-8", "replace") + text.getvalue())


def _flush_all() -> None:
    """Flush Python's and the C library's buffered standard streams (what was written before
    a redirection goes where it was meant to, what is written during one goes to the buffer)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)


def _first_message(text: str, path: str) -> str:
    """OpenEXR's first captured line, without the file name it starts with."""
    for line in text.splitlines():
        line = line.strip()
        if line:
            return line.removeprefix(f"{path}:").strip()
    return ""


def read_exr(path: str, with_names: bool = False):
    """Read an EXR into an (H, W, C) float32 array, channels in a stable order.

    Colour channels come first (R, G, B[, A], X, Y, Z[, A] or Y[, A]), then the rest sorted by
    name. With
    ``with_names=True`` returns ``(array, names)``. A file that does not decode (cut short,
    damaged, not an EXR) raises one :class:`~draaw_mi.errors.IOFailure` line; OpenEXR's own
    messages about it are kept off the terminal (:func:`quiet_fds`), the first one quoted.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise IOFailure(f"read_exr: {path!r} does not exist")
    import OpenEXR  # (15 ms to import: paid by EXR files only)
    failure = None
    with quiet_fds() as noise:
        try:
            with OpenEXR.File(path, separate_channels=True) as f:
                chans = {n: np.asarray(c.pixels, dtype=np.float32) for n, c in f.channels().items()}
        except Exception as e:  # noqa: BLE001 - OpenEXR raises bare RuntimeError/ValueError
            failure = str(e)
    said = _first_message(noise[0] if noise else "", path)
    if failure is None and not chans:
        failure = "no channels"
    if failure is not None:
        with open(path, "rb") as fh:
            magic = fh.read(4)
        if magic != b"\x76\x2f\x31\x01":
            raise IOFailure(f"read_exr({path!r}): not a readable EXR file: not an EXR file at all "
                            "(it does not start with the EXR magic number)")
        raise IOFailure(f"read_exr({path!r}): not a readable EXR file: truncated or damaged "
                        f"({os.path.getsize(path)} bytes; OpenEXR: {said or failure})")
    order = [n for n in ("R", "G", "B", "X", "Y", "Z", "A") if n in chans]
    order += sorted(n for n in chans if n not in order)
    arr = np.stack([chans[n] for n in order], axis=-1)
    return (arr, order) if with_names else arr


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB values in [0, 1] -> linear (the inverse of :func:`srgb_encode`).

    >>> float(srgb_decode(np.array([0.5]))[0])  # doctest: +ELLIPSIS
    0.2140...
    """
    x = np.asarray(encoded)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB transfer function on linear values clipped to [0, 1].

    >>> float(srgb_encode(np.array([0.0031308]))[0])  # doctest: +ELLIPSIS
    0.0404...
    """
    x = np.clip(np.nan_to_num(linear, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def xyz_to_srgb_matrix() -> np.ndarray:
    """Mitsuba's XYZ -> linear sRGB matrix (3 x 3, applied as ``M @ xyz``)."""
    return np.array([np.array(mi.xyz_to_srgb(mi.Color3f(*map(float, e)))).ravel() for e in np.eye(3)]).T


def write_png(path: str, image, exposure: float = 0.0, text: dict | None = None,
              encoded: bool = False, channels: Sequence[str] | None = None) -> None:
    """Write the first 3 (or 4) channels as an 8-bit sRGB PNG, atomically: 1 (grey), 2 (grey,
    alpha), 3 (RGB) or 4 (RGBA) channels; of more (AOVs), the first 3. Alpha is stored linear,
    and a linear image's colour, premultiplied by alpha as films hold it, is stored straight
    (divided by alpha where alpha > 0), as PNG's alpha is.

    ``channels``: the image's channel names (``render(..., return_info=True)``'s
    ``info["channels"]``): then its colour channels are written (R, G, B; X, Y, Z converted to
    sRGB by Mitsuba's matrix; or Y), with A as alpha where there is one, and its AOVs left
    out. Without them an image of R, G, B and one AOV (``aovs = ["depth"]``) would be taken
    for RGBA, and X, Y, Z for R, G, B.

    ``exposure`` is in stops (the image is multiplied by 2**exposure before encoding);
    ``encoded``: the image is display-encoded already (a post chain that ends in ``srgb``,
    :func:`draaw_mi.post.display_encoded`) and is stored as it is;
    ``text``: string key/value pairs stored as PNG text chunks (Pillow reads them back as
    ``PIL.Image.open(path).text``).
    """
    import matplotlib.image  # (0.16 s to import: paid by PNG/JPEG files only)

    if not os.fspath(path).lower().endswith(".png"):
        # (no 8-bit PNG under an .exr name; write_exr refuses the mirror case)
        raise IOFailure(f"write_png({path!r}): expected a '.png' name (write_exr writes EXRs)")
    arr = to_numpy(image, f"write_png({path!r})")
    if channels is not None:
        names = list(channels)
        if len(names) != arr.shape[2]:
            raise IOFailure(f"write_png({path!r}): {len(names)} channel names for an image with "
                            f"{arr.shape[2]} channels")
        colour = next((c for c in (["R", "G", "B"], ["X", "Y", "Z"], ["Y"]) if set(c) <= set(names)), None)
        if colour is None:
            raise IOFailure(f"write_png({path!r}): channels {names}; expected R, G, B or Y (or X, "
                            "Y, Z) among them")
        arr = arr[..., [names.index(n) for n in colour + (["A"] if "A" in names else [])]]
        if colour[0] == "X":
            arr = arr.copy()
            arr[..., :3] = arr[..., :3] @ xyz_to_srgb_matrix().T
    c = arr.shape[2]
    rgb = np.repeat(arr[..., :1], 3, axis=2) if c in (1, 2) else arr[..., :3]
    if c in (2, 4) and not encoded:
        # a film's colour is premultiplied by its alpha (what EXR stores), a PNG's is not:
        # stored as it comes, partly covered pixels would be dark fringes (as in Mitsuba's own
        # film.write); alpha-0 pixels keep their colour (a visible sky)
        a = np.clip(np.nan_to_num(arr[..., c - 1:c]), 0.0, 1.0)      # (as stored below)
        rgb = np.where(a > 0, rgb / np.where(a > 0, a, 1.0), rgb)
    if encoded and exposure:
        raise IOFailure(f"write_png({path!r}): exposure={exposure!r} needs a linear image; "
                        "this one is display-encoded (encoded=True)")
    out = np.clip(np.nan_to_num(rgb), 0.0, 1.0) if encoded else srgb_encode(rgb * (2.0 ** exposure))
    if c in (2, 4):                  # (grey, alpha) keeps its alpha too
        out = np.concatenate([out, np.clip(np.nan_to_num(arr[..., c - 1:c]), 0, 1)], axis=2)
    u8 = np.round(out * 255.0).astype(np.uint8)
    with atomic_path(path, ".png") as tmp:
        try:
            matplotlib.image.imsave(tmp, u8, format="png", metadata=text)
        except Exception as e:  # noqa: BLE001
            raise IOFailure(f"write_png({path!r}): {e}") from None
