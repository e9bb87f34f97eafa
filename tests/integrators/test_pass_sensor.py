"""The sensor a pass renders is the calling thread's (pass_sensor): a preview's worker and a
fit's gradient pass share one integrator."""
from __future__ import annotations

import threading

from integrators_helpers import mi, rs

from draaw_mi.integrators import pass_sensor


def test_two_threads_passes_each_read_their_own_sensor():
    """As an attribute of the integrator, set and restored by each pass, thread A rendering
    sensor 1 read sensor 0 while thread B's pass ran, and a stale sensor stayed behind."""
    d = rs.cornell_draaw(res=4, spp=1)
    d["sensor2"] = dict(d["sensor"])
    scene = mi.load_dict(d)
    integ = object()
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def a():
        with pass_sensor.rendering(integ, scene, 1):
            a_in.set()
            b_in.wait(10)
            seen["a"] = pass_sensor.sensor_of(integ)
        a_out.set()

    def b():
        a_in.wait(10)
        with pass_sensor.rendering(integ, scene, 0):
            b_in.set()
            a_out.wait(10)
            seen["b"] = pass_sensor.sensor_of(integ)

    threads = [threading.Thread(target=f) for f in (a, b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert seen["a"] is scene.sensors()[1] and seen["b"] is scene.sensors()[0]
    assert pass_sensor.sensor_of(integ) is None
