"""Tracking through one medium over a local majorant grid (used by :mod:`.volume`).

* :func:`free_flight` -- delta tracking: a DDA walks the coarse majorant cells along the ray
  inside ``dr.while_loop``; within a cell, tentative collisions are drawn against its bound and
  accepted as real with probability ``sigma_t / sigma_maj`` (empty cells cost one step);
* :func:`ratio_track` -- ratio-tracking transmittance over the same cells (Russian roulette
  on small T);
* :func:`transmittance` -- a shadow ray through media, ``null`` boundaries and blockers.

In the adjoint phase (path replay) each function back-propagates the log-derivative of every
factor it multiplies (null collisions ``d log sigma_n``, real ones ``d log sigma_s``, ratio
factors ``d log (1 - sigma_t / sigma_maj)``, closed-form ``d log T``); majorants are detached.
Loops stop after ``MAX_TRACKING_STEPS`` steps; an exhausted flight counts as absorbed.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .features import scene_shapes

# per flight; an exhausted flight counts as absorbed (documented). A guard against loops that
# never end (NaN distances), far above honest flights: one voxel of optical depth 5000 at the
# finest majorant level, scaled x2 in a differentiated render, takes ~10^4 null steps per cell.
MAX_TRACKING_STEPS = 1 << 16
# null-surface crossings per shadow ray (index-matched boundaries, masks); a shadow ray still
# live at the cap counts as blocked (T = 0), as an exhausted flight counts as absorbed: light
# never leaks through an opaque blocker behind many null surfaces
MAX_NULL_CROSSINGS = 1024
RATIO_RR = 0.1                # ratio tracking: Russian roulette on T below this

# the lobes that scatter light (a BSDF with Null and any of these lets light through in part)
_LOBES = int(mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DeltaReflection
             | mi.BSDFFlags.DiffuseTransmission | mi.BSDFFlags.GlossyTransmission
             | mi.BSDFFlags.DeltaTransmission)


def partly_null(scene: mi.Scene) -> bool:
    """Whether a shape's BSDF lets light through in part (``mask``: the ``Null`` flag and
    other lobes). Smoke scenes must not cross such surfaces as if absent (an opaque masked
    card would disappear); where none is, their handling adds no kernel code."""
    null = int(mi.BSDFFlags.Null)
    for shape in scene_shapes(scene):
        bsdf = shape.bsdf()
        if bsdf is not None:
            flags = int(bsdf.flags())
            if flags & null and flags & _LOBES:
                return True
    return False


def scatters(flags) -> mi.Bool:
    """Per lane: the BSDF ``flags`` include a lobe other than ``Null``."""
    return (flags & _LOBES) != 0


def _bw(x) -> None:
    """Back-propagate ``x`` when it depends on a differentiated parameter (else nothing)."""
    if dr.grad_enabled(x):
        dr.backward(x, flags=dr.ADFlag.Default | dr.ADFlag.AllowNoGrad)


#  Interactions
# ---------------------------------------------------------------------------------------

def medium_interaction(ray: mi.Ray3f, t: mi.Float, medium: mi.MediumPtr) -> mi.MediumInteraction3f:
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.t = t
    mei.p = ray(t)
    mei.wi = -ray.d
    mei.sh_frame = mi.Frame3f(mei.wi)
    mei.time = ray.time
    mei.wavelengths = ray.wavelengths
    mei.medium = medium
    return mei


def coefficients(medium, mei, active):
    """(sigma_s, sigma_t) with sigma_t grey (channel 0), both at least 0: a density an
    optimiser step took below 0 is no medium there, not a transmittance above 1 or negative
    scattering (the march of V1/V2 read pixels of -3.5 at a density of -0.5)."""
    sigma_s, _, sigma_t = medium.get_scattering_coefficients(mei, active)
    return dr.maximum(sigma_s, 0.0), dr.maximum(sigma_t.x, 0.0)


# ---------------------------------------------------------------------------------------
#  Tracking over the majorant grid
# ---------------------------------------------------------------------------------------

class Flight:
    """Result of a free flight: ``t`` of the real collision (inf if none), ``weight`` (primal
    throughput factor: albedo on a real collision, 1 on escape)."""

    def __init__(self, t, collided, weight):
        self.t, self.collided, self.weight = t, collided, weight


def _segment(table, medium, ray, tmax, active):
    """[t0, t1] of the ray inside the medium's box and below tmax."""
    ok, mint, maxt = medium.intersect_aabb(ray)
    t0 = dr.maximum(mint, 0.0)
    t1 = dr.minimum(maxt, tmax)
    ok = active & ok & (t1 > t0)
    return ok, dr.select(ok, t0, 0.0), dr.select(ok, t1, 0.0)


