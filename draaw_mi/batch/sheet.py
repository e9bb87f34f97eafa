"""Contact sheets: one sRGB PNG per job with a thumbnail of every finished frame."""
from __future__ import annotations

import math
import os

import numpy as np

from ..errors import IOFailure
from ..io import write_png
from .exr import frame_status, read_frame


def sheet_path(first_frame: dict) -> str:
    """The contact sheet of a job: ``<job>_contact.png`` beside the frame spec
    ``first_frame``'s file (its frame 0).

    >>> sheet_path({"job": "turn", "output": "/o/turn/0000.exr"})
    '/o/turn/turn_contact.png'
    """
    return os.path.join(os.path.dirname(first_frame["output"]), f"{first_frame['job']}_contact.png")


def contact_sheets(specs, thumb: int = 128, columns: int = 6, damaged: list | None = None) -> list[str]:
    """Write ``<first frame's folder>/<job>_contact.png`` for each job; return the paths.
    A finished frame (:func:`~draaw_mi.batch.exr.frame_status` ``"done"``) whose pixel data
    does not decode raises :class:`~draaw_mi.errors.IOFailure`; with a ``damaged`` list, its
    spec is appended there instead and its sheet made of the other frames."""
    jobs: dict = {}
    for s in specs:
        jobs.setdefault(s["job"], []).append(s)
    written = []
    for job, frames in jobs.items():
        tiles = []
        for s in frames:
            if frame_status(s) != "done":
                continue
            try:
                img = read_frame(s["output"])[..., :3]
            except IOFailure:
                if damaged is None:
                    raise
                damaged.append(s)
                continue
            step = max(1, math.ceil(max(img.shape[:2]) / thumb))
            tiles.append(img[::step, ::step])
        if not tiles:
            continue
        h = max(t.shape[0] for t in tiles)
        w = max(t.shape[1] for t in tiles)
        cols = min(columns, len(tiles))
        rows = -(-len(tiles) // cols)
        sheet = np.zeros((rows * h, cols * w, 3), np.float32)
        for i, t in enumerate(tiles):
            r, c = divmod(i, cols)
            sheet[r * h:r * h + t.shape[0], c * w:c * w + t.shape[1]] = t
        path = sheet_path(frames[0])
        write_png(path, sheet, encoded=bool(frames[0].get("encoded")))
        written.append(path)
    return written
