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

A frame is *finished* when its file exists, its header is readable and its ``draaw:frame_hash``
equals the planned hash (:func:`frame_status`). Because the file is renamed into place only
after it is completely written, a present file is never a partial one. A job with previews
also wants the frame's PNG, which carries the same hash as a text chunk and is written before
the EXR: a finished EXR whose PNG is missing or another frame's (a run killed between the two
writes, previews turned on later) gets its PNG from the EXR, not a new render
(:func:`write_preview`).
"""
from __future__ import annotations

import os
import time

import numpy as np

from ..errors import IOFailure
from ..integrators import resolve_version

HASH_ATTR = "draaw:frame_hash"


def metadata(spec: dict, seconds: float) -> dict:
    """The header attributes of a rendered frame."""
    meta = {HASH_ATTR: spec["hash"], "draaw:scene": spec["scene"], "draaw:scene_sha256": spec["scene_hash"],
            "draaw:job": spec["job"], "draaw:frame": int(spec["frame"]), "draaw:version": spec["version"],
            "draaw:integrator": resolve_version(spec["version"]),
            "draaw:spp": int(spec["spp"]), "draaw:sampler": str(spec.get("sampler")),
            "draaw:seed": int(spec["seed"]),
            "draaw:max_depth": int(spec["max_depth"]), "draaw:render_seconds": float(seconds),
            "draaw:rendered_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if spec.get("files_hash"):
        meta["draaw:files_sha256"] = spec["files_hash"]
    meta.update({f"draaw:{k}": str(v) for k, v in spec["versions"].items()})
    return meta


def render_metadata(scene_file, scene, info: dict, post=None) -> dict:
    """The ``draaw:*`` header attributes of one ``draaw-mi render`` EXR, as batch frames carry
    them: the scene (and its file's SHA-256), the integrator, sampler, spp, seed, depth, time,
    the post chain applied (``post``: a chain or a list of filter dicts; none: no attribute) and
    the versions of draaw-mi, Mitsuba and Dr.Jit. ``info``: what ``render(...,
    return_info=True)`` returned."""
    from .plan import file_hash, versions
    meta = {"draaw:scene": os.path.abspath(scene_file), "draaw:version": info["version"],
            "draaw:integrator": info["integrator"],
            "draaw:spp": int(info["spp"]), "draaw:seed": int(scene.settings["seed"]),
            "draaw:max_depth": int(scene.settings["max_depth"]),
            "draaw:render_seconds": float(info["seconds"]), "draaw:denoised": int(bool(info.get("denoised"))),
            "draaw:rendered_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if os.path.isfile(scene_file):
        meta["draaw:scene_sha256"] = file_hash(scene_file)
    meta["draaw:sampler"] = str(scene.settings.get("sampler") or "independent")
    if post:
        import json

        from ..post import load_chain
        meta["draaw:post"] = json.dumps(load_chain(post).to_list())
    meta.update({f"draaw:{k}": str(v) for k, v in versions().items()})
    return meta


def write_frame(path: str, image: np.ndarray, channels, meta: dict, half: bool = False) -> None:
    """Write an (H, W, C) frame with named channels and header attributes, atomically
    (:func:`draaw_mi.io.write_exr` with ``metadata``)."""
    from ..io import write_exr

    if image.ndim != 3 or image.shape[2] != len(channels):
        raise IOFailure(f"write_frame({path!r}): {len(channels)} channel names for an image of shape "
                        f"{image.shape}")
    write_exr(path, image, channels=list(channels), half=half, metadata=meta)


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
    """``"done"`` (present, hash matches), ``"stale"`` (present, other job), ``"missing"``, or
    ``"no-preview"`` (the EXR is done, the preview the job asks for is missing or stale)."""
    header = read_header(spec["output"])
    if header is None:
        return "stale" if os.path.exists(spec["output"]) else "missing"
    if header.get(HASH_ATTR) != spec["hash"]:
        return "stale"
    if spec.get("preview"):
        tag = _png_hash(preview_path(spec))
        # a PNG without a hash was written by draaw-mi before previews carried one, after its
        # EXR: it is this frame's
        if tag is None or (tag and tag != spec["hash"]):
            return "no-preview"
    return "done"


def preview_path(spec: dict) -> str:
    """The PNG preview beside a frame's EXR."""
    return os.path.splitext(spec["output"])[0] + ".png"


def write_preview(spec: dict, image: np.ndarray | None = None) -> None:
    """Write the frame's sRGB PNG preview, tagged with its hash; ``image``: the rendered
    frame, or ``None`` to take it from the finished EXR."""
    from ..io import read_exr, write_png

    if image is None:
        image = read_exr(spec["output"])
    write_png(preview_path(spec), image[..., :3], text={HASH_ATTR: spec["hash"]},
              encoded=bool(spec.get("encoded")))


def _png_hash(path: str) -> str | None:
    """The frame hash a preview carries, ``""`` for a PNG without one, ``None`` for a missing
    or unreadable file."""
    from PIL import Image

    try:
        with Image.open(path) as im:          # reads the chunks before the pixels only
            return str(im.info.get(HASH_ATTR, ""))
    except (OSError, ValueError):
        return None
