"""The channels of a pass that a Mitsuba integrator with AOVs of its own renders (``aov``,
``moment``): read from the film's bitmap, which holds and names every channel.

``mi.render``'s tensor (the film's ``develop()``) leaves channels of such integrators out in
Mitsuba 3.9.1: an ``aov`` integrator's nested integrator's R, G, B, A, and its colour where it
nests none (an ``aov`` of depth alone develops to one channel, where the film stores R, G, B
and the depth). Its channels then cannot be named; the bitmap's are the film's colour
channels and then :meth:`aov_names`, what Mitsuba writes to an EXR.

>>> import mitsuba as mi
>>> named_by_film(mi.load_dict({"type": "aov", "aovs": "d:depth", "n": {"type": "path"}}))
True
>>> named_by_film(mi.load_dict({"type": "path"}))
False
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

from ..integrators.common import DraawIntegrator


def named_by_film(integrator) -> bool:
    """Whether a pass of ``integrator`` is read from its film's bitmap: a Mitsuba integrator
    (not one of draaw's, whose images name their channels) with AOVs."""
    return not isinstance(integrator, DraawIntegrator) and bool(integrator.aov_names())


def film_channels(mi_scene, sensor) -> mi.TensorXf:
    """The film of ``sensor`` (an index into ``mi_scene``'s sensors, or a sensor) as an
    ``(H, W, C)`` tensor of its colour channels and then its AOVs, after a render pass."""
    sensor = mi_scene.sensors()[sensor] if isinstance(sensor, int) else sensor
    return mi.TensorXf(np.array(sensor.film().bitmap(), dtype=np.float32))
