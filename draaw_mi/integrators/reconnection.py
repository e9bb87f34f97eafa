"""Path reuse at second vertices whose light depends on where they are seen from: the
reconnection shift, with the balance heuristic over every sampling technique of the tile.

:mod:`~.pixel_reuse` shares a path's second vertex ``x2`` among the four pixels of a 2x2 tile.
On a Lambertian surface the light ``x2`` reflects is the same towards every pixel's first
vertex; on any other surface without delta lobes (glossy metal, plastic, a normal-mapped
diffuse) it is ``Lr_c(x2) = int f(x2; w_c, w) Li(x2, w) dw`` with ``w_c`` towards the pixel
``c``'s first vertex, so the BSDF at ``x2`` is evaluated again towards each pixel (the
reconnection shift of gradient-domain path tracing and ReSTIR PT: Lin et al. 2022,
"Generalized resampled importance sampling"). The weights then come from the balance
heuristic over the techniques that can produce each sample, the densities of the whole
connection (Veach 1997): the BSDF sample ``w`` at ``x2`` and what it finds at ``x3`` was
drawn by member ``k`` with density ``p_k(x2) q_k(w)``, its BSDF (or the guided mixture)
towards ``w`` seen from its own first vertex; the light sample at ``x2`` with ``p_k(x2) pl(w)``.
So, at pixel ``c`` (``f_c``: its first vertex's BSDF and the geometry term towards ``x2``)::

    f_c [ f(w_c, we) E / sum_j p_j (1 + q_j(we) / pl(we))                 (light sample)
        + f(w_c, wb) ( Le3 / sum_j p_j (q_j(wb) + pl(wb))                (emission at x3)
                     + R3 / sum_j p_j q_j(wb) ) ]                       (light beyond x3)

``E``: the light sample's value before the BSDF (``1 / pl`` taken as 0 for a delta light,
which BSDF sampling cannot reach); ``Le3``: the emission found at ``x3``; ``R3``: the light the
rest of the path brought to ``x3``. Each member delivers one sample of each technique, so the
estimate is ``path``'s in expectation. With the members' BSDF densities in the sums, a
neighbour's sample weighs little where its own BSDF would rarely have drawn that direction: on
a near-mirror the estimate falls back to the pixel's own sample, without the fireflies of
re-weighting by ``f(w_c, w) / q_k(w)`` alone (which took the speed suite's metal spheres to
100x ``path``'s error).

The BSDF at ``x2`` is evaluated after the path loop, for the paths that brought light back
(15 % of them on the glossy panel, 60 % in the Cornell box), tracing the ray to ``x2`` once more: cheaper than
eight more BSDF calls at every second vertex in the loop.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from . import guiding
from .pixel_reuse import TILE, SharedLight, tile_member

SLOTS = TILE * TILE
NONE = 0xFFFFFFFF       # a lane without a record (its x2 brought no light back)
AUTO_MAX_PIXELS = 1 << 19   # ``auto`` re-evaluates in images up to this size: about 330 bytes a
                            # lane (glossy panel at 64 spp, peak: 512^2 341 MiB, path's 160;
                            # 1024^2, a pass of one sample of every pixel, 518 against 176)


def _rcp(x: mi.Float) -> mi.Float:
    return dr.select(x > 0, dr.rcp(x), 0.0)


class ReconnectedLight(SharedLight):
    """:class:`~.pixel_reuse.SharedLight` where a second vertex's BSDF depends on where it is
    seen from (see the module docstring), as ``draaw_v4``'s loop state. :attr:`L` holds ``R3``
    (the throughput ``β`` counted from the third vertex's bounce); the loop records the light
    sample at ``x2`` (:attr:`wo_e`, :attr:`E`, :attr:`rpl_e`), its BSDF sample
    (:attr:`wo_b`), the emission at ``x3`` (:attr:`Le3`, :attr:`pl3`) and the ray to ``x2``
    (:attr:`o`, :attr:`d`), through :meth:`record`."""
    DRJIT_STRUCT = dict(SharedLight.DRJIT_STRUCT, wo_e=mi.Vector3f, E=mi.Spectrum, rpl_e=mi.Float,
                        wo_b=mi.Vector3f, Le3=mi.Spectrum, pl3=mi.Float, o=mi.Point3f, d=mi.Vector3f)
    _first_kept = 2

    def __init__(self, shared=None, β=None, L=None, x2=None, wo_e=None, E=None, rpl_e=None,
                 wo_b=None, Le3=None, pl3=None, o=None, d=None):
        super().__init__(shared, β, L, x2)
        self.wo_e = mi.Vector3f(0.0) if wo_e is None else wo_e
        self.E = mi.Spectrum(0.0) if E is None else E
        self.rpl_e = mi.Float(0.0) if rpl_e is None else rpl_e
        self.wo_b = mi.Vector3f(0.0) if wo_b is None else wo_b
        self.Le3 = mi.Spectrum(0.0) if Le3 is None else Le3
        self.pl3 = mi.Float(0.0) if pl3 is None else pl3
        self.o = mi.Point3f(0.0) if o is None else o
        self.d = mi.Vector3f(0.0) if d is None else d
        self._idx = self._rec = self._f = self._q = None      # after the loop (prepare)

    def own_part(self, depth, Le, Lr, Le_raw, Lr_raw):
        """As :meth:`SharedLight.own_part <.pixel_reuse.SharedLight.own_part>`, where
        :attr:`L` takes the light samples from the third vertex on and the emission from the
        fourth (the second's light sample and the third's emission: :meth:`record`)."""
        rel = self.shared & (depth >= 1)
        if Le_raw is not None:
            self.L += dr.select(rel & (depth >= 3), self.β * Le_raw, 0.0)
        if Lr_raw is not None:
            self.L += dr.select(rel & (depth >= 2), self.β * Lr_raw, 0.0)
        return dr.select(rel, dr.select(depth == 1, Le, 0.0), Le + Lr)

    def record(self, depth: mi.UInt32, ray: mi.Ray3f, wo_e, E, rpl_e, wo_b: mi.Vector3f, Le, pl) -> None:
        """At each vertex of a shared path: at ``x2`` (reached by ``ray``) its light sample's
        direction (local), value before the BSDF and ``1 / pl`` (0 for delta lights; ``None``:
        the scene has no light to sample), and its BSDF sample's direction (local); at ``x3``
        the emission it shows (unweighted; ``None``: nothing to hit) and the light sample's
        density ``pl`` for it from ``x2`` (0 where light sampling cannot reach it)."""
        at2 = self.shared & (depth == 1)
        if E is not None:
            self.wo_e = dr.select(at2, wo_e, self.wo_e)
            self.E = dr.select(at2, self.β * E, self.E)
            self.rpl_e = dr.select(at2, rpl_e, self.rpl_e)
        self.wo_b = dr.select(at2, wo_b, self.wo_b)
        self.o = dr.select(at2, ray.o, self.o)
        self.d = dr.select(at2, ray.d, self.d)
        if Le is not None:
            at3 = self.shared & (depth == 2)
            self.Le3 = dr.select(at3, self.β * Le, self.Le3)
            self.pl3 = dr.select(at3, pl, self.pl3)

    def prepare(self, scene, layout, ray, pi, active, flags, guide) -> None:
        """For each shared ``x2`` that brought light back (a record), the BSDF towards each
        slot's first vertex: its values (``f``: light sample, BSDF sample) and densities (``q``;
        the guided mixture's where guided) at ``4 record + slot``; each lane's record
        (:data:`NONE` without)."""
        n = dr.width(self.shared)
        valid = active & pi.is_valid()
        first = dr.select(valid, ray(pi.t), ray.o)
        need = self.shared & ((dr.max(self.E) > 0) | (dr.max(self.Le3) > 0) | (dr.max(self.L) > 0))
        dr.eval(valid, first, need)
        self._idx = idx = dr.compress(need)
        m = dr.width(idx)
        self._rec = dr.full(mi.UInt32, NONE, n)
        dr.scatter(self._rec, dr.arange(mi.UInt32, m), idx)
        self._f = [dr.zeros(mi.Spectrum, m * SLOTS) for _ in range(2)]
        self._q = [dr.zeros(mi.Float, m * SLOTS) for _ in range(2)]
        if m == 0:
            return
        si = scene.ray_intersect(mi.Ray3f(dr.gather(mi.Point3f, self.o, idx), dr.gather(mi.Vector3f, self.d, idx)),
                                 ray_flags=flags, coherent=False)
        bsdf = si.bsdf()
        ctx = mi.BSDFContext()
        wo_e, wo_b = dr.gather(mi.Vector3f, self.wo_e, idx), dr.gather(mi.Vector3f, self.wo_b, idx)
        lit = dr.max(dr.gather(mi.Spectrum, self.E, idx)) > 0
        record = dr.arange(mi.UInt32, m)

        def slot(k):
            member, inside = tile_member(layout, idx, k)
            go = inside & dr.gather(mi.Bool, valid, member) & si.is_valid()
            v = dr.gather(mi.Point3f, first, member, go) - si.p
            si_k = mi.SurfaceInteraction3f(si)
            si_k.wi = si.to_local(v * dr.rsqrt(dr.maximum(dr.squared_norm(v), 1e-30)))
            at = record * SLOTS + k
            for i, (wo, on) in enumerate(((wo_e, go & lit), (wo_b, go))):
                f, q = bsdf.eval_pdf(ctx, si_k, wo, on)
                if guide is not None:
                    q = guiding.mix_pdf(guide, si.p, si.to_world(wo), q, on)
                dr.scatter(self._f[i], f, at, on)
                dr.scatter(self._q[i], q, at, on)
            return (k + 1,)

        # one symbolic loop over the slots: its BSDF calls in one kernel (outside a loop
        # each call ends the kernel before it)
        dr.while_loop((dr.zeros(mi.UInt32, m),), lambda k: k < SLOTS, slot, labels=("k",), label="reconnection")
        dr.eval(self._rec, self._f, self._q)

    def weigh(self, density) -> None:
        """Per record: the light sample's weight ``E / sum_j p_j (1 + q_j / pl)`` and the BSDF
        sample's ``Le3 / sum_j p_j (q_j + pl3) + R3 / sum_j p_j q_j`` (the module docstring),
        to be multiplied by the BSDF at ``x2`` and at the first vertex."""
        idx = self._idx
        if dr.width(idx) == 0:
            self._w = None
            return
        p = density(idx)
        at = dr.arange(mi.UInt32, dr.width(idx)) * SLOTS
        q_e = [dr.gather(mi.Float, self._q[0], at + j) for j in range(SLOTS)]
        q_b = [dr.gather(mi.Float, self._q[1], at + j) for j in range(SLOTS)]
        rpl_e, pl3 = dr.gather(mi.Float, self.rpl_e, idx), dr.gather(mi.Float, self.pl3, idx)
        light = sum(p[j] * (1.0 + q_e[j] * rpl_e) for j in range(SLOTS))
        emitted = sum(p[j] * (q_b[j] + pl3) for j in range(SLOTS))
        beyond = sum(p[j] * q_b[j] for j in range(SLOTS))
        self._w = (dr.gather(mi.Spectrum, self.E, idx) * _rcp(light),
                   dr.gather(mi.Spectrum, self.Le3, idx) * _rcp(emitted)
                   + dr.gather(mi.Spectrum, self.L, idx) * _rcp(beyond))
        dr.eval(self._w)

    def contribution(self, member, slot, f):
        if self._w is None:
            return mi.Spectrum(0.0)
        rec = dr.gather(mi.UInt32, self._rec, member)
        has = rec != NONE
        at = rec * SLOTS + slot
        value = dr.gather(mi.Spectrum, self._f[0], at, has) * dr.gather(mi.Spectrum, self._w[0], rec, has)
        value += dr.gather(mi.Spectrum, self._f[1], at, has) * dr.gather(mi.Spectrum, self._w[1], rec, has)
        return f * value
