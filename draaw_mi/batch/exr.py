"""Frame files: multi-layer EXR with draaw-mi metadata in the header, written atomically.

Colour is the default layer (``R, G, B``); AOVs are OpenEXR layers named by their prefix
(``depth.Z``, ``N.X/Y/Z``, ``albedo.R/G/B``). Header attributes (strings or numbers, readable
with ``exrheader`` or ``OpenEXR.File(path, header_only=True).header()``)::

    draaw:frame_hash   identity of the job (scene hash + settings + camera + overrides + versions)
    draaw:scene        scene file      draaw:scene_sha256   its SHA-256
    draaw:job, draaw:frame, draaw:version, draaw:spp, draaw:seed, draaw:max_depth
    draaw:render_seconds, draaw:rendered_at (UTC ISO time)
    draaw:draaw_mi, draaw:mitsuba, draaw:drjit, draaw:variant

A frame is *finished* when its file exists, its header is readable and its ``draaw:frame_hash``
equals the planned hash (:func:`frame_status`). Because the file is renamed into place only
after it is completely written, a present file is never a partial one.
"""
from __future__ import annotations

import os
import time

import numpy as np

from ..errors import IOFailure
from ..io import atomic_path

HASH_ATTR = "draaw:frame_hash"


def metadata(spec: dict, seconds: float) -> dict:
    """The header attributes of a rendered frame."""
    meta = {HASH_ATTR: spec["hash"], "draaw:scene": spec["scene"], "draaw:scene_sha256": spec["scene_hash"],
            "draaw:job": spec["job"], "draaw:frame": int(spec["frame"]), "draaw:version": spec["version"],
            "draaw:spp": int(spec["spp"]), "draaw:sampler": str(spec.get("sampler")),
            "draaw:seed": int(spec["seed"]),
            "draaw:max_depth": int(spec["max_depth"]), "draaw:render_seconds": float(seconds),
            "draaw:rendered_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    meta.update({f"draaw:{k}": str(v) for k, v in spec["versions"].items()})
    return meta


def write_frame(path: str, image: np.ndarray, channels, meta: dict, half: bool = False) -> None:
    """Write an (H, W, C) frame with named channels and header attributes, atomically."""
    import OpenEXR

    if image.ndim != 3 or image.shape[2] != len(channels):
        raise IOFailure(f"write_frame({path!r}): {len(channels)} channel names for an image of shape "
                        f"{image.shape}")
    dtype = np.float16 if half else np.float32
    chans = {n: np.ascontiguousarray(image[..., i].astype(dtype)) for i, n in enumerate(channels)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, **meta}
    with atomic_path(path, ".exr") as tmp:
        try:
            with OpenEXR.File(header, chans) as f:
                f.write(tmp)
        except Exception as e:  # noqa: BLE001 - OpenEXR raises bare RuntimeErrors
            raise IOFailure(f"write_frame({path!r}): {e}") from None


def read_header(path: str) -> dict | None:
    """The header of an EXR, or None when the file is missing or not a readable EXR."""
    import OpenEXR

    if not os.path.isfile(path):
        return None
    try:
        with OpenEXR.File(path, header_only=True) as f:
            return dict(f.header())
    except Exception:  # noqa: BLE001 - any unreadable file counts as not finished
        return None


def frame_status(spec: dict) -> str:
    """``"done"`` (present, hash matches), ``"stale"`` (present, other job) or ``"missing"``."""
    header = read_header(spec["output"])
    if header is None:
        return "stale" if os.path.exists(spec["output"]) else "missing"
    return "done" if header.get(HASH_ATTR) == spec["hash"] else "stale"
