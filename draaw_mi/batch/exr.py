"""Frame files: multi-layer EXR with draaw-mi metadata in the header, written atomically.

Colour is the default layer (``R, G, B``); AOVs are OpenEXR layers named by their prefix
(``depth.Z``, ``N.X/Y/Z``, ``albedo.R/G/B``). Header attributes (strings or numbers, readable
with ``exrheader`` or ``OpenEXR.File(path, header_only=True).header()``)::

    draaw:frame_hash   identity of the job (scene hash + settings + camera + overrides + versions)
    draaw:scene        scene file      draaw:scene_sha256   its SHA-256
    draaw:files_sha256 SHA-256 of the files the scene reads (textures, meshes...), if any
    draaw:job, draaw:frame, draaw:version (as given: v4, V2M, path), draaw:integrator (its
    Mitsuba plugin: draaw_v4, draaw_v2, path), draaw:spp, draaw:seed, draaw:max_depth
    draaw:render_seconds, draaw:rendered_at (UTC ISO time)
    draaw:draaw_mi, draaw:mitsuba, draaw:drjit, draaw:variant
    draaw:params  the frame's overrides (JSON: {parameter key: value}), if any
    draaw:camera  the frame's camera (JSON: origin, target, up, fov, and mirror: true for a
                  mirrored GO-Draaw view), if the job moves it
    draaw:post    the post chain applied to its colour (JSON), if any

A frame is *finished* when its file exists, its header is readable, its ``draaw:frame_hash``
equals the planned hash and its pixel data is all there (:func:`frame_status`,
:func:`exr_complete`: every chunk the offset table lists lies in the file, with a chunk header
of a non-empty size; the compressed bytes themselves are not read). The file is renamed into
place only after it is completely written, so draaw-mi never leaves a partial one; the last
check catches a file cut short later (a copy that ran out of disk, a partial rsync), whose
header still reads. Bytes changed inside a chunk (a disk's bad block, zeros written over the
middle of a file) leave its size intact: only decoding finds them (``frame_status(...,
verify=True)``, :func:`exr_decodes`), which costs a read of every pixel. A job with previews
also wants the frame's PNG, which carries the same hash as a text chunk and is written after
the EXR (a PNG is never there without its frame): a finished EXR whose PNG is missing or
another frame's (a run killed between the two writes, previews turned on later) gets its PNG
from the EXR, not a new render (:func:`write_preview`).
"""
from __future__ import annotations

import contextlib
import ctypes
import functools
import json
import os
import struct
import sys
import time

import numpy as np
from PIL import Image

from ..errors import IOFailure
from ..integrators import resolve_version
from ..io import openexr, read_exr, write_exr, write_png
from ..post import load_chain
from .digests import file_hash, versions

HASH_ATTR = "draaw:frame_hash"
MANIFEST_ATTR = "draaw:manifest"       # the absolute path of the manifest file that made a frame