def _dda_setup(table, idx, ray, t0):
    lo = [dr.gather(mi.Float, table.lo[a], idx) for a in range(3)]
    size = [dr.gather(mi.Float, table.size[a], idx) for a in range(3)]
    res = [dr.gather(mi.Int32, table.res[a], idx) for a in range(3)]
    off = dr.gather(mi.UInt32, table.offset, idx)
    p = ray(t0)
    d = [ray.d.x, ray.d.y, ray.d.z]
    pc = [p.x, p.y, p.z]
    cell, t_next, dt, step = [], [], [], []
    for a in range(3):
        u = (pc[a] - lo[a]) / size[a]
        c = dr.clip(mi.Int32(dr.floor(u)), 0, res[a] - 1)
        pos = d[a] > 0
        nz = d[a] != 0
        inv = dr.select(nz, dr.rcp(dr.select(nz, d[a], 1.0)), 0.0)
        bound = lo[a] + mi.Float(c + dr.select(pos, 1, 0)) * size[a]
        t_next.append(dr.select(nz, t0 + (bound - pc[a]) * inv, dr.inf))
        dt.append(dr.select(nz, size[a] * dr.abs(inv), dr.inf))
        cell.append(c)
        step.append(dr.select(pos, mi.Int32(1), mi.Int32(-1)))
    return cell, t_next, dt, step, res, off


def _cell_step(table, off, res, cell, t_next, t, t1, sampler, live):
    """In the current DDA cell: its majorant, where the ray leaves it (capped at ``t1``), and a
    tentative collision distance sampled from the majorant (inf where it is 0). Returns
    ``(sig_maj, t_exit, has, t_c)``."""
    cx, cy, cz = cell
    tnx, tny, tnz = t_next
    flat = off + mi.UInt32(cx + res[0] * (cy + res[1] * cz))
    sig_maj = dr.gather(mi.Float, table.values, flat, live)
    t_exit = dr.minimum(dr.minimum(tnx, dr.minimum(tny, tnz)), t1)
    u = sampler.next_1d(live)
    has = live & (sig_maj > 0)
    t_c = dr.select(has, t - dr.log(1.0 - u) / dr.select(has, sig_maj, 1.0), dr.inf)
    return sig_maj, t_exit, has, t_c


def _dda_advance(step_on, t, t_exit, cell, t_next, dt, step, res):
    """One DDA step for the lanes ``step_on``: move ``t`` to the cell's exit and into the
    neighbouring cell along the axis whose boundary comes first. Returns ``(t, cell, t_next,
    out)``, ``out`` where the new cell lies outside the grid."""
    cx, cy, cz = cell
    tnx, tny, tnz = t_next
    ax = dr.select(tnx <= dr.minimum(tny, tnz), 0, dr.select(tny <= tnz, 1, 2))
    mx, my, mz = step_on & (ax == 0), step_on & (ax == 1), step_on & (ax == 2)
    t = dr.select(step_on, t_exit, t)
    cx, tnx = dr.select(mx, cx + step[0], cx), dr.select(mx, tnx + dt[0], tnx)
    cy, tny = dr.select(my, cy + step[1], cy), dr.select(my, tny + dt[1], tny)
    cz, tnz = dr.select(mz, cz + step[2], cz), dr.select(mz, tnz + dt[2], tnz)
    out = (cx < 0) | (cy < 0) | (cz < 0) | (cx >= res[0]) | (cy >= res[1]) | (cz >= res[2])
    return t, (cx, cy, cz), (tnx, tny, tnz), out


