"""Boundary gradients of SDF shape parameters: silhouettes and shadow edges as a thin band.

A pixel's value jumps where the SDF's outline crosses it, and a light sample's where an SDF
edge crosses the shadow ray; re-attaching hit points (:func:`~draaw_mi.sdf.tracer.reattach_t`)
misses what those jumps contribute when the shape moves. With ``m(x)`` the smallest distance
``|f|`` along the ray of sample ``x`` (a *closest approach*: a local minimum of ``|f|`` that the
ray passes without hitting), the outline is the level set ``m = 0`` and moves outwards with
the normal speed ``-dm/dpi / |grad_x m|``. The boundary term of Reynolds' transport theorem,
``int_outline (L_in - L_out) v dl``, becomes by the coarea formula an integral over the band
``0 < m < eps`` of the samples, where ``|grad_x m|`` cancels (Wang et al. 2024, "A simple
approach to differentiable rendering of SDFs", relaxed boundary):

    d I / d pi  (boundary)  =  int k(m(x)) (L_in(x) - L_out(x)) (-dm/dpi) dx  +  O(eps^2)

* ``dm/dpi`` is ``df/dpi`` at the closest point (envelope theorem: the point's own motion does
  not enter at a minimum), i.e. the SDF evaluated with AD at a detached point; for a shadow
  ray from a moving (re-attached) SDF point, the point at the same ``t`` on the moving ray; at
  a kink of ``|f|`` (a crease's edge) the crossing's own motion (:func:`attached_minimum`).
* ``k(m) = (4 - 6 m/eps) / eps`` on ``(0, eps)``: weights that integrate constants to 1 and
  linear functions of ``m`` to their value at ``m = 0``, so the band's width costs ``O(eps^2)``
  (a flat ``1/eps`` costs ``O(eps)``: half a pixel of band over an outline 20 pixels from the
  centre of a sphere is 2.5 % of the term).
* ``eps``: the band's width, :class:`Band`: ``width`` camera pixels at the closest point's
  distance from the camera (so the band is as narrow in the image at every distance).
* ``L_out``: the sample's own radiance (the ray misses the part it approached); ``L_in``: the
  radiance of the ray turned to graze the surface just inside the outline (camera rays,
  :func:`inside_ray`); for a shadow ray ``L_in = 0`` and ``L_out`` is the light sample.
  ``L_in`` is the limit at the outline: near it a shaded surface's radiance goes with the
  square root of the depth ``s`` beneath the outline (the normal turns as ``sqrt(2 s / R)``;
  a glossy BSDF's masking and Fresnel terms change fastest there), so two inside rays pass
  ``s`` and ``4 s`` beneath it (``s``: ``GRAZE = 1e-3`` bands, at least four hit tolerances, so
  that they do hit), with the same random numbers, and ``L_in = 2 L(s) - L(4 s)`` removes the
  square-root term. Measured on a glossy ball lit from the side at 64x48 (finite differences
  0.0463 +- 0.0009): one ray at ``s`` gave 0.0546, at ``10 s`` 0.0575, at ``30 s`` 0.0640.

Independent of the image parametrisation (``|grad_x m|`` cancelled), the same estimator serves
camera rays (integrator side: :mod:`draaw_mi.integrators.silhouettes`) and shadow rays
(:meth:`draaw_mi.sdf.integration.SDFHook.shadow_boundary`). Outlines met by bounce rays (an SDF
seen in a mirror or lighting the floor indirectly), an SDF touching a mesh, and a mesh's shadow
edge on a moving SDF point are not included.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError
from .tracer import TracerOptions, gradient, length_scale, ray_interval

# a ray passing a surface of radius R at m takes ~ pi sqrt(2 R / m) steps there: 330 for
# m = 1e-4 beside a ball of radius 0.55, past the primal march's 256. Band rays that close
# weigh the most (k(0) = 4 / eps); cut off, they took 4 % off a glossy ball's boundary term
CLOSE_STEPS = 4
BISECTIONS = 12     # inside rays Newton cannot place (creases): offset found to 8 / 2^12
RISE = 1.5          # |f| must grow by this factor after a minimum for it to count as passed
GRAZE = 1e-3        # an inside ray passes this fraction of the band beneath the outline


class Band:
    """The boundary band's width: ``width`` pixels of ``sensor`` at a point's distance.

    ``footprint(p) = ortho + angle |p - origin|`` is one pixel's size at ``p`` (``angle``: the
    angle between neighbouring pixels' rays; ``ortho``: their spacing for an orthographic
    camera), measured on the ray differential through the film's centre.

    >>> b = Band(1.0, origin=(0, 0, 0), angle=0.01, ortho=0.0)
    >>> round(float(b.epsilon(mi.Point3f(0, 0, 2))[0]), 6)
    0.02
    """
    def __init__(self, width: float, origin, angle: float, ortho: float):
        if not (isinstance(width, (int, float)) and not isinstance(width, bool) and 0 < width <= 8):
            raise ParameterError(f"sdf band: width={width!r}; expected a number of pixels in (0, 8]")
        self.width = float(width)
        self.origin = mi.ScalarPoint3f(origin)
        self.angle = float(angle)
        self.ortho = float(ortho)

    @classmethod
    def of_sensor(cls, sensor: mi.Sensor, width: float) -> "Band":
        with dr.suspend_grad():
            size = sensor.film().crop_size()
            ray, _ = sensor.sample_ray_differential(
                sensor.shutter_open(), 0.5, mi.Point2f(0.5, 0.5), mi.Point2f(0.5, 0.5))
            # Mitsuba's differentials step one pixel of the full film in x
            ang = float(dr.norm(ray.d_x - ray.d)[0])
            ortho = float(dr.norm(ray.o_x - ray.o)[0])
            o = [float(c[0]) for c in (ray.o.x, ray.o.y, ray.o.z)]
        if not (math.isfinite(ang) and math.isfinite(ortho)) or (ang <= 0 and ortho <= 0):
            ang = 1.0 / max(1, int(size[0]))       # a sensor without differentials
        return cls(width, o, ang, ortho)

    def epsilon(self, p: mi.Point3f) -> mi.Float:
        d = dr.norm(mi.Vector3f(p) - mi.Vector3f(self.origin))
        return self.width * (self.ortho + self.angle * d)

    def pad(self, sdf) -> float:
        """The widest band at the SDF objects' far side (rays are marched that far around
        their boxes)."""
        far = 0.0
        for bb in sdf.bboxes():
            lo, hi = list(bb.min), list(bb.max)
            if not all(math.isfinite(c) for c in lo + hi):
                return self.width * (self.ortho + self.angle * 10.0)
            for corner in ((x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])):
                far = max(far, math.dist(corner, list(self.origin)))
        return 2.0 * self.width * (self.ortho + self.angle * far)


def hit_tolerance(sdf, opts: TracerOptions, p: mi.Point3f, t: mi.Float) -> mi.Float:
    """The sphere tracer's hit band at ``p = o + t d`` (:func:`~draaw_mi.sdf.tracer.march`'s
    rule: the objects' size plus the distance travelled, and ~16 float spacings of ``p``)."""
    scale = opts.hit_epsilon * dr.opaque(mi.Float, length_scale(sdf))
    return scale + opts.hit_epsilon * t + 1e-6 * dr.maximum(dr.maximum(dr.abs(p.x), dr.abs(p.y)), dr.abs(p.z))


