"""What a gradient pass of a render session runs (:meth:`~draaw_mi.rendering.session.Session.gradient_pass`):
the body a recording takes (render, loss, backward), the host-side part of its key, and the
gradients a failed recording must give back."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi


def gradient_body(integrator, spp: int, spp_grad: int, loss, params=None):
    """``body(mi_scene, seed, sensor, key, inputs) -> (loss value, extras)`` of
    :meth:`~draaw_mi.rendering.session.Session.gradient_pass`: render, loss, backward. Without
    ``params`` the scene's are traversed inside (a recording's body: its parameters are the
    scene's, an input); ``key`` (:func:`host_key`) is there for the recording's key only."""
    def body(mi_scene, seed, sensor, key, inputs):
        p = mi.traverse(mi_scene) if params is None else params
        image = mi.render(mi_scene, p, sensor=sensor, integrator=integrator, seed=seed, spp=spp, spp_grad=spp_grad)
        value, extras = loss(image, *inputs)
        dr.backward(value)
        return dr.detach(value), extras
    return body


def host_key(sensor) -> tuple:
    """What a recording's key must see of a sensor that ``dr.freeze`` does not: the host-side
    values its kernels bake in (the film's size and crop window, the shutter). Its JIT values
    (the camera's transforms) are inputs; a sensor made outside the scene is not part of
    :func:`~draaw_mi.rendering.frozen.scene_scalars`."""
    film = sensor.film()
    return (tuple(film.size()), tuple(film.crop_offset()), tuple(film.crop_size()),
            float(sensor.shutter_open_time()))


def gradients_of(params) -> list:
    """``[(value, its gradient now)]`` for the parameters that track gradients."""
    return [(v, dr.grad(v)) for v in dict(params).values() if dr.is_diff_v(v) and dr.grad_enabled(v)]


def restore_gradients(saved: list) -> None:
    """Put back the gradients :func:`gradients_of` saved: a recording that failed after its
    backward pass began may have added to them, and the traced retry adds its own."""
    for v, g in saved:
        dr.set_grad(v, g)
