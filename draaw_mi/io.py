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
import math
import os
import stat
import tempfile
import warnings
from typing import Sequence

import mitsuba as mi
import numpy as np

from .errors import IOFailure, ParameterError, raise_if_interrupted
from .limits import HALF_MAX

DEFAULT_NAMES = {1: ["Y"], 2: ["Y", "A"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}


def openexr(where: str):
    """The ``OpenEXR`` module, imported on first use (15 ms: paid by EXR files only, so PNG
    renders and ``draaw-mi --help`` work without it); an :class:`IOFailure` naming ``where``
    and how to get it back when it cannot be imported (it is a core dependency)."""
    try:
        import OpenEXR
    except ImportError as e:
        raise_if_interrupted(e)          # (Ctrl-C or SIGTERM during the import: not a missing package)
        raise IOFailure(f"{where}: EXR files need the OpenEXR package, which cannot be imported ({e}); "
                        "reinstall draaw-mi (pip install -e .) or pip install OpenEXR") from None
    return OpenEXR


def to_numpy(image, where: str = "to_numpy") -> np.ndarray:
    """An (H, W, C) float32 numpy copy of a TensorXf, Bitmap or array (2-D gets C = 1);
    ``where`` names the caller in the error."""
    try:
        arr = np.array(image, dtype=np.float32)
    except (TypeError, ValueError) as e:    # a string, a list of lists of different lengths
        raise IOFailure(f"{where}: image of type {type(image).__name__} is not an array of numbers "
                        f"({e}); expected (H, W) or (H, W, C) values") from None
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
    # the folder as the OS resolves it (symbolic links followed, then ".."), and the file
    # renamed into that same folder: "d/missing/../x.exr" is d/x.exr for both (abspath alone
    # folded the ".." while os.replace, given the literal path, needed "missing" to exist)
    folder = os.path.realpath(os.path.dirname(path) or os.curdir)
    target = os.path.join(folder, os.path.basename(path))
    if not os.path.isdir(folder):
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as e:
            raise IOFailure(f"cannot create folder {folder!r} for {path!r}: {e.strerror}") from None
    if os.path.isdir(target):
        raise IOFailure(f"cannot write {path!r}: it is a folder")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".draaw-", suffix=suffix, dir=folder)
    except OSError as e:
        raise IOFailure(f"cannot write {path!r}: {e.strerror}") from None
    os.close(fd)
    try:
        yield tmp
        try:                                 # a file replaced keeps its mode (as sed -i does:
            mode = stat.S_IMODE(os.stat(target).st_mode)    # a read-only or group-readable
        except OSError:                                     # output stays so, not 0644)
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o666 & ~umask            # mkstemp makes 0600 files; give the usual mode
        os.chmod(tmp, mode)
        _fsync(tmp)
        try:
            os.replace(tmp, target)
        except OSError as e:
            raise IOFailure(f"cannot write {path!r}: renaming the finished file onto it failed: "
                            f"{e.strerror}") from None
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
    float32 become ``inf`` as in any EXR writer, and with ``half`` those beyond 65504 too, with a
    ``RuntimeWarning`` — they are not clipped silently. ``metadata``:
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
    # (the array is float32 already: only half can overflow here)
    over = half and bool(np.any(np.isfinite(arr) & (np.abs(arr) > HALF_MAX)))
    with np.errstate(over="ignore"):                     # (said once below, in our words)
        chans = {n: np.ascontiguousarray(arr[..., i].astype(dtype)) for i, n in enumerate(names)}
    if over:      # (one message for every file: Python shows it once per calling line)
        warnings.warn("write_exr: values beyond half's range (+-65504) are stored as +-inf; half=False "
                      "keeps them", RuntimeWarning, stacklevel=2)
    OpenEXR = openexr(f"write_exr({path!r})")
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


_EXR_MAGIC = b"\x76\x2f\x31\x01"
# scanlines per chunk of each compression (OpenEXR's Compression enum, 0..9)
_LINES_PER_CHUNK = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}