def kernel(m: mi.Float, eps: mi.Float) -> mi.Float:
    """The band weight ``(4 - 6 m/eps) / eps`` on ``0 < m < eps``, else 0.

    >>> import numpy as np
    >>> m = mi.Float(np.linspace(0.0, 1.0, 100001, dtype=np.float32))
    >>> k = np.array(kernel(m, mi.Float(0.5)))
    >>> round(float(np.trapezoid(k, np.array(m))), 3), round(float(np.trapezoid(k * np.array(m), np.array(m))), 4)
    (1.0, 0.0)
    """
    inside = (m > 0) & (m < eps)
    e = dr.select(inside, eps, 1.0)
    return dr.select(inside, (4.0 - 6.0 * m / e) / e, 0.0)


def closest_approach(sdf, o: mi.Point3f, d: mi.Vector3f, tmax: mi.Float, active: mi.Bool,
                     opts: TracerOptions, pad: float):
    """Sphere-trace ``o + t d`` (``|d| = 1``, ``t < tmax``; plain steps) and keep the closest
    approach the ray *passes*: the smallest local minimum of ``|f|`` after which ``|f|`` grew
    again (by :data:`RISE`, or up to where the ray leaves the SDF's boxes, padded by ``pad``, or
    ends at ``tmax``). A ray leaving a surface (its origin in the hit band) starts counting
    once ``|f|`` has dipped, so the surface it leaves is no minimum. The march may take
    :data:`CLOSE_STEPS` times the tracer's ``max_steps``. Detached.

    Returns ``(hit, t, m, found)``: whether the ray hits an SDF surface, the closest approach's
    ``t`` and ``m``, ``|f|`` there less the tracer's hit band (rays closer than the band hit:
    the outline a render shows lies there), and whether there is one (rays whose iterations run
    out have none).
    """
    with dr.suspend_grad():
        o, d, tmax = dr.detach(o), dr.detach(d), dr.detach(tmax)
        t0, t1, act = ray_interval(sdf, o, d, tmax, mi.Bool(active), pad=pad)
        def band(p, t):
            return hit_tolerance(sdf, opts, p, t)

        f_o = dr.abs(sdf.distance(mi.Point3f(o)))
        state = (mi.Float(dr.select(act, t0, 0.0)), mi.Bool(False), mi.Bool(f_o >= band(o, 0.0)),
                 mi.UInt32(0), mi.Float(dr.inf), mi.Float(0.0), mi.Float(dr.inf), mi.Float(0.0),
                 mi.Bool(False), mi.Float(0.0))

        def cond(t, hit, armed, steps, m_best, t_best, m_cur, t_cur, dipped, f_last):
            return act & ~hit & (t < t1) & (steps < CLOSE_STEPS * opts.max_steps)

        def body(t, hit, armed, steps, m_best, t_best, m_cur, t_cur, dipped, f_last):
            p = dr.fma(d, t, o)
            f = dr.abs(sdf.distance(mi.Point3f(p)))
            eps = band(p, t)
            hit = armed & (f < eps)
            track = armed & ~hit
            lower = track & (f < m_cur)
            dipped |= lower & dr.isfinite(m_cur)
            m_cur = dr.select(lower, f, m_cur)
            t_cur = dr.select(lower, t, t_cur)
            done = track & dipped & (f > RISE * m_cur)         # a minimum passed
            better = done & (m_cur < m_best)
            m_best = dr.select(better, m_cur, m_best)
            t_best = dr.select(better, t_cur, t_best)
            m_cur = dr.select(done, f, m_cur)
            t_cur = dr.select(done, t, t_cur)
            dipped &= ~done
            armed |= f >= eps
            f_last = dr.select(track, f, f_last)
            t = dr.select(hit, t, t + dr.maximum(f, 0.5 * eps))
            return t, hit, armed, steps + 1, m_best, t_best, m_cur, t_cur, dipped, f_last

        t, hit, armed, steps, m_best, t_best, m_cur, t_cur, dipped, f_last = dr.while_loop(
            state, cond, body, label="sdf_closest_approach")
        hit &= act & (t < t1)
        left = act & ~hit & (t >= t1)          # left the boxes or reached tmax
        # a minimum before the end counts (the ray passed it, then left or met a mesh)
        tail = left & dipped & (f_last > m_cur) & (m_cur < m_best)
        m_best = dr.select(tail, m_cur, m_best)
        t_best = dr.select(tail, t_cur, t_best)
        found = act & (left | hit) & dr.isfinite(m_best)
        # the steps sample |f| about m apart around the minimum: refine between them
        m_fine, t_fine = _lowest_along(sdf, o, d, t_best, dr.select(found, m_best, 0.0),
                                       dr.select(sdf.distance(mi.Point3f(dr.fma(d, t_best, o))) < 0, -1.0, 1.0))
        better = found & (m_fine < m_best) & (m_fine > 0)
        m_best = dr.select(better, m_fine, m_best)
        t_best = dr.select(better, t_fine, t_best)
        # the outline the tracer renders is |f| = its hit band, not |f| = 0
        m_best = dr.maximum(m_best - band(dr.fma(d, t_best, o), t_best), 0.0)
    return hit, t_best, m_best, found


