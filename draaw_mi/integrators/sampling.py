"""Variance-reduction helpers of ``draaw_v4`` (sampling decisions, not light transport).

* :func:`roulette` -- Russian roulette that only stops *weak* paths: a path whose throughput
  (times ``eta^2``) is above ``threshold`` always continues, a weaker one survives with
  probability ``throughput / threshold`` (at least ``rr_min``) and is re-weighted by its
  inverse. Mitsuba's ``path`` / ``prb`` instead survive with ``min(throughput, 0.95)``: even a
  bright path is stopped 5 % of the time at each bounce, which costs variance wherever the
  remaining bounces carry most of the light (open scenes under a sky, metals).

The survival probability only depends on the path's own sampled values, and survivors are
divided by it, so the estimator keeps its expectation (the standard Russian-roulette
argument; ``tests/integrators/test_integrators_expectation.py`` checks it per pixel).

* :class:`PowerSelection` -- next-event estimation picks an emitter in proportion to a power
  estimate instead of uniformly (Mitsuba's default), for scenes whose emitters differ in
  strength; the hit-side MIS pdf uses the same probabilities.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


def survival_probability(beta_max: mi.Float, eta: mi.Float, threshold: float,
                         rr_min: float) -> mi.Float:
    """``clip(beta_max * eta^2 / threshold, rr_min, 1)`` (detached).

    >>> import draaw_mi, mitsuba as mi
    >>> survival_probability(mi.Float(0.05, 0.5), mi.Float(1.0), 0.25, 0.05)
    [0.2, 1]
    """
    q = dr.detach(beta_max * dr.square(eta)) * (1.0 / threshold)
    return dr.clip(q, rr_min, 1.0)


def roulette(beta: mi.Spectrum, eta: mi.Float, depth: mi.UInt32, rr_depth: int,
             threshold: float, rr_min: float, u: mi.Float, active: mi.Bool, also=None):
    """Russian roulette after the path has ``rr_depth`` segments (``depth + 1 >= rr_depth``).

    Returns ``(beta, active)``: survivors re-weighted by ``1 / q``, stopped paths inactive;
    with ``also`` (a throughput of part of the path), ``(beta, active, also)``, ``also``
    re-weighted alike.
    """
    beta_max = dr.max(beta)
    active = active & (beta_max != 0)
    rr_active = depth + 1 >= rr_depth
    q = survival_probability(beta_max, eta, threshold, rr_min)
    rr_active &= q < 1.0
    beta = dr.select(rr_active, beta * dr.rcp(q), beta)
    alive = active & (~rr_active | (u < q))
    if also is None:
        return beta, alive
    return beta, alive, dr.select(rr_active, also * dr.rcp(q), also)


def only_constant_environment(scene: mi.Scene) -> bool:
    """Whether every emitter of ``scene`` is a constant environment (``constant``).

    There, next-event estimation only adds cost: its uniform sphere samples waste half their
    shadow rays below the horizon, while the BSDF's own sampling (cosine, GGX) already follows
    the integrand up to visibility; ``draaw_v4`` then samples the BSDF alone (MIS weight 1).
    """
    emitters = scene.emitters()
    # infinite and not spatially varying: Mitsuba's ``constant`` (flags only: no JIT values
    # are read, so this also works while dr.freeze records a render)
    return len(emitters) > 0 and all(
        mi.has_flag(e.flags(), mi.EmitterFlags.Infinite)
        and not mi.has_flag(e.flags(), mi.EmitterFlags.SpatiallyVarying)
        # a directional sun is Infinite too, but a delta light: BSDF sampling never hits it
        and not mi.has_flag(e.flags(), mi.EmitterFlags.Delta) for e in emitters)


# ---------------------------------------------------------------------------------------
#  Emitter selection by power (scenes with several emitters of different strength)
# ---------------------------------------------------------------------------------------

POWER_SPREAD = 1.5      # select by power only when the strongest / weakest estimate exceeds this


POWER_SAMPLES = 16        # a 16 x 16 stratified pattern of ``sample_ray`` calls per emitter


def emitter_powers(scene: mi.Scene) -> np.ndarray:
    """The power of each of ``scene.emitters()`` (finite ones: an infinite one's is
    ``inf``), by Monte Carlo: the mean luminance of ``sample_ray``'s weights (emitted radiance
    over the ray's density, whose expectation is the power) on a fixed stratified pattern, for
    every emitter in one vectorised call. So a spot's cone and falloff, a textured area light's
    texture and a mesh light's area all count as the emitter's own ``sample_ray`` sees them.
    Only steers selection: any positive value keeps the estimate unbiased. Where an emitter
    cannot sample rays, every power is ``inf`` (unknown: :meth:`PowerSelection.of` then
    leaves the choice uniform).

    >>> import mitsuba as mi; from draaw_mi.integrators.sampling import emitter_powers
    >>> scene = mi.load_dict({"type": "scene", "p": {"type": "point", "intensity": 2.0},
    ...                       "s": {"type": "spot", "intensity": 2.0, "cutoff_angle": 30}})
    >>> p = emitter_powers(scene); round(float(p[0] / (8 * 3.14159265)), 4), bool(p[1] < p[0] / 10)
    (1.0, True)
    """
    emitters = scene.emitters()
    power = np.full(len(emitters), np.inf)
    finite = [k for k, e in enumerate(emitters)
              if not mi.has_flag(e.flags(), mi.EmitterFlags.Infinite)]
    if not finite:
        return power
    m = POWER_SAMPLES * POWER_SAMPLES
    g = (np.arange(POWER_SAMPLES) + 0.5) / POWER_SAMPLES
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    ids = np.repeat(np.array(finite, np.uint32), m)
    with dr.suspend_grad():
        ptr = dr.gather(mi.EmitterPtr, scene.emitters_dr(), mi.UInt32(ids))
        uv = mi.Point2f(np.tile(u, len(finite)), np.tile(v, len(finite)))
        vu = mi.Point2f(np.tile(v, len(finite)), np.tile(u, len(finite)))
        try:
            _, weight = ptr.sample_ray(0.0, 0.5, uv, vu, True)
            rgb = np.array(mi.Color3f(weight), dtype=np.float64)    # (3, lanes)
        except (RuntimeError, NotImplementedError, TypeError):
            return power          # an emitter without sample_ray (a plugin of one's own): unknown
    lum = np.array([0.2126, 0.7152, 0.0722]) @ rgb
    lum = np.where(np.isfinite(lum), np.maximum(lum, 0.0), 0.0)
    power[finite] = lum.reshape(len(finite), m).mean(1)
    return power


POWER_UNIFORM_SHARE = 0.05     # of the power table's probability, spread evenly over the lights


class PowerSelection:
    """Emitter selection proportional to :func:`emitter_powers`; ``None`` from :meth:`of` when
    uniform selection (Mitsuba's) is as good: a single emitter or similar powers.

    The table is four plain Dr.Jit arrays (:meth:`arrays`), so a ``dr.freeze`` recording can
    take it as an input (:meth:`Session.recording <draaw_mi.rendering.session.Session.recording>`): frozen and traced renders then
    choose lights alike, and a replay reads the table it is given rather than a stale copy."""

    def __init__(self, n: int, pmf: mi.Float, cdf: mi.Float, pmf_by_id: mi.Float,
                 emitter_ids: mi.UInt32):
        # the emitter count as a Python int: a recording keyed on it re-traces when it changes
        self.n = int(n)
        self.pmf_dr, self.cdf, self.pmf_by_id, self.emitter_ids = pmf, cdf, pmf_by_id, emitter_ids
        self.emitters = dr.reinterpret_array(mi.EmitterPtr, emitter_ids)

    @staticmethod
    def from_power(scene: mi.Scene, power: np.ndarray) -> "PowerSelection":
        power = np.maximum(np.asarray(power, np.float64), 0.0)
        # a share spread evenly: else a dark light (intensity 0, or 1e-3 of the others) is
        # practically never sampled, so its gradient comes out 0, or 35x off on the seed that
        # draws it; a light being fitted up from dark is a normal inverse-lighting case
        pmf = (1.0 - POWER_UNIFORM_SHARE) * power / power.sum() + POWER_UNIFORM_SHARE / power.size
        cdf = np.cumsum(pmf)
        cdf[-1] = 1.0
        ids = np.array(dr.reinterpret_array(mi.UInt32, scene.emitters_dr()), dtype=np.int64)
        table = np.zeros(ids.max() + 1)
        table[ids] = pmf                              # registry id -> selection probability
        return PowerSelection(len(pmf), mi.Float(pmf), mi.Float(cdf), mi.Float(table), mi.UInt32(ids))

    def arrays(self) -> tuple:
        """The table as inputs for a ``dr.freeze`` recording (see :meth:`from_arrays`)."""
        return (self.n, self.pmf_dr, self.cdf, self.pmf_by_id, self.emitter_ids)

    @staticmethod
    def from_arrays(arrays: tuple) -> "PowerSelection":
        return PowerSelection(*arrays)

    @property
    def pmf_np(self) -> np.ndarray:
        return np.array(self.pmf_dr, dtype=np.float64)

    @staticmethod
    def of(scene: mi.Scene) -> "PowerSelection | None":
        emitters = scene.emitters()
        if len(emitters) < 2:
            return None
        if any(mi.has_flag(e.flags(), mi.EmitterFlags.Infinite) for e in emitters):
            # An environment's power (through the scene's bounding sphere) says little about
            # what it gives the visible surfaces: measured on the thesis scene (sky, area
            # light, point light), the table gives the sky 58 % of the light samples and
            # starves the point light, whose glints on the near-mirror floor carry most of the
            # image's variance (pbrt-v4 also keeps infinite lights out of its power/BVH sampling).
            return None
        power = emitter_powers(scene)
        if not np.all(np.isfinite(power)) or power.max() <= 0:
            return None
        if power.max() < POWER_SPREAD * max(power.min(), 1e-30):
            return None
        return PowerSelection.from_power(scene, power)

    def sample_index(self, x: mi.Float, active: mi.Bool):
        """``(index, reused sample, pmf)``: the emitter whose CDF interval holds ``x`` (as
        ``DiscreteDistribution.sample_reuse_pmf``, on this object's own arrays)."""
        n = self.n
        idx = dr.binary_search(0, n - 1, lambda i: dr.gather(mi.Float, self.cdf, i) <= x)
        idx = dr.minimum(idx, n - 1)
        pmf = dr.gather(mi.Float, self.pmf_dr, idx, active)
        lo = dr.gather(mi.Float, self.cdf, dr.maximum(idx, 1) - 1, active & (idx > 0))
        u = dr.clip((x - dr.select(idx > 0, lo, 0.0)) * dr.rcp(dr.maximum(pmf, 1e-30)), 0.0,
                    dr.one_minus_epsilon(mi.Float))
        return idx, u, pmf

    def pmf(self, emitter: mi.EmitterPtr, active: mi.Bool) -> mi.Float:
        idx = dr.reinterpret_array(mi.UInt32, emitter)
        return dr.gather(mi.Float, self.pmf_by_id, idx, active & (emitter != None))  # noqa: E711

    def pdf_direction(self, ref: mi.Interaction3f, ds: mi.DirectionSample3f, active: mi.Bool):
        """Solid-angle pdf of NEE towards ``ds`` (replaces ``scene.pdf_emitter_direction``)."""
        return ds.emitter.pdf_direction(ref, ds, active) * self.pmf(ds.emitter, active)

    def sample(self, scene: mi.Scene, si: mi.SurfaceInteraction3f, sample: mi.Point2f,
               active: mi.Bool, primal: bool, sdf=None):
        """As :func:`~draaw_mi.integrators.common.sample_emitter`, the emitter chosen by power
        (``sdf``: the scene's SDF hook, whose objects also occlude the shadow ray)."""
        with dr.suspend_grad():
            idx, u, pmf = self.sample_index(sample.x, active)
            emitter = dr.gather(mi.EmitterPtr, self.emitters, idx, active)
            ds, w = emitter.sample_direction(si, mi.Point2f(u, sample.y), active)
            active = active & (ds.pdf != 0.0) & (pmf > 0)
            active &= ~scene.ray_test(si.spawn_ray_to(ds.p), active)
            if sdf is not None:
                active &= ~sdf.occluded(si, ds, active)
            inv = dr.select(active, dr.rcp(pmf), 0.0)
            ds.pdf *= pmf
            em_weight = w * inv
        if not primal:
            em_val = emitter.eval_direction(si if sdf is None else dr.detach(si), ds, active)
            em_weight = dr.replace_grad(em_weight, dr.select(active, em_val / dr.select(active, dr.detach(ds.pdf), 1.0), 0.0))
            if sdf is not None:
                ds, em_weight = sdf.emitter_geometry(si, ds, em_weight, active)
                em_weight = sdf.shadow_boundary(si, ds, em_weight, active)
        return ds, em_weight, active
