"""Contact sheets (draaw_mi.batch.sheet) against the frames they show."""
from __future__ import annotations

import numpy as np
from batch_helpers import manifest, write_scene
from PIL import Image

from draaw_mi.batch import runner as batch
from draaw_mi.io import read_exr


def srgb8(linear):
    """The 8-bit sRGB code of linear values clipped to [0, 1] (IEC 61966-2-1), as a float in
    [0, 1] before rounding."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def test_every_tile_of_a_wrapped_contact_sheet_is_its_own_frame(tmp_path):
    """8 frames of 12x8 on a sheet of 6 columns (the default) wrap to a second row: tile i sits
    at row i // 6, column i % 6 and equals frame i's EXR, sRGB-encoded and clipped (the sheet
    of a linear job), with nothing written in the four empty cells of the second row. The
    frames differ from each other (an orbit with a roughness ramp), so a tile that shows the
    wrong frame is tens of levels away. Tolerance: the PNG's 8-bit rounding, 0.5/255 (+1e-6
    for the float32 encode)."""
    scene = write_scene(tmp_path, "small.toml", resolution=[12, 8], spp=1)
    doc = manifest(tmp_path, frames=8, scene=scene, spp=1)
    doc["contact_sheet"] = True
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 8 and not getattr(res, "sheet_error", None)
    out = tmp_path / "out" / "orbit"
    sheet = np.asarray(Image.open(out / "orbit_contact.png").convert("RGB"), dtype=np.float64) / 255.0
    h, w = 8, 12
    assert sheet.shape == (2 * h, 6 * w, 3)
    frames = [read_exr(str(out / f"{i:04d}.exr"))[..., :3] for i in range(8)]
    assert all(f.shape == (h, w, 3) for f in frames)
    assert min(np.abs(srgb8(frames[i]) - srgb8(frames[0])).max() for i in range(1, 8)) > 5 / 255
    for i, f in enumerate(frames):
        r, c = divmod(i, 6)
        tile = sheet[r * h:(r + 1) * h, c * w:(c + 1) * w]
        err = np.abs(tile - srgb8(f)).max()
        assert err <= 0.5 / 255 + 1e-6, f"tile {i} (row {r}, column {c}): max |diff| {err * 255:.2f} levels"
    assert np.all(sheet[h:, 2 * w:] == 0)                           # the empty cells stay black