def attached_minimum(sdf, o: mi.Point3f, d: mi.Vector3f, t: mi.Float, m: mi.Float, delta,
                     active: mi.Bool):
    """``m`` carrying the derivative of the ray's closest approach ``min_t |f(o + t d)|`` with
    respect to the SDF parameters (and ``o``, ``d`` where they are attached).

    At a smooth minimum that is ``df/dpi`` there (envelope theorem); at a *kink* (a crease's
    edge: ``f = max(a, b)`` of a sharp operator or a box, the minimum where the two pieces
    cross) it is ``(s+ f-_pi - s- f+_pi) / (s+ - s-)``, from the slopes ``s-``, ``s+`` and the
    parameter derivatives on either side (the crossing itself moves). Both come out of the same
    formula with the one-sided values at ``t -/+ delta``: a smooth minimum gives each side half
    the weight. (At a crease the envelope derivative is one piece's alone: a subtraction's
    bite radius got none where it moved the outline.) 0 without a derivative outside
    ``active`` (where ``m`` may be infinite: no minimum)."""
    with dr.suspend_grad():
        active = active & dr.isfinite(m) & dr.isfinite(t) & dr.isfinite(delta)
        m = dr.select(active, m, 0.0)
        delta = dr.select(active, delta, 0.0)
        od, dd, td = dr.detach(o), dr.detach(d), dr.select(active, dr.detach(t), 0.0)
        sgn = dr.select(sdf.distance(mi.Point3f(dr.fma(dd, td, od))) < 0, -1.0, 1.0)
        f0 = sgn * sdf.distance(mi.Point3f(dr.fma(dd, td, od)))
        fl = sgn * sdf.distance(mi.Point3f(dr.fma(dd, td - delta, od)))
        fr = sgn * sdf.distance(mi.Point3f(dr.fma(dd, td + delta, od)))
        s_l = dr.minimum(f0 - fl, 0.0)
        s_r = dr.maximum(fr - f0, 0.0)
        den = s_r - s_l
        ok = den > 1e-12
        w_l = dr.select(ok, s_r / dr.select(ok, den, 1.0), 0.5)
    left = sdf.distance(mi.Point3f(o + (td - delta) * d))
    right = sdf.distance(mi.Point3f(o + (td + delta) * d))
    value = dr.replace_grad(dr.detach(m), sgn * (w_l * left + (1.0 - w_l) * right))
    return dr.select(active, value, dr.detach(m))