@dr.syntax
def free_flight(table, medium, idx, ray: mi.Ray3f, tmax: mi.Float, sampler: mi.Sampler,
                active: mi.Bool, adjoint=None) -> Flight:
    """Delta tracking from ``ray.o`` up to ``tmax`` in ``medium`` (grid / global kinds).

    ``adjoint``: ``(δL, L_rem)`` in the backward phase -- every null collision then
    back-propagates ``δL * L_rem * d log sigma_n``; None in the primal phase."""
    ok, t0, t1 = _segment(table, medium, ray, tmax, active)
    cell, t_next, dt, step, res, off = _dda_setup(table, idx, ray, t0)
    cx, cy, cz = cell
    tnx, tny, tnz = t_next
    t = mi.Float(t0)
    t_hit = mi.Float(dr.inf)
    collided = mi.Bool(False)
    weight = mi.Spectrum(1.0)
    it = mi.UInt32(0)
    live = mi.Bool(ok)
    while live:
        sig_maj, t_exit, has, t_c = _cell_step(table, off, res, (cx, cy, cz), (tnx, tny, tnz),
                                               t, t1, sampler, live)
        tentative = live & (t_c < t_exit)
        mei = medium_interaction(ray, t_c, medium)
        sigma_s, sigma_t = coefficients(medium, mei, tentative)
        u2 = sampler.next_1d(tentative)
        real = tentative & (u2 * sig_maj < sigma_t)
        null = tentative & ~real
        if dr.hint(adjoint is not None, mode="scalar"):
            with dr.resume_grad():
                s_s, s_t = coefficients(medium, mei, null | real)
                s_n = sig_maj - s_t
                ok_n = null & (dr.detach(s_n) > 1e-12 * sig_maj)
                r = dr.select(ok_n, s_n / dr.detach(dr.select(ok_n, s_n, 1.0)), 0.0)
                ok_s = real & (dr.detach(s_t) > 0)
                w = dr.select(ok_s, s_s / dr.detach(dr.select(ok_s, s_t, 1.0)), 0.0)
                w_d = dr.detach(w)
                _bw(adjoint[0] * adjoint[1] * (mi.Spectrum(r) + dr.select(w_d != 0, w / dr.select(w_d != 0, w_d, 1.0), 0.0)))
        ok_t = real & (sigma_t > 0)
        weight[real] = dr.select(ok_t, sigma_s / dr.select(ok_t, sigma_t, 1.0), 0.0)
        t_hit[real] = t_c
        collided |= real
        t[null] = t_c
        # advance the DDA where no tentative collision happened in this cell
        adv = live & ~tentative
        done = adv & (t_exit >= t1)
        step_on = adv & ~done
        t, (cx, cy, cz), (tnx, tny, tnz), out = _dda_advance(
            step_on, t, t_exit, (cx, cy, cz), (tnx, tny, tnz), dt, step, res)
        it += 1
        exhausted = it >= MAX_TRACKING_STEPS
        weight[live & exhausted & ~real] = 0.0          # exhausted: absorbed (never NaN)
        live &= ~real & ~done & ~out & ~exhausted
    return Flight(t_hit, collided, weight)


@dr.syntax
def ratio_track(table, medium, idx, ray: mi.Ray3f, tmax: mi.Float, sampler: mi.Sampler,
                active: mi.Bool, adjoint=None) -> mi.Float:
    """Ratio-tracking transmittance along ``ray`` up to ``tmax`` (grid / global kinds).

    Russian roulette on T below ``RATIO_RR`` keeps dense media cheap (unbiased).
    ``adjoint``: ``(δL, contribution)`` replays with gradients of each factor."""
    ok, t0, t1 = _segment(table, medium, ray, tmax, active)
    cell, t_next, dt, step, res, off = _dda_setup(table, idx, ray, t0)
    cx, cy, cz = cell
    tnx, tny, tnz = t_next
    t = mi.Float(t0)
    T = mi.Float(1.0)
    it = mi.UInt32(0)
    live = mi.Bool(ok)
    while live:
        sig_maj, t_exit, has, t_c = _cell_step(table, off, res, (cx, cy, cz), (tnx, tny, tnz),
                                               t, t1, sampler, live)
        tentative = live & (t_c < t_exit)
        mei = medium_interaction(ray, t_c, medium)
        _, sigma_t = coefficients(medium, mei, tentative)
        factor = dr.clip(1.0 - sigma_t / dr.select(has, sig_maj, 1.0), 0.0, 1.0)
        if dr.hint(adjoint is not None, mode="scalar"):
            with dr.resume_grad():
                _, s_t = coefficients(medium, mei, tentative)
                f = 1.0 - s_t / dr.select(has, sig_maj, 1.0)
                ok_f = tentative & (dr.detach(f) > 0)
                r = dr.select(ok_f, f / dr.detach(dr.select(ok_f, f, 1.0)), 0.0)
                _bw(adjoint[0] * adjoint[1] * mi.Spectrum(r))
        T[tentative] = T * factor
        t[tentative] = t_c
        # Russian roulette on small T
        u_rr = sampler.next_1d(tentative & (T < RATIO_RR))
        rr = tentative & (T < RATIO_RR)
        T[rr] = dr.select(u_rr * RATIO_RR < T, RATIO_RR, 0.0)
        adv = live & ~tentative
        done = adv & (t_exit >= t1)
        step_on = adv & ~done
        t, (cx, cy, cz), (tnx, tny, tnz), out = _dda_advance(
            step_on, t, t_exit, (cx, cy, cz), (tnx, tny, tnz), dt, step, res)
        it += 1
        exhausted = it >= MAX_TRACKING_STEPS
        T[live & exhausted] = 0.0
        live &= ~done & ~out & ~exhausted & (T > 0)
    return T


