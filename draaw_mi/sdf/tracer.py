"""Sphere tracing of an :class:`~draaw_mi.sdf.scene.SDFScene` (detached), normals, and the
implicit re-attachment of the hit to the SDF parameters.

==================  =====================================================================
option              meaning (integrator property ``sdf_*``; defaults)
==================  =====================================================================
``hit_epsilon``     relative hit tolerance: ``p = o + t d`` is on the surface when
                    ``|f(p)| < hit_epsilon * (L + t) + 1e-6 max|p|`` (grows with the
                    distance travelled; ``L``: the objects' size, at most 1
                    (:func:`length_scale`); the last term, ~16 float spacings of ``p``,
                    keeps far-away objects convergent). (``sdf_epsilon``, 1e-5)
``max_steps``       iteration cap; a ray that has not converged then is a **miss**
                    (``sdf_max_steps``, 256)
``relaxation``      over-relaxation factor ``omega`` in [1, 2): steps of ``omega |f|``
                    with Keinert et al.'s check (if the unbounding spheres of two steps
                    do not overlap, step back and continue with omega = 1; a relaxed
                    step that would leave the ray's interval is replaced by a plain one)
                    (``sdf_relaxation``, 1.0 = plain sphere tracing)
==================  =====================================================================

The march uses ``|f|``, i.e. SDF surfaces behave like Mitsuba's surfaces: a camera inside an
SDF sees the inside of its surface, rays may leave a surface to either side. A ray whose
*origin* lies within the hit band (a ray spawned on a surface) is *disarmed* until ``|f|`` has
exceeded the band once, and steps at least ``epsilon / 2`` meanwhile, so it neither hits its
own surface nor stalls. Rays are clipped to the union of the roots' bounding boxes first:
rays that miss every box do not march, the others start at the first box entry.

Normals are central differences on a tetrahedron (4 evaluations, ``h = 1e-4 L + 4e-6 max|p|``
with the hit band's ``L``, so objects a millimetre across in metre units keep their shading;
Quilez' tetrahedral stencil), which are differentiable with respect to the SDF parameters
and the point, so the same code gives the primal normal and the normal's derivative in the
adjoint phase. A zero gradient (e.g. the centre of a sphere) falls back to ``-ray.d``.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError
from .node import is_infinite

FAR = 1e7
#: the most steps a ray may take (``max_steps``): the loop counts them in a 32-bit integer
MAX_STEPS_LIMIT = 2**31 - 1
_TETRA = ((1.0, -1.0, -1.0), (-1.0, -1.0, 1.0), (-1.0, 1.0, -1.0), (1.0, 1.0, 1.0))


class TracerOptions:
    """Sphere-tracer knobs (see the module docstring)."""
    def __init__(self, hit_epsilon: float = 1e-5, max_steps: int = 256, relaxation: float = 1.0):
        # (a bool is an int to Python: True would pass as relaxation 1 or max_steps 1)
        if isinstance(hit_epsilon, bool) or not (isinstance(hit_epsilon, (int, float)) and 0 < hit_epsilon <= 5e-5):
            raise ParameterError(f"sdf tracer: hit_epsilon={hit_epsilon!r}; expected a number in "
                                 "(0, 5e-5] (relative to the objects' size plus the distance; Mitsuba offsets rays "
                                 "by ~9e-5)")
        if (isinstance(max_steps, bool) or not isinstance(max_steps, int)
                or not 1 <= max_steps <= MAX_STEPS_LIMIT):
            raise ParameterError(f"sdf tracer: max_steps={max_steps!r}; expected a whole number >= 1 and "
                                 f"<= {MAX_STEPS_LIMIT} (the step counter is a 32-bit integer)")
        if isinstance(relaxation, bool) or not (isinstance(relaxation, (int, float)) and 1.0 <= relaxation < 2.0):
            raise ParameterError(f"sdf tracer: relaxation={relaxation!r}; expected a number in [1, 2)")
        self.hit_epsilon = float(hit_epsilon)
        self.max_steps = int(max_steps)
        self.relaxation = float(relaxation)

    @classmethod
    def from_props(cls, props, plugin: str) -> "TracerOptions":
        kw = {}
        for prop, key, conv in (("sdf_epsilon", "hit_epsilon", float), ("sdf_max_steps", "max_steps", _whole),
                                ("sdf_relaxation", "relaxation", float)):
            if prop in props:
                v = props[prop]
                try:
                    kw[key] = conv(v) if not isinstance(v, bool) else v
                except (TypeError, ValueError, OverflowError):
                    raise ParameterError(f"{plugin}: {prop}={v!r} is not a number") from None
        try:
            return cls(**kw)
        except ParameterError as e:
            msg = str(e).replace("sdf tracer: ", "")
            for prop, key in (("sdf_epsilon", "hit_epsilon"), ("sdf_max_steps", "max_steps"),
                              ("sdf_relaxation", "relaxation")):
                msg = msg.replace(f"{key}=", f"{prop}=")
            raise ParameterError(f"{plugin}: {msg}") from None

    def __repr__(self) -> str:
        return (f"TracerOptions(hit_epsilon={self.hit_epsilon:g}, max_steps={self.max_steps}, "
                f"relaxation={self.relaxation:g})")


def _whole(v):
    """``int`` of a whole number (64, 64.0, "64"); anything else as it is, for the constructor
    to refuse by name (``int`` would truncate 64.7 to 64 without a word)."""
    if isinstance(v, str):
        v = float(v)
    if isinstance(v, float) and v.is_integer():
        return int(v)
    return v


def _max_abs(p) -> mi.Float:
    return dr.maximum(dr.maximum(dr.abs(p.x), dr.abs(p.y)), dr.abs(p.z))


def length_scale(sdf) -> float:
    """The largest side of the SDF roots' finite boxes, at most 1 (1 if none is finite).

    >>> from draaw_mi.sdf import Sphere
    >>> class One:  # a stand-in holding one root
    ...     def __init__(self, r): self.r = r
    ...     def bboxes(self): return [self.r.bbox()]
    >>> round(length_scale(One(Sphere(radius=1e-4))), 9), length_scale(One(Sphere(radius=3.0)))
    (0.0002, 1.0)
    """
    sides = [max(float(h) - float(l) for l, h in zip(bb.min, bb.max))
             for bb in sdf.bboxes() if not is_infinite(bb)]
    return min(1.0, max(sides)) if sides and max(sides) > 0 else 1.0


def ray_interval(sdf, o: mi.Point3f, d: mi.Vector3f, tmax: mi.Float, active: mi.Bool,
                 pad: float = 0.0):
    """``(t0, t1, active)``: the part of the ray inside the union of the roots' boxes, each
    grown by ``pad`` (besides a rounding margin)."""
    t0 = mi.Float(math.inf)
    t1 = mi.Float(-math.inf)
    hit_any = mi.Bool(False)
    for bb in sdf.bboxes():
        if is_infinite(bb):
            a, b, ok = mi.Float(0.0), mi.Float(FAR), mi.Bool(True)
        else:
            ext = max(float(h) - float(l) for l, h in zip(bb.min, bb.max))
            grow = pad + 1e-4 * (1.0 + ext + max(abs(float(c)) for c in list(bb.min) + list(bb.max)))
            lo = dr.opaque(mi.Point3f, [float(c) - grow for c in bb.min])
            hi = dr.opaque(mi.Point3f, [float(c) + grow for c in bb.max])
            box = mi.BoundingBox3f(lo, hi)
            ok, a, b = box.ray_intersect(mi.Ray3f(o, d))
            ok &= b >= 0
        t0 = dr.select(ok, dr.minimum(t0, a), t0)
        t1 = dr.select(ok, dr.maximum(t1, b), t1)
        hit_any |= ok
    t0 = dr.maximum(t0, 0.0)
    t1 = dr.minimum(dr.minimum(t1, tmax), FAR)
    return t0, t1, active & hit_any & (t0 < t1)


def march(sdf, o: mi.Point3f, d: mi.Vector3f, tmax: mi.Float, active: mi.Bool,
          opts: TracerOptions):
    """Sphere-trace ``o + t d`` (``|d| = 1``) for ``t < tmax``; detached.

    Returns ``(t, hit, steps)``; exhausted iterations and ``t >= tmax`` are misses.
    """
    with dr.suspend_grad():
        o, d, tmax = dr.detach(o), dr.detach(d), dr.detach(tmax)
        t0, t1, act = ray_interval(sdf, o, d, tmax, mi.Bool(active))
        # the band's absolute part in the scene's own length (at most 1): for objects 1e-4
        # across, a band of 1e-5 would be a fifth of their radius (inflated silhouettes); opaque,
        # so a moving or growing object does not compile a new kernel
        eps_rel = opts.hit_epsilon * dr.opaque(mi.Float, length_scale(sdf))
        omega0 = opts.relaxation
        relax = omega0 > 1.0
        t = mi.Float(dr.select(act, t0, 0.0))
        hit = mi.Bool(False)
        # rays that start in the hit band of a surface (spawned on it) are disarmed; the
        # test is at the origin, not at the box entry (tight boxes touch the surface)
        f_o = dr.abs(sdf.distance(mi.Point3f(o)))
        armed = mi.Bool(f_o >= eps_rel + 1e-6 * _max_abs(o))
        eps_t = opts.hit_epsilon
        steps = mi.UInt32(0)
        omega = mi.Float(omega0)
        r_prev = mi.Float(0.0)
        step_prev = mi.Float(0.0)
        neg_prev = mi.Bool(False)          # the previous point's side (relaxation)

        def cond(t, hit, armed, steps, omega, r_prev, step_prev, neg_prev):
            return act & ~hit & (t < t1) & (steps < opts.max_steps)

        def body(t, hit, armed, steps, omega, r_prev, step_prev, neg_prev):
            p = dr.fma(d, t, o)
            fs = sdf.distance(mi.Point3f(p))
            f = dr.abs(fs)
            eps = eps_rel + eps_t * t + 1e-6 * _max_abs(p)
            if relax:
                # the spheres of the last two points do not overlap, or the side changed (a
                # step through a face head-on lands inside, where |f| + r_prev equals the
                # step and the overlap test alone passes it: 83 % of such rays would hit the back
                # face at 1.5): a surface lies in between; go back and take the plain step
                # from the previous point. Not from a point in the hit band (a ray spawned on
                # a surface: its first steps are longer than |f| by design, and failing
                # there would turn relaxation off for the whole ray)
                crossed = neg_prev != (fs < 0)
                fail = (omega > 1.0) & (r_prev >= eps) & ((f + r_prev < step_prev) | crossed)
                t_back = t - step_prev + r_prev
                omega = dr.select(fail, 1.0, omega)
                hit = ~fail & armed & (f < eps)
                armed |= ~fail & (f >= eps)
                plain = dr.maximum(f, 0.5 * eps)
                step = omega * plain
                # a relaxed step must not leave the interval unchecked (the surface may lie
                # before t1, e.g. in front of a mesh): take the plain step there instead
                out = ~fail & ~hit & (omega > 1.0) & (t + step >= t1)
                omega = dr.select(out, 1.0, omega)
                step = dr.select(out, plain, step)
                t_new = dr.select(fail, t_back, dr.select(hit, t, t + step))
                r_prev = dr.select(fail, r_prev, f)
                step_prev = dr.select(fail, r_prev, step)
                neg_prev = dr.select(fail, neg_prev, fs < 0)
                t = t_new
            else:
                hit = armed & (f < eps)
                armed |= f >= eps
                t = dr.select(hit, t, t + dr.maximum(f, 0.5 * eps))
            return t, hit, armed, steps + 1, omega, r_prev, step_prev, neg_prev

        t, hit, armed, steps, omega, r_prev, step_prev, neg_prev = dr.while_loop(
            (t, hit, armed, steps, omega, r_prev, step_prev, neg_prev), cond, body, label="sdf_march")
        hit &= act & (t < t1)
    return t, hit, steps


def gradient(sdf, p: mi.Point3f, scale: float = 1.0) -> mi.Vector3f:
    """Tetrahedral central-difference gradient of ``sdf`` at ``p`` (differentiable), the
    step ``scale`` times the default, ``1e-4 L + 4e-6 max|p|`` (``L``: :func:`length_scale`,
    as the hit band's; a fixed 1e-4 turned the normals of a sphere of radius 2e-4 by 6 degrees
    on average). Opaque, so a growing object compiles no new kernel."""
    h = scale * (1e-4 * dr.opaque(mi.Float, length_scale(sdf)) + 4e-6 * dr.detach(_max_abs(p)))
    g = mi.Vector3f(0.0)
    for k in _TETRA:
        kv = mi.Vector3f(*k)
        g += kv * sdf.distance(mi.Point3f(p + kv * h))
    return g / (4.0 * h)


def normal(sdf, p: mi.Point3f, fallback: mi.Vector3f) -> mi.Vector3f:
    """Unit outward normal ``grad f / |grad f|`` (``fallback`` where the gradient vanishes)."""
    g = gradient(sdf, p)
    n2 = dr.squared_norm(g)
    ok = n2 > 1e-12
    return dr.select(ok, g * dr.rsqrt(dr.select(ok, n2, 1.0)), fallback)


def near_crease(sdf, p: mi.Point3f, n: mi.Vector3f) -> mi.Bool:
    """Whether ``p`` lies within a few normal steps of a crease (a box's edge, a sharp
    operator's seam): the normal ``n`` and the one from a 4x wider stencil disagree by more
    than 0.8 degrees (on a smooth surface they agree to 1e-6: curvature radii far above the
    step). Detached."""
    with dr.suspend_grad():
        g4 = gradient(sdf, mi.Point3f(dr.detach(p)), 4.0)
        c = dr.dot(dr.detach(n), g4) * dr.rsqrt(dr.maximum(dr.squared_norm(g4), 1e-24))
        return c < 1.0 - 1e-4


def reattach_t(sdf, o: mi.Point3f, d: mi.Vector3f, t0: mi.Float, active: mi.Bool) -> mi.Float:
    """``t0`` carrying the derivative of the hit distance w.r.t. the SDF parameters:
    ``t = t0 - (f - detach(f)) / dot(grad f, d)`` at ``p0 = o + t0 d`` (one Newton step of
    the implicit function ``f(o + t d) = 0``; value unchanged). Grazing hits
    (``|dot(grad f, d)| < 1e-3 |grad f|``) get no derivative instead of an unbounded one."""
    p0 = mi.Point3f(dr.detach(dr.fma(d, t0, o)))
    f = sdf.distance(p0)
    with dr.suspend_grad():
        g = gradient(sdf, p0)
    den = dr.dot(g, dr.detach(d))
    ok = active & (dr.abs(den) > 1e-3 * dr.norm(g))
    step = dr.select(ok, (f - dr.detach(f)) / dr.select(ok, den, 1.0), 0.0)
    return dr.detach(t0) - step