def _lowest_along(sdf, o, d, t, w, side):
    """``(side * f, t)`` at the lowest of 9 points ``t + w [-1, 1]`` on the ray ``o + t d``,
    refined by a parabola through it and its neighbours."""
    best_f, best_t = mi.Float(dr.inf), mi.Float(t)
    fs = []
    for i in range(9):
        ti = t + w * (i / 4.0 - 1.0)
        fi = side * sdf.distance(mi.Point3f(dr.fma(d, ti, o)))
        fs.append((ti, fi))
        lower = fi < best_f
        best_f = dr.select(lower, fi, best_f)
        best_t = dr.select(lower, ti, best_t)
    # parabola through the lowest sample and its neighbours (interior samples only)
    h = w / 4.0
    f0 = side * sdf.distance(mi.Point3f(dr.fma(d, best_t, o)))
    fm = side * sdf.distance(mi.Point3f(dr.fma(d, best_t - h, o)))
    fp = side * sdf.distance(mi.Point3f(dr.fma(d, best_t + h, o)))
    curv = fm + fp - 2.0 * f0
    ok = curv > 1e-12
    shift = dr.select(ok, 0.5 * h * (fm - fp) / dr.select(ok, curv, 1.0), 0.0)
    shift = dr.clip(shift, -h, h)
    t_min = best_t + shift
    f_min = side * sdf.distance(mi.Point3f(dr.fma(d, t_min, o)))
    return dr.minimum(f_min, f0), dr.select(f_min < f0, t_min, best_t)