# ---------------------------------------------------------------------------------------
#  Transmittance between two points (shadow rays): media, null boundaries, blockers
# ---------------------------------------------------------------------------------------

@dr.syntax
def transmittance(table, scene: mi.Scene, ray: mi.Ray3f, dist: mi.Float, medium: mi.MediumPtr,
                  sampler: mi.Sampler, active: mi.Bool, adjoint=None) -> mi.Float:
    """Transmittance along ``ray`` over ``dist`` (inf: to infinity), starting in ``medium``:
    ratio tracking in media, crossing ``null`` surfaces (switching media), 0 at other
    surfaces. ``adjoint``: ``(δL, contribution)`` for the replay with gradients. A ray that
    would cross more than ``MAX_NULL_CROSSINGS`` null surfaces counts as blocked (T = 0)."""
    T = mi.Float(1.0)
    remaining = mi.Float(dist)
    med = dr.select(active, medium, dr.zeros(mi.MediumPtr))
    r = mi.Ray3f(ray)
    live = mi.Bool(active)
    n = mi.UInt32(0)
    partial = table.partly_null
    flags = mi.RayFlags.All if partial else mi.RayFlags.Minimal     # (a mask's opacity texture: uv)
    while live:
        r.maxt = remaining
        si = scene.ray_intersect(r, flags, False, live)
        seg = dr.minimum(si.t, remaining)
        in_med = live & (med != None)  # noqa: E711
        if dr.hint(table.has_tracked, mode="scalar"):
            idx = table.index(med)
            tracked = in_med & ~dr.gather(mi.Bool, table.is_homog, idx, in_med)
            Tm = ratio_track(table, med, idx, r, seg, sampler, tracked, adjoint)
            T[tracked] = T * Tm
        if dr.hint(table.has_homogeneous, mode="scalar"):
            homog = in_med
            if dr.hint(table.has_tracked, mode="scalar"):
                homog &= dr.gather(mi.Bool, table.is_homog, table.index(med), in_med)
            mei = medium_interaction(r, seg, med)
            with dr.resume_grad(when=adjoint is not None):
                _, s_t = coefficients(med, mei, homog)
                ok, mint, maxt = med.intersect_aabb(r)
                length = dr.maximum(dr.minimum(maxt, seg) - dr.maximum(mint, 0.0), 0.0)
                Th = dr.exp(-s_t * length)
                if dr.hint(adjoint is not None, mode="scalar"):
                    Thd = dr.detach(Th)
                    okh = homog & (Thd > 0)
                    _bw(adjoint[0] * adjoint[1] * mi.Spectrum(dr.select(okh, Th / dr.select(okh, Thd, 1.0), 0.0)))
            T[homog] = T * dr.detach(Th)
        hit = live & si.is_valid() & (si.t < remaining)
        bsdf = si.bsdf()
        null = hit & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Null)
        T[hit & ~null] = 0.0
        if dr.hint(partial, mode="scalar"):      # a mask passes 1 - opacity (volpath's weight)
            T[null] = T * bsdf.eval_null_transmission(si, null).x
        med[null & si.is_medium_transition()] = si.target_medium(r.d)
        remaining[null] = remaining - si.t
        r[null] = si.spawn_ray(r.d)
        n += 1
        live &= null & (T > 0)
        T[live & (n >= MAX_NULL_CROSSINGS)] = 0.0       # still crossing at the cap: blocked
        live &= n < MAX_NULL_CROSSINGS
    return T


