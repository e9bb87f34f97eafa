"""The sensor a render pass renders, per thread: media scenes start camera rays in its medium.

``mi.render(scene, sensor=k)`` gives the integrator the sensor, but not ``sample()``, where the
camera ray's medium is chosen. :func:`rendering` keeps it for the pass, in a thread-local table
keyed by the integrator: a preview's worker and a fit's gradient pass on another thread, with one
integrator between them, each read their own (an attribute of the integrator had been set and
restored by both, out of order).

>>> import mitsuba as mi
>>> class Integ: pass
>>> integ = Integ()
>>> sensor_of(integ) is None
True
"""
from __future__ import annotations

import contextlib
import threading

_PASSES = threading.local()


def _table() -> dict:
    table = getattr(_PASSES, "sensors", None)
    if table is None:
        table = _PASSES.sensors = {}
    return table


@contextlib.contextmanager
def rendering(integrator, scene, sensor):
    """While the block runs on this thread, :func:`sensor_of` ``(integrator)`` is the sensor
    rendered (``sensor``: an index or a Sensor, as ``mi.render`` takes it). Yields the Sensor."""
    obj = scene.sensors()[sensor] if isinstance(sensor, int) else sensor
    table = _table()
    key = id(integrator)
    prev = table.get(key)
    table[key] = obj
    try:
        yield obj
    finally:
        if prev is None:
            table.pop(key, None)
        else:
            table[key] = prev


def sensor_of(integrator):
    """The sensor the calling thread's pass of ``integrator`` renders (``None`` outside one)."""
    return _table().get(id(integrator))