def inside_ray(sdf, o: mi.Point3f, d: mi.Vector3f, t: mi.Float, m: mi.Float, eps: mi.Float,
               opts: TracerOptions, deeper: float = 1.0, iterations: int = 3):
    """The direction from ``o`` whose ray passes ``GRAZE * eps`` (at least four of the
    tracer's hit tolerances), times ``deeper``, beneath the outline that the ray ``o + t d``
    approached to ``m``: it meets the surface grazing, just inside the outline.

    Newton steps across the ray: each turns the ray towards the surface by (its lowest
    ``|f|`` + the depth wanted) / ``|grad f|`` across it; a smooth blend's ``f`` is a bound
    (``|grad f| < 1``) and curved, so one step falls short. Returns ``(direction, ok)``, ``ok``
    where the last ray dips to the depth within half of it; detached."""
    with dr.suspend_grad():
        p = mi.Point3f(dr.fma(d, t, o))
        side = dr.select(sdf.distance(p) < 0, -1.0, 1.0)      # towards the surface
        tol = hit_tolerance(sdf, opts, p, t)
        depth = deeper * dr.maximum(GRAZE * eps, 4.0 * tol)
        ok = mi.Bool(True)
        g0 = side * gradient(sdf, p)
        across0 = g0 - dr.dot(g0, d) * d
        a0 = dr.squared_norm(across0)
        across0 = dr.select(a0 > 1e-12, across0 * dr.rsqrt(dr.select(a0 > 1e-12, a0, 1.0)), 0.0)
        rate0 = dr.maximum(dr.sqrt(a0), 0.05)
        d_now, f_now, t_now = mi.Vector3f(d), mi.Float(m), mi.Float(t)
        for _ in range(iterations):
            q = dr.fma(d_now, t_now, o)
            g = side * gradient(sdf, mi.Point3f(q))
            across = g - dr.dot(g, d_now) * d_now
            a2 = dr.squared_norm(across)
            ok &= a2 > 1e-12
            rate = dr.maximum(dr.sqrt(dr.select(a2 > 1e-12, a2, 1.0)), 0.05)
            step = (f_now + depth) / rate
            move = dr.select(a2 > 1e-12, across / rate, 0.0) * step
            d_now = dr.normalize(q - move - o)
            f_now, t_now = _lowest_along(sdf, o, d_now, t_now, 2.0 * step + 4.0 * tol, side)
            f_now = dr.maximum(f_now, -depth)        # close enough: no step back out
            f_now = dr.select(f_now <= -0.5 * depth, -depth, f_now)
        ok &= f_now <= -0.5 * depth
        # where Newton fails (a crease: the gradient jumps between faces), bisect the offset
        # across the ray at the closest point between none and 8 first-order reaches
        lo, hi = mi.Float(0.0), 8.0 * (m + depth) / rate0
        w = 2.0 * hi + 4.0 * tol
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            d_mid = dr.normalize(p - across0 * mid - o)
            f_mid, _ = _lowest_along(sdf, o, d_mid, t, w, side)
            deep = f_mid <= -depth
            hi = dr.select(deep, mid, hi)
            lo = dr.select(deep, lo, mid)
        d_bis = dr.normalize(p - across0 * hi - o)
        f_bis, _ = _lowest_along(sdf, o, d_bis, t, w, side)
        use = ~ok & (a0 > 1e-12) & (f_bis <= -0.5 * depth)
        return dr.select(use, d_bis, d_now), ok | use


__all__ = ["Band", "kernel", "closest_approach", "attached_minimum", "inside_ray", "RISE", "GRAZE"]