def metadata(spec: dict, seconds: float, post: list | None = None) -> dict:
    """The header attributes of a rendered frame; ``post``: the chain applied (the job's, or
    its scene's own when the job gives none), recorded as ``draaw:post``."""
    meta = {HASH_ATTR: spec["hash"], "draaw:scene": spec["scene"], "draaw:scene_sha256": spec["scene_hash"],
            "draaw:job": spec["job"], "draaw:frame": int(spec["frame"]), "draaw:version": spec["version"],
            "draaw:integrator": resolve_version(spec["version"]),
            "draaw:spp": int(spec["spp"]), "draaw:sampler": str(spec.get("sampler")),
            "draaw:seed": int(spec["seed"]),
            "draaw:max_depth": int(spec["max_depth"]), "draaw:render_seconds": float(seconds),
            "draaw:rendered_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if spec.get("files_hash"):
        meta["draaw:files_sha256"] = spec["files_hash"]
    if spec.get("manifest"):
        meta[MANIFEST_ATTR] = spec["manifest"]
    shown = {"params": spec.get("params"), "camera": spec.get("camera"),
             "post": spec.get("post") if post is None else post}
    for key, value in shown.items():        # what the frame shows, readable from its file
        if value:
            meta[f"draaw:{key}"] = json.dumps(value)
    meta.update({f"draaw:{k}": str(v) for k, v in spec["versions"].items()})
    return meta


def render_metadata(scene_file, scene, info: dict, post=None) -> dict:
    """The ``draaw:*`` header attributes of one ``draaw-mi render`` EXR, as batch frames carry
    them: the scene (and its file's SHA-256), the integrator, sampler, spp, seed, depth, time,
    the post chain applied (``post``: a chain or a list of filter dicts; none: no attribute), an
    XML scene's ``$name`` defines (``draaw:defines``), the sensor where not the first
    (``draaw:sensor``: its index and id) and the versions of draaw-mi, Mitsuba and Dr.Jit. ``info``: what ``render(...,
    return_info=True)`` returned."""
    meta = {"draaw:scene": os.path.abspath(scene_file), "draaw:version": info["version"],
            "draaw:integrator": info["integrator"],
            "draaw:spp": int(info["spp"]), "draaw:seed": int(scene.settings["seed"]),
            "draaw:max_depth": int(scene.settings["max_depth"]),
            "draaw:render_seconds": float(info["seconds"]), "draaw:denoised": int(bool(info.get("denoised"))),
            "draaw:rendered_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if os.path.isfile(scene_file):
        meta["draaw:scene_sha256"] = file_hash(scene_file)
    meta["draaw:sampler"] = str(scene.settings.get("sampler") or "independent")
    defines = (scene.info.get("xml") or {}).get("defines")
    if defines:                              # (two -D values: two images, one header)
        meta["draaw:defines"] = json.dumps(defines, sort_keys=True, default=str)
    if post:
        meta["draaw:post"] = json.dumps(load_chain(post).to_list())
    if info.get("sensor"):                   # (another of the scene's sensors: --sensor)
        sensor = scene.mi_scene.sensors()[int(info["sensor"])]
        meta["draaw:sensor"] = f"{int(info['sensor'])} {sensor.id()}".strip()
    meta.update({f"draaw:{k}": str(v) for k, v in versions().items()})
    return meta


def write_frame(path: str, image: np.ndarray, channels, meta: dict, half: bool = False) -> None:
    """Write an (H, W, C) frame with named channels and header attributes, atomically
    (:func:`draaw_mi.io.write_exr` with ``metadata``)."""

    if image.ndim != 3 or image.shape[2] != len(channels):
        raise IOFailure(f"write_frame({path!r}): {len(channels)} channel names for an image of shape "
                        f"{image.shape}")
    write_exr(path, image, channels=list(channels), half=half, metadata=meta)


def read_header(path: str) -> dict | None:
    """The header of an EXR, or None when the file is missing or not a readable EXR."""
    if not os.path.isfile(path):
        return None
    OpenEXR = openexr(f"read_header({path!r})")      # (outside the try: no OpenEXR is no unread frame)
    try:
        with OpenEXR.File(path, header_only=True) as f:
            return dict(f.header())
    except Exception:  # noqa: BLE001 - any unreadable file counts as not finished
        return None


# scanlines per chunk of each OpenEXR compression (the ``compression`` attribute's value):
# NO, RLE, ZIPS, ZIP, PIZ, PXR24, B44, B44A, DWAA, DWAB
_LINES_PER_CHUNK = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}
_MAGIC = b"\x76\x2f\x31\x01"
_HEADER_READ = 1 << 18


def exr_complete(path: str) -> bool:
    """Whether the EXR at ``path`` holds all of its pixel data: every chunk its offset table
    lists starts after the table with a header of a non-empty size and lies inside the file.
    A file cut short keeps a readable header, so :func:`read_header` alone would take it for
    finished; a power cut can leave the header and table over zeroed blocks, whose chunks
    read as empty (every chunk is looked at: zeroed ones before the last count too). Reads
    the header, the offset table and 8 bytes per chunk, not the compressed bytes: zeros or
    other bytes written inside a chunk whose header is intact pass (:func:`exr_decodes`
    finds them). Files that are not single-part scanline images (tiled, deep, multi-part,
    newer compressions) are decoded in full instead.

    >>> import tempfile, numpy as np
    >>> from draaw_mi.io import write_exr
    >>> p = tempfile.mkdtemp() + "/f.exr"
    >>> write_exr(p, np.ones((8, 8, 3), np.float32))
    >>> exr_complete(p)
    True
    >>> with open(p, "r+b") as fh:
    ...     _ = fh.truncate(os.path.getsize(p) - 1)
    >>> exr_complete(p)
    False
    """
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as fh:
            head = fh.read(_HEADER_READ)
            layout = _scanline_layout(head)
            if layout is None:
                return exr_decodes(path)
            table_at, chunks = layout
            if table_at + 8 * chunks > size:
                return False
            fh.seek(table_at)
            offsets = struct.unpack(f"<{chunks}Q", fh.read(8 * chunks))
            data_at = table_at + 8 * chunks
            if min(offsets) < data_at or max(offsets) + 8 > size:
                return False
            for at in offsets:
                fh.seek(at)
                _, length = struct.unpack("<ii", fh.read(8))
                if length <= 0 or at + 8 + length > size:
                    return False
            return True
    except (OSError, struct.error, ValueError):
        return False


def _scanline_layout(head: bytes):
    """``(offset table position, chunk count)`` of a single-part scanline EXR from the
    file's first bytes, or ``None`` when the file is of another kind (or its header is longer
    than what was read)."""
    if head[:4] != _MAGIC:
        raise ValueError("not an EXR file")
    flags = int.from_bytes(head[4:8], "little")
    if flags & (0x200 | 0x800 | 0x1000):            # tiled, deep ("non-image"), multi-part
        return None
    pos, window, compression, count = 8, None, None, None
    while True:
        try:
            end = head.index(b"\0", pos)
            name = head[pos:end]
            if not name:
                pos = end + 1
                break
            tend = head.index(b"\0", end + 1)
            (length,) = struct.unpack_from("<i", head, tend + 1)
        except (ValueError, struct.error):
            # the header goes on past the bytes read (a large draaw:params): decode in full
            # (else a complete frame reads as 'damaged' and renders again on every run)
            return None
        value = head[tend + 5:tend + 5 + length]
        if len(value) != length:
            return None
        if name == b"dataWindow":
            window = struct.unpack("<iiii", value)
        elif name == b"compression":
            compression = value[0]
        elif name == b"chunkCount":
            (count,) = struct.unpack("<i", value)
        pos = tend + 5 + length
    if count is None:
        lines = _LINES_PER_CHUNK.get(compression)
        if window is None or lines is None:
            return None
        count = -(-(window[3] - window[1] + 1) // lines)
    return (pos, count) if count > 0 else None


def exr_decodes(path: str) -> bool:
    """Whether every channel of the EXR at ``path`` decodes: every chunk is read and
    decompressed, so bytes changed inside a chunk whose size is intact are found (draaw-mi
    writes ZIP-compressed frames, whose zlib checksum fails on them), as :func:`exr_complete`
    cannot. OpenEXR's own messages about a chunk it cannot decompress are silenced
    (:func:`quiet_native_output`): the caller reports the frame."""
    OpenEXR = openexr(f"exr_decodes({path!r})")
    try:
        with quiet_native_output(), OpenEXR.File(path) as f:
            for channel in f.channels().values():
                channel.pixels                          # noqa: B018 - decoding is the check
        return True
    except Exception:  # noqa: BLE001 - any failure to decode is a damaged file
        return False


def read_frame(path: str, with_names: bool = False):
    """:func:`draaw_mi.io.read_exr` with OpenEXR's own messages silenced: a frame that does not
    decode raises one :class:`~draaw_mi.errors.IOFailure`, and nothing else reaches the
    terminal."""
    with quiet_native_output():
        return read_exr(path, with_names=with_names)


@functools.cache
def _c_fflush():
    """The C library's ``fflush``, looked up once; None where there is none to ask."""
    try:
        return ctypes.CDLL(None).fflush
    except (OSError, AttributeError, TypeError):
        return None


def _flush_c_stdio() -> None:
    fflush = _c_fflush()
    if fflush is not None:                       # (no C library: nothing buffered there)
        fflush(None)


@contextlib.contextmanager
def quiet_native_output():
    """Nothing written to standard output or error reaches them during the block. OpenEXR's C
    library reports a chunk it cannot decompress on standard error (``(EXR_ERR_CORRUPT_CHUNK)
    Unable to decompress ...``) and its Python binding prints a warning to ``sys.stdout``
    before it raises; the binding offers no way to turn either off, so file descriptors 1 and
    2 go to the null device and ``sys.stdout`` / ``sys.stderr`` are swapped for it too (they
    need not write to the descriptors: a notebook's, pytest's). Python's and C's buffers are
    flushed on both sides (nothing written before lands in the block, nothing written in it
    comes out after). What other threads of the process write meanwhile is lost too: the
    batch runner reads frames this way while it renders nothing (before its executor
    starts, after it ends)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):          # (a closed or replaced stream)
            stream.flush()
    _flush_c_stdio()
    try:
        null = os.open(os.devnull, os.O_WRONLY)
    except OSError:
        yield
        return
    saved = []
    try:
        for fd in (1, 2):
            try:
                saved.append((fd, os.dup(fd)))
                os.dup2(null, fd)
            except OSError:           # (a descriptor that is not open: nothing to silence)
                pass
        with open(os.devnull, "w", encoding="utf-8") as sink, contextlib.redirect_stdout(sink), \
                contextlib.redirect_stderr(sink):
            yield
    finally:
        _flush_c_stdio()
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)
        os.close(null)


def frame_status(spec: dict, verify: bool = False) -> str:
    """``"done"`` (present, hash matches, pixel data complete), ``"stale"`` (present, another
    job's settings), ``"foreign"`` (present, other settings, and made by another manifest
    file: :func:`draaw_mi.batch.run` does not replace it unless told to), ``"damaged"``
    (present but unreadable or cut short; with ``verify``, also one whose pixel data does not
    decode: :func:`exr_decodes`), ``"missing"``, or ``"no-preview"`` (the EXR is done, the
    preview the job asks for is missing or stale). Without ``verify`` it reads the header, the
    offset table and 8 bytes per chunk (:func:`exr_complete`); ``verify`` decodes the whole
    file of a frame that passes those."""
    header = read_header(spec["output"])
    if header is None:
        return "damaged" if os.path.exists(spec["output"]) else "missing"
    if header.get(HASH_ATTR) != spec["hash"]:
        other, mine = header.get(MANIFEST_ATTR), spec.get("manifest")
        return "foreign" if other and mine and other != mine else "stale"
    if not exr_complete(spec["output"]) or (verify and not exr_decodes(spec["output"])):
        return "damaged"
    if spec.get("preview"):
        tag = _png_hash(preview_path(spec))
        # a PNG without a hash comes from a draaw-mi whose previews carry none, written after
        # its EXR: it is this frame's
        if tag is None or (tag and tag != spec["hash"]):
            return "no-preview"
    return "done"


def preview_path(spec: dict) -> str:
    """The PNG preview beside a frame's EXR."""
    return os.path.splitext(spec["output"])[0] + ".png"


def write_preview(spec: dict, image: np.ndarray | None = None, channels=None) -> None:
    """Write the frame's sRGB PNG preview, tagged with its hash; ``image`` and its
    ``channels``: the rendered frame, or ``None`` to take both from the finished EXR. The
    colour is taken by name (by position, a luminance frame's preview would take Y and two
    AOVs as R, G, B)."""

    if image is None:
        image, channels = read_frame(spec["output"], with_names=True)
    write_png(preview_path(spec), image, channels=channels, text={HASH_ATTR: spec["hash"]},
              encoded=bool(spec.get("encoded")))


def _png_hash(path: str) -> str | None:
    """The frame hash a preview carries, ``""`` for a PNG without one, ``None`` for a missing,
    unreadable or cut-short file (its hash, written ahead of the pixels, survives a cut: the
    file must end in the IEND chunk)."""

    try:
        with open(path, "rb") as f:
            f.seek(-len(_PNG_END), os.SEEK_END)
            if f.read() != _PNG_END:
                return None
        with Image.open(path) as im:          # reads the chunks before the pixels only
            return str(im.info.get(HASH_ATTR, ""))
    except (OSError, ValueError):
        return None


_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"     # the IEND chunk: length 0, type, CRC
