"""The :class:`~draaw_mi.widgets.MaterialTuner`'s scene rebuilds: texture files and the
resolution slider, the only changes that recompile (every other control writes parameter
values). Functions of the tuner: they read its controls, texture files, document and preview,
and put the new preview in place of the old one.
"""
from __future__ import annotations

import os

from ..errors import DraawError
from ..scene.loading import from_description
from .tuning import scaled_resolution


def apply_textures(tuner, m: str) -> None:
    """Load the texture / normal-map files typed for material ``m`` (names relative to the
    scene's folder) and rebuild the scene with them; a file that does not load is not kept."""
    base = scene_folder(tuner.scene.source)
    files = {}
    for field, param in (("texture", "base_color"), ("normalmap", "normalmap")):
        text = tuner.controls[m][field].value.strip()
        if not text:
            continue
        path = text if os.path.isabs(text) else os.path.join(base, text)
        if not os.path.isfile(path):
            raise DraawError(f"{m}.{param}: file {text!r} does not exist (looked for {path!r})")
        files[param] = os.path.abspath(path)
    if not files:
        raise DraawError(f"{m}: no texture or normal-map file given")
    previous = {k: dict(v) for k, v in tuner._textures.items()}
    tuner._textures.setdefault(m, {}).update(files)
    try:
        reload(tuner)
    except Exception:
        tuner._textures.clear()
        tuner._textures.update(previous)
        raise
    if "base_color" in files:               # now a texture: no single colour to pick
        tuner.controls[m]["base_color"].disabled = True
        tuner.controls[m]["base_color_text"].disabled = True


def reload(tuner, scale: float | None = None) -> None:
    """Rebuild the scene at the resolution slider's ``scale`` (textures, resolution). The
    worker stops first (a scene built or freed while it records a frame kills the process);
    the old preview goes on if the new scene cannot be made."""
    scale = tuner.controls_render["scale"].value if scale is None else scale
    size = scaled_resolution(tuner.base_scene.resolution, scale)
    running = tuner.preview.running
    tuner.preview.stop()
    try:
        scene = rebuilt(tuner, size)
        new = tuner._new_preview(scene, tuner.post_panel.chain)
    except BaseException:
        if running:
            tuner.preview.start()
        raise
    for m, files in tuner._textures.items():
        if "base_color" in files:                   # a texture now: no single colour
            tuner.materials[m].pop("base_color", None)
    # the lights' base values stay the loaded scene's: the new scene's lights are already
    # scaled by the intensity and colour controls
    old, tuner.preview, tuner.scene = tuner.preview, new, scene
    old.close()                      # (its scene freed now, under the render guard)
    if running:
        tuner.preview.start()


def rebuilt(tuner, size):
    """The scene at ``size`` with the panel's values and texture files."""
    scene = tuner.scene
    if scene.description is None:
        # an XML scene has no description to rebuild: loaded again at the new size, its
        # current values carried over
        return scene.with_resolution(*size)
    doc = tuner.document()
    for m, files in tuner._textures.items():
        doc["materials"][m].update(files)
    doc["render"]["resolution"] = list(size)
    return from_description(doc, scene.source, scene_folder(scene.source), {})


def scene_folder(source: str) -> str:
    """The folder a scene's relative file names are resolved against (the working folder for a
    description dict)."""
    return os.path.dirname(os.path.abspath(source)) if os.path.isfile(source) else os.getcwd()