def exr_cut_short(path: str) -> str | None:
    """Why the single-part scanline EXR at ``path`` is cut short or damaged (its header, its
    offset table or a chunk reaching past the end of the file), or ``None`` when its layout is
    whole or is not one this check reads (tiled, multi-part, deep, an unknown compression).

    Checked in Python before OpenEXR opens the file: OpenEXR reports a cut file with a dozen
    lines of its own on the process's standard streams, which cannot be silenced for one
    thread only.

    >>> import os, tempfile, numpy as np
    >>> d = tempfile.mkdtemp(); p = os.path.join(d, "x.exr")
    >>> write_exr(p, np.zeros((64, 8, 3), np.float32))
    >>> exr_cut_short(p) is None
    True
    >>> data = open(p, "rb").read(); _ = open(p, "wb").write(data[:len(data) - 5])
    >>> exr_cut_short(p)
    'its last chunk of pixels ends 5 bytes past the end of the file'
    """
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        head = fh.read(min(size, 1 << 20))
        if head[:4] != _EXR_MAGIC:
            return None
        if len(head) < 8:
            return "it ends inside its version field"
        flags = int.from_bytes(head[4:8], "little")
        if flags & (0x200 | 0x800 | 0x1000):               # tiled, deep or multi-part
            return None
        pos, attrs = 8, {}
        while True:
            if pos >= len(head):
                return "it ends inside its header"
            if head[pos] == 0:
                pos += 1
                break
            name_end = head.find(b"\0", pos)
            type_end = head.find(b"\0", name_end + 1) if name_end >= 0 else -1
            if type_end < 0 or type_end + 5 > len(head):
                return "it ends inside its header"
            n = int.from_bytes(head[type_end + 1:type_end + 5], "little", signed=True)
            if n < 0 or type_end + 5 + n > len(head):
                return "it ends inside its header"
            attrs[head[pos:name_end]] = head[type_end + 5:type_end + 5 + n]
            pos = type_end + 5 + n
        window, compression = attrs.get(b"dataWindow"), attrs.get(b"compression")
        if window is None or len(window) != 16 or not compression or compression[0] not in _LINES_PER_CHUNK:
            return None
        ymin, ymax = (int.from_bytes(window[i:i + 4], "little", signed=True) for i in (4, 12))
        lines = _LINES_PER_CHUNK[compression[0]]
        chunks = max(0, -(-(ymax - ymin + 1) // lines))
        table_end = pos + 8 * chunks
        if table_end > size:
            return "it ends inside its table of chunk offsets"
        fh.seek(pos)
        offsets = np.frombuffer(fh.read(8 * chunks), dtype="<u8")
        if chunks and (offsets.min() < table_end or offsets.max() + 8 > size):
            return "its chunk offsets point past the end of the file"
        if chunks:
            last = int(offsets.max())
            fh.seek(last + 4)
            packed = int.from_bytes(fh.read(4), "little", signed=True)
            if last + 8 + packed > size:
                return f"its last chunk of pixels ends {last + 8 + packed - size} bytes past the end of the file"
    return None


def read_exr(path: str, with_names: bool = False):
    """Read an EXR into an (H, W, C) float32 array, channels in a stable order.

    Colour channels come first (R, G, B[, A], X, Y, Z[, A] or Y[, A]), then the rest sorted by
    name. With
    ``with_names=True`` returns ``(array, names)``. A file that does not decode (cut short,
    damaged, not an EXR) raises one :class:`~draaw_mi.errors.IOFailure` line; a scanline file
    cut short is found before OpenEXR reads it (:func:`exr_cut_short`), so OpenEXR's own
    messages about it never reach the terminal.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise IOFailure(f"read_exr: {path!r} " + ("is a folder; expected an EXR file" if os.path.isdir(path)
                                                  else "does not exist"))
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
        cut = exr_cut_short(path)
    except OSError as e:
        raise IOFailure(f"read_exr({path!r}): cannot read it: {e.strerror or e}") from None
    if magic != _EXR_MAGIC:
        raise IOFailure(f"read_exr({path!r}): not a readable EXR file: not an EXR file at all "
                        "(it does not start with the EXR magic number)")
    if cut is not None:
        raise IOFailure(f"read_exr({path!r}): not a readable EXR file: truncated or damaged "
                        f"({os.path.getsize(path)} bytes: {cut})")
    OpenEXR = openexr(f"read_exr({path!r})")
    try:
        with OpenEXR.File(path, separate_channels=True) as f:
            chans = {n: np.asarray(c.pixels, dtype=np.float32) for n, c in f.channels().items()}
    except Exception as e:  # noqa: BLE001 - OpenEXR raises bare RuntimeError/ValueError
        raise IOFailure(f"read_exr({path!r}): not a readable EXR file: truncated or damaged "
                        f"({os.path.getsize(path)} bytes; OpenEXR: {e})") from None
    if not chans:
        raise IOFailure(f"read_exr({path!r}): not a readable EXR file: it has no channels")
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


def _stops(exposure, path) -> float:
    """``write_png``'s exposure as a float: one finite number (a numpy or Dr.Jit value of one
    element too); NaN had written a black image, Inf a white one."""
    try:
        ok = not isinstance(exposure, (bool, np.bool_, str)) and np.size(exposure) == 1
        value = float(np.asarray(exposure, dtype=np.float64).reshape(-1)[0]) if ok else math.nan
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        raise ParameterError(f"write_png({path!r}): exposure={exposure!r}; expected a finite number of stops")
    return value


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

    ``exposure`` is in stops, a finite number (the image is multiplied by 2**exposure before
    encoding);
    ``encoded``: the image is display-encoded already (a post chain that ends in ``srgb`` or a
    GO-Draaw grade, :func:`draaw_mi.post.display_encoded`; a render of a scene whose ``[[post]]`` does:
    ``encoded=display_encoded(info["post"])`` with ``render(..., return_info=True)``) and is
    stored as it is;
    ``text``: string key/value pairs stored as PNG text chunks (Pillow reads them back as
    ``PIL.Image.open(path).text``).
    """
    from PIL import Image, PngImagePlugin  # (Pillow, matplotlib's own PNG writer: RGB stays RGB)

    if not os.fspath(path).lower().endswith(".png"):
        # (no 8-bit PNG under an .exr name; write_exr refuses the mirror case)
        raise IOFailure(f"write_png({path!r}): expected a '.png' name (write_exr writes EXRs)")
    # a finite number of stops (NaN wrote a black image, Inf a white one)
    exposure = _stops(exposure, path)
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
    if c in (2, 4):
        # a film's colour is premultiplied by its alpha (what EXR stores), a PNG's is not:
        # stored as it comes, partly covered pixels would be dark fringes (as in Mitsuba's own
        # film.write); alpha-0 pixels keep their colour (a visible sky). An encoded image from
        # a post chain is premultiplied too: its curves act on c / a and multiply a back
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
            info = PngImagePlugin.PngInfo()
            for key, value in (text or {}).items():
                info.add_text(str(key), str(value))
            # (matplotlib's imsave wrote every PNG as RGBA, an opaque alpha on colour alone)
            Image.fromarray(np.ascontiguousarray(u8), "RGBA" if u8.shape[2] == 4 else "RGB").save(
                tmp, format="png", pnginfo=info)
        except Exception as e:  # noqa: BLE001
            raise IOFailure(f"write_png({path!r}): {e}") from None
