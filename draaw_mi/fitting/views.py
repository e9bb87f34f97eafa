"""What one fit iteration compares: the sensors of the views a fit renders, the sample count
the scene's sampler takes, and each view's loss against its reference."""
from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..rendering.passes import sample_passes
from ..scene.camera import camera_to_look_at, sampler_plugin, sensor_dict
from ..scene.schema import Where

if TYPE_CHECKING:
    from ..scene import DraawScene

LOSSES = ("l2", "l1", "relative_l2")


def view_sensors(scene: DraawScene, views, cameras_of_captures: bool = False):
    """Sensors for each view: the scene's own camera, or camera tables as in [camera] (a view
    of None: the scene's camera). ``cameras_of_captures``: the views are the ``camera`` of
    each of fit's ``captures`` (and named so in errors)."""
    if views is None:
        return [scene.mi_scene.sensors()[0]]
    if not isinstance(views, (list, tuple)) or not views:
        raise ParameterError("fit: views must be a non-empty list of camera tables or mi.Sensor objects")
    w, h = scene.resolution
    # a view without a field of view has the scene camera's, not [camera]'s default of 40
    # degrees (its references would be fitted through another lens)
    own = mi.traverse(scene.mi_scene.sensors()[0])
    x_fov = float(np.array(own["x_fov"]).ravel()[0]) if "x_fov" in own else 40.0
    # the film's own filter object, not its name: a gaussian's stddev or a lanczos' lobes that
    # an XML scene sets reach the other views too
    rfilter = scene.mi_scene.sensors()[0].film().rfilter()
    medium = scene.mi_scene.sensors()[0].get_medium()      # the medium the views stand in
    out = []
    for i, v in enumerate(views):
        if v is None:                          # (a capture without a camera: the scene's)
            out.append(scene.mi_scene.sensors()[0])
            continue
        if isinstance(v, mi.Sensor):
            size = tuple(int(c) for c in v.film().crop_size())
            if size != (w, h):     # (else a raw Dr.Jit size error, or pixels compared scrambled)
                raise ParameterError(f"fit: views[{i}] is a sensor of {size[0]}x{size[1]} pixels; "
                                 f"expected the references' {w}x{h}")
            out.append(v)
            continue
        if isinstance(v, dict) and "fov" not in v:
            if "fov_axis" in v:
                raise ParameterError(f"fit: views[{i}] has fov_axis but no fov; give both, or neither "
                                 "for the scene camera's")
            v = {**v, "fov": x_fov, "fov_axis": "x"}
        where = Where("fit") / "captures" / i / "camera" if cameras_of_captures else Where("fit") / "views" / i
        look = camera_to_look_at(v, where)
        d = sensor_dict(look, w, h, scene.settings["spp"], rfilter, scene.settings.get("sampler", "independent"))
        if medium is not None:           # (a view inside the scene camera's fog sees the fog)
            d["medium"] = medium
        out.append(mi.load_dict(d))
    return out


def sampler_spp(scene: DraawScene, spp: int, name: str) -> int:
    """The per-pixel count the scene's sampler takes nearest ``spp`` (from below where it can).
    A stratifying sampler rounds other counts up (``multijitter``: 35 for 32) with a Mitsuba
    warning at every render; a fit cannot split its renders into passes (one kernel per run),
    so it says once which count it uses and uses it."""
    got = sample_passes(scene.mi_scene, spp, spp)[0]
    if got != spp:
        warnings.warn(f"fit: the scene's {sampler_plugin(scene.mi_scene.sensors()[0].sampler())} "
                      f"sampler takes {got} samples per pixel, not {name}={spp}; fitting with {got}",
                      RuntimeWarning, stacklevel=3)
    return got


def view_loss(img, ref, kind: str, exposure: str, mask=None):
    """(loss, scale) of one view. With ``exposure="fit"`` the render is scaled by
    ``s = <ref, ref> / <image, ref>`` (detached): the scale at which the render's projection onto
    the reference equals the reference. Both dot products are unbiased under Monte Carlo noise
    (``<image, ref>`` is linear in the image), unlike the least-squares ``<image, ref> /
    <image, image>``, whose denominator picks up the pixel variance and biases the scale low
    (-0.07 stops at 16 spp, 128x128) and with it metallic (+0.03). ``mask`` (a
    :class:`mi.TensorXf` of 0/1 like ``ref``): the pixels that count (a display reference's
    unclipped ones); the loss stays linear in the render, so unbiased under noise (clipping the
    render to [0, 1] instead biases metallic by +0.18 at 8 spp)."""
    scale = mi.Float(1.0)
    if exposure == "fit":
        r = ref.array if mask is None else ref.array * mask.array
        num = dr.sum(r * r)
        den = dr.sum(dr.detach(img.array) * r)
        ok = (den > 0) & dr.isfinite(den)
        scale = dr.detach(dr.select(ok, num / dr.select(ok, den, 1.0), 1.0))
    d = img.array * scale - ref.array
    if mask is not None:
        d = d * mask.array
    if kind == "l2":
        return dr.mean(dr.square(d)), scale
    if kind == "l1":
        return dr.mean(dr.abs(d)), scale
    return dr.mean(dr.square(d) / (dr.square(ref.array) + 1e-2)), scale
