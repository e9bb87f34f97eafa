"""Volumetric path tracing for ``draaw_v3`` / ``draaw_v4`` (scenes whose ``media`` flag is on).

Estimator (the same expectation as Mitsuba's ``volpath``, tested per pixel):

* **Free flights** by delta tracking against a **local majorant grid** (pbrt-v4's design,
  :mod:`draaw_mi.media.majorant`): a DDA walks the coarse cells the ray crosses inside
  ``dr.while_loop``; in each cell tentative collisions are drawn against that cell's bound,
  accepted as real with probability ``sigma_t / sigma_maj``. Empty cells cost one DDA step.
  Homogeneous media are sampled in closed form (no grid code is compiled for them).
* **Next-event estimation** at every surface and medium vertex: one emitter sample whose
  transmittance is estimated by **ratio tracking** over the same majorant grid, through
  ``null`` (index-matched) boundaries and medium changes; opaque surfaces block. Emitters
  hit by BSDF / phase-sampled rays are combined with it by multiple importance sampling
  (power heuristic, as ``volpath``; weight 1 on camera rays and after delta bounces).
* Surfaces: any Mitsuba BSDF through ``sample`` / ``eval``; ``null`` BSDFs are crossed
  without counting a bounce (as ``volpath``); ``interior`` / ``exterior`` media switch at
  medium transitions; a camera inside a medium starts in the rendered sensor's medium.
* SDF objects (feature ``sdf``, :mod:`draaw_mi.sdf.integration`): every segment ends at the
  nearer of the mesh hit and the sphere-traced SDF hit (free flights stop there), SDF hits
  scatter with their slot's BSDF without changing the current medium (SDFs are opaque
  surfaces inside or outside media), and SDFs block shadow rays before ratio tracking runs.
  SDF hits are detached here: no SDF *shape* gradients in media scenes (material, medium and
  emitter gradients as usual).
* ``max_depth`` counts real scattering events as ``volpath`` does; ``draaw_v4`` adds Russian
  roulette (``rr_depth``), ``draaw_v3`` has none.

Differentiable by path replay w.r.t. medium density, albedo and the HG ``g`` (and BSDF /
emitter parameters), as ``prbvolpath``: majorants are detached; each null collision
contributes ``d log sigma_n``, each real collision ``d log sigma_s``, closed-form
homogeneous segments ``d log T``; shadow-ray transmittance is replayed with a cloned sampler.

Assumptions (checked when a render is prepared, a :class:`ParameterError` otherwise): grey
extinction (a one-channel ``sigma_t``; the albedo may be RGB).
"""
from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, RenderError
from ..media.majorant import build_majorant
from . import pass_sensor
from . import volume_tracking as vt
from .stamps import stamp as value_stamp
from .common import mis_weight
from .features import scene_shapes
from .volume_tracking import _bw, coefficients, medium_interaction

# While a medium parameter is differentiated, majorants are scaled by this factor: path replay
# differentiates transmittance only through null collisions (d log sigma_n), and where the
# majorant equals sigma_t (a uniform region) there are none, so the density gradient would
# silently miss the d/dsigma of the transmittance (prbvolpath has this bias on uniform grids).
DIFF_MAJORANT_FACTOR = 2.0
FREE_PATHS = 8.0              # free paths at the median density a global bound's flight takes at most
MEDIA_RR_DEPTH = 5            # first depth at which Russian roulette may stop a path (v4)


# ---------------------------------------------------------------------------------------
#  Scene preparation: one table of media and their majorant grids
# ---------------------------------------------------------------------------------------

class MediaTable:
    """Every medium of a scene with its majorant, as Dr.Jit arrays indexed per lane."""
    def __init__(self, scene: mi.Scene, factor: float = 1.0):
        top = scene.shapes()
        for shape in scene_shapes(scene):
            if all(shape is not s for s in top) and (shape.interior_medium() or shape.exterior_medium()):
                # (its medium would be ignored: a smoke-filled instanced sphere renders as empty)
                raise RenderError(f"draaw integrators: a participating medium on a shape inside a "
                                  f"shapegroup ({shape.id() or shape.class_name()}) is not supported; "
                                  "move the shape out of the group, or render with volpath")
        media, inside, names = [], [], []
        for shape in top:
            for m, side in ((shape.interior_medium(), "interior_medium"), (shape.exterior_medium(), "exterior_medium")):
                if m is not None and all(m is not x for x in media):
                    media.append(m)
                    names.append(f"{shape.id()}.{side}" if shape.id() else None)
                    bb = shape.bbox()
                    inside.append(0.5 * (np.array(bb.min) + np.array(bb.max)))
        # every sensor of the scene with its medium (None: in vacuum), looked up by identity
        # (camera_medium): a render from sensor k starts its camera rays in k's medium
        self.sensor_media = []
        for sensor in scene.sensors():
            m = sensor.get_medium()
            if m is not None and all(m is not x for x in media):
                media.append(m)
                names.append(f"{sensor.id()}.medium" if sensor.id() else None)
                inside.append(np.array(sensor.world_transform().translation(), float).ravel())
            self.sensor_media.append((sensor, m))
        self.media = media
        self.majorants = [build_majorant(m, inside=p, factor=factor, name=n) for m, p, n in zip(media, inside, names)]
        for m, mj, n in zip(media, self.majorants, names):
            self._check_grey(m)
            self._check_global(m, mj, n, factor)
        kinds = [mj.kind for mj in self.majorants]
        self.has_homogeneous = "homogeneous" in kinds
        self.has_tracked = any(k != "homogeneous" for k in kinds)
        self.partly_null = vt.partly_null(scene)        # masks (see volume_tracking.partly_null)
        # flat arrays for the tracked media
        offs, vals = [], []
        total = 0
        for mj in self.majorants:
            offs.append(total)
            vals.append(mj.values.ravel(order="F") * factor)  # x fastest
            total += mj.values.size
        self.values = mi.Float(np.concatenate(vals).astype(np.float32)) if vals else mi.Float(0)
        self.offset = mi.UInt32(np.array(offs or [0], np.uint32))
        res = np.array([mj.values.shape for mj in self.majorants] or [(1, 1, 1)], np.int32)
        lo = np.array([mj.bbox_min for mj in self.majorants] or [np.zeros(3)], np.float64)
        hi = np.array([mj.bbox_max for mj in self.majorants] or [np.ones(3)], np.float64)
        self.res = [mi.Int32(res[:, a]) for a in range(3)]
        self.lo = [mi.Float(lo[:, a].astype(np.float32)) for a in range(3)]
        self.size = [mi.Float(((hi[:, a] - lo[:, a]) / res[:, a]).astype(np.float32)) for a in range(3)]
        self.is_homog = mi.Bool(np.array([mj.kind == "homogeneous" for mj in self.majorants] or [False]))

    @staticmethod
    def _check_global(medium, mj, name, factor) -> None:
        """Warn of a medium under one global bound (a rotated / mirrored grid, a non-clamp wrap
        mode: :mod:`draaw_mi.media.majorant`) whose flights may run out of tracking steps and
        count as absorbed (a hot voxel of 2e5 in thin smoke, rotated: the image 17x darker).
        The steps a flight takes: the bound times the shorter of the box's diagonal and a few
        free paths at the grid's median density (a medium dense throughout collides early)."""
        if mj.kind != "global":
            return
        bound = factor * float(mj.values.max())
        reach = mj.diagonal if mj.median <= 0 else min(mj.diagonal, FREE_PATHS / mj.median)
        steps = bound * reach
        if steps > 0.5 * vt.MAX_TRACKING_STEPS:
            warnings.warn(
                f"draaw_v3/draaw_v4: medium {name or medium.id() or medium.class_name()!r} is bounded by one "
                f"global majorant ({mj.note}): sigma_t up to {float(mj.values.max()):.4g}"
                f"{' (x' + format(factor, 'g') + ' while differentiated)' if factor != 1 else ''} where its "
                f"median is {mj.median:.4g}, over a box diagonal of {mj.diagonal:.4g}: a flight may take "
                f"{steps:.3g} tracking steps, past the {0.5 * vt.MAX_TRACKING_STEPS:g} after which flights are "
                "cut short and count as absorbed (the medium renders too dark). Place the grid with an "
                "axis-aligned, unmirrored to_world (rotate or flip the data array instead), use wrap_mode "
                "'clamp', lower its densest voxels, or render with volpath", RuntimeWarning, stacklevel=2)

    @staticmethod
    def _check_grey(medium) -> None:
        params = mi.traverse(medium)
        for key in params.keys():
            if key.startswith("sigma_t."):
                v = np.array(params[key])
                if key.endswith(".data") and v.ndim == 4 and v.shape[3] != 1:
                    raise ParameterError(f"draaw_v3/draaw_v4: medium {medium.id() or medium} has a "
                                         f"{v.shape[3]}-channel sigma_t grid; expected grey extinction "
                                         "(one channel); render it with 'volpath'")
                if key.endswith("value") and v.size == 3 and not np.allclose(v, v.ravel()[0]):
                    raise ParameterError(f"draaw_v3/draaw_v4: medium {medium.id() or medium} has RGB "
                                         f"sigma_t {v.ravel().tolist()}; expected grey extinction")

    def camera_medium(self, sensor):
        """The medium of ``sensor`` (the rendered one, :func:`.pass_sensor.sensor_of`; ``None``: sensor 0,
        as in a ``sample()`` call outside a render pass), or ``None`` for vacuum."""
        if sensor is None:
            return self.sensor_media[0][1] if self.sensor_media else None
        for s, m in self.sensor_media:
            if s is sensor:
                return m
        m = sensor.get_medium()          # a sensor that is not the scene's
        if m is not None and all(m is not x for x in self.media):
            raise RenderError(f"draaw_v3/draaw_v4: sensor {sensor.id() or sensor.class_name()} is not one "
                              "of the scene's sensors and has a medium the scene does not know; "
                              "add the sensor to the scene (its medium then gets a majorant)")
        return m

    def index(self, medium: mi.MediumPtr) -> mi.UInt32:
        idx = mi.UInt32(0)
        for k, m in enumerate(self.media):
            idx = dr.select(medium == mi.MediumPtr(m), k, idx)
        return idx

    def describe(self) -> list[str]:
        return [f"{m.id() or type(m).__name__}: {mj.kind} {mj.values.shape}{' (' + mj.note + ')' if mj.note else ''}"
                for m, mj in zip(self.media, self.majorants)]


_TABLES: dict[int, tuple] = {}
_TABLES_MAX = 4          # a few scenes at most (each entry holds its media alive)


def held_media() -> list:
    """The media that :func:`media_table`'s tables hold alive (ordered by ``id``). A
    ``dr.freeze`` recording must take them as inputs (``rendering.frozen``): a medium call
    traced over registered media of which none is an input fails to record ("a virtual
    function call ... no such object instance was found in the function's inputs"), as
    volpath's did after a smoke scene had rendered with V4."""
    seen = {}
    for _, table in _TABLES.values():
        for m in table.media:
            seen[id(m)] = m
    return [seen[k] for k in sorted(seen)]


def release_tables() -> None:
    """Drop every majorant table, and with them the media only they hold alive (a scene
    rendered again rebuilds its table). ``rendering.frozen`` does this when a recording
    failed with held media about: a medium with its own phase function (an ``hg``) kept
    alive here broke the recording of a volpath render of another scene even as an input
    (its phase call traced over a phase function the recorder did not find)."""
    _TABLES.clear()


def media_table(scene: mi.Scene) -> MediaTable:
    """The scene's :class:`MediaTable`, rebuilt when medium parameters changed."""
    key = id(scene)
    stamp = []
    diff = False
    # the sensors' media too: else a medium only the camera sits in is neither stamped (an
    # edited density keeps the old majorant) nor seen as differentiated (a density gradient of
    # the wrong sign: no null collisions under a tight bound)
    media = [m for shape in scene.shapes() for m in (shape.interior_medium(), shape.exterior_medium())]
    media += [s.get_medium() for s in scene.sensors()]
    traversed = set()
    for m in media:
        # the media by identity: the table holds them alive, so a new scene at a reused
        # address cannot match unless it has these very media (the scene itself is not
        # held: a held scene keeps its Python BSDFs alive, which enlarge every BSDF call)
        stamp.append(id(m))
        if m is None or id(m) in traversed:       # (a fog shared by shapes: once)
            continue
        traversed.add(id(m))
        p = mi.traverse(m)
        with dr.resume_grad():            # sample() runs with AD suspended
            for k in p.keys():
                v = p[k]
                if k.endswith("sigma_t.data") or k == "scale" or k.startswith("sigma_t."):
                    stamp.append((k, *value_stamp(v)))   # (holds an array it stamps)
                diff |= not isinstance(v, (float, int)) and dr.grad_enabled(v)
    stamp.append(("differentiated", diff))
    hit = _TABLES.get(key)
    if hit is not None and hit[0] == stamp:
        return hit[1]
    table = MediaTable(scene, DIFF_MAJORANT_FACTOR if diff else 1.0)
    _TABLES.pop(key, None)
    while len(_TABLES) >= _TABLES_MAX:                  # drop the oldest (insertion order)
        _TABLES.pop(next(iter(_TABLES)))
    _TABLES[key] = (stamp, table)
    return table


# ---------------------------------------------------------------------------------------
#  Next-event estimation from a surface or medium vertex
# ---------------------------------------------------------------------------------------

def _nee(table, scene, sampler, ref: mi.Interaction3f, medium, active, adjoint_scale=None, sdf=None):
    """Sample an emitter from ``ref``; returns ``(ds, Le / pdf, active, shadow ray, dist)``
    (detached). ``sdf``: the scene's SDF hook -- lanes whose shadow ray an SDF blocks are
    deactivated here, so neither the primal nor the replayed ratio tracking runs for them."""
    with dr.suspend_grad():
        ds, em_w = scene.sample_emitter_direction(ref, sampler.next_2d(active), False, active)
    active = active & (ds.pdf != 0)
    if sdf is not None:                       # SDF occluders (feature 'sdf'; draaw_mi.sdf)
        active &= ~sdf.occluded(ref, ds, active)
    ray = ref.spawn_ray(ds.d)
    dist = dr.select(dr.isfinite(ds.dist), ds.dist * (1.0 - mi.math.ShadowEpsilon), dr.inf)
    return ds, em_w, active, ray, dist


def sample(integ, mode: dr.ADMode, scene: mi.Scene, sampler: mi.Sampler, ray: mi.Ray3f, δL, state_in,
           active: mi.Bool, russian_roulette: bool):
    """The body of ``draaw_v3`` / ``draaw_v4``'s ``sample()`` for scenes with media."""
    if mode == dr.ADMode.Forward:
        raise ParameterError(f"{integ.PLUGIN}: forward-mode differentiation is not supported in scenes "
                             "with participating media (use reverse mode, as prbvolpath)")
    table = media_table(scene)
    # SDF objects beside the media (feature 'sdf'): None when the scene has none, so no SDF
    # code enters the kernel. Segments end at the nearer of the mesh and SDF hits.
    feats = integ.features(scene)
    sdf = integ.sdf_hook(scene, feats)
    aovs = integ.camera_aovs(scene, ray, active, feats, sdf) if mode == dr.ADMode.Primal else integ.zero_aovs()
    return _sample(integ, mode, scene, sampler, ray, δL, state_in, active, russian_roulette, table,
                   aovs, sdf)


@dr.syntax
def _sample(integ, mode, scene, sampler, ray, δL, state_in, active, russian_roulette, table, aovs, sdf=None):
    primal = mode == dr.ADMode.Primal
    has_tracked = table.has_tracked
    has_homog = table.has_homogeneous
    ctx = mi.BSDFContext()
    max_depth = integ.max_depth
    # Russian roulette in media: from depth 5 with survival up to 0.99, as volpath. The
    # surface-tuned draaw_v4 default (depth 2) doubles the variance in dense media, where
    # every path scatters many times with a throughput of albedo^k.
    rr_depth = max(integ.rr_depth, MEDIA_RR_DEPTH)
    rr_min = getattr(integ, "rr_min", 0.05)

    ray = mi.Ray3f(dr.detach(ray))
    ray.d = dr.normalize(ray.d)
    depth = mi.UInt32(0)
    L = mi.Spectrum(0 if primal else state_in)
    δL = mi.Spectrum(δL if δL is not None else 0)
    β = mi.Spectrum(1)
    η = mi.Float(1)
    active = mi.Bool(active)
    valid = mi.Bool(False)
    count_emission = mi.Bool(True)            # camera ray or after a delta bounce: weight 1
    prev_it = dr.zeros(mi.Interaction3f)      # last real scattering vertex (for MIS)
    prev_pdf = mi.Float(1.0)                  # its BSDF / phase pdf of the sampled direction
    medium = dr.zeros(mi.MediumPtr)
    cam_medium = table.camera_medium(pass_sensor.sensor_of(integ))
    if dr.hint(cam_medium is not None, mode="scalar"):      # camera rays start in its medium
        medium = dr.select(active, mi.MediumPtr(cam_medium), medium)
    first = mi.Bool(True)

    while dr.hint(active, label=f"{integ.PLUGIN} media ({mode.name})"):
        si = scene.ray_intersect(ray, mi.RayFlags.All, False, active)
        if dr.hint(sdf is not None, mode="scalar"):
            si = sdf.intersect(ray, si, sampler, active)    # depth test: nearer hit wins
        valid |= active & first & si.is_valid()
        first = mi.Bool(False)
        in_med = active & (medium != None)  # noqa: E711
        scattered = mi.Bool(False)
        t_scatter = mi.Float(dr.inf)
        adj = None if primal else (δL, L)

        # ------------------------- free flight -------------------------
        if dr.hint(has_tracked, mode="scalar"):
            idx = table.index(medium)
            tracked = in_med & ~dr.gather(mi.Bool, table.is_homog, idx, in_med)
            fl = vt.free_flight(table, medium, idx, ray, si.t, sampler, tracked, adj)
            scattered |= tracked & fl.collided
            t_scatter[tracked & fl.collided] = fl.t
            β[tracked] *= fl.weight
        if dr.hint(has_homog, mode="scalar"):
            homog = mi.Bool(in_med)
            if dr.hint(has_tracked, mode="scalar"):
                homog &= dr.gather(mi.Bool, table.is_homog, table.index(medium), in_med)
            mei0 = medium_interaction(ray, mi.Float(0.0), medium)
            s_s0, s_t0 = coefficients(medium, mei0, homog)
            u = sampler.next_1d(homog)
            t_h = dr.select(s_t0 > 0, -dr.log(1.0 - u) / dr.select(s_t0 > 0, s_t0, 1.0), dr.inf)
            ok, mint, maxt = medium.intersect_aabb(ray)
            t_end = dr.minimum(si.t, maxt)
            hit_h = homog & (t_h < t_end)
            scattered |= hit_h
            t_scatter[hit_h] = t_h
            wh = dr.select(s_t0 > 0, s_s0 / dr.select(s_t0 > 0, s_t0, 1.0), 0.0)
            β[hit_h] *= wh
            if dr.hint(not primal, mode="scalar"):
                with dr.resume_grad():
                    s_s, s_t = coefficients(medium, mei0, homog)
                    tt = dr.select(hit_h, t_h, t_end)
                    f = dr.select(hit_h, s_s, mi.Spectrum(1.0)) * dr.exp(-s_t * tt)
                    fd = dr.detach(f)
                    okf = homog & (fd > 0)
                    _bw(δL * L * dr.select(okf, f / dr.select(okf, fd, 1.0), 0.0))

        # ------------------------ medium vertex ------------------------
        scattered &= active
        depth[scattered] += 1
        med_active = scattered & (depth < max_depth)
        active &= ~scattered | med_active
        mei = medium_interaction(ray, t_scatter, medium)
        phase = mei.medium.phase_function()
        phase[~med_active] = dr.zeros(mi.PhaseFunctionPtr)
        phase_ctx = mi.PhaseFunctionContext(sampler)
        if dr.hint(not primal, mode="scalar"):
            nee_sampler = sampler.clone()
        ds, em_w, act_e, sray, sdist = _nee(table, scene, sampler, mei, medium, med_active, sdf=sdf)
        Tm = vt.transmittance(table, scene, sray, sdist, medium, sampler, act_e)
        with dr.resume_grad(when=not primal):
            ph_val, ph_pdf_e = phase.eval_pdf(phase_ctx, mei, ds.d, act_e)
            w_e = dr.select(ds.delta, 1.0, mis_weight(ds.pdf, dr.detach(ph_pdf_e)))
            ph_val = ph_val * w_e
            contrib = β * ph_val * em_w * Tm
            if dr.hint(not primal, mode="scalar"):
                em_val = scene.eval_emitter_direction(mei, ds, act_e)
                contrib = β * ph_val * dr.select(act_e, em_val / dr.detach(dr.select(act_e, ds.pdf, 1.0)), 0.0) * Tm
            contrib = dr.select(act_e & (Tm > 0), contrib, 0.0)
            if dr.hint(not primal, mode="scalar"):
                _bw(δL * contrib)
        L = (L + dr.detach(contrib)) if primal else (L - dr.detach(contrib))
        if dr.hint(not primal, mode="scalar"):
            _nee(table, scene, nee_sampler, mei, medium, med_active)   # replays draws only
            vt.transmittance(table, scene, sray, sdist, medium, nee_sampler, act_e, (δL, dr.detach(contrib)))
        with dr.suspend_grad():
            wo, ph_w, ph_pdf = phase.sample(phase_ctx, mei, sampler.next_1d(med_active),
                                            sampler.next_2d(med_active), med_active)
        med_active &= ph_pdf > 0
        if dr.hint(not primal, mode="scalar"):
            with dr.resume_grad():
                ph_eval = phase.eval_pdf(phase_ctx, mei, wo, med_active)[0]
                ph_d = dr.detach(ph_eval)
                okp = med_active & (ph_d > 0)
                _bw(δL * L * mi.Spectrum(dr.select(okp, ph_eval / dr.select(okp, ph_d, 1.0), 0.0)))
        β[med_active] *= ph_w
        ray[med_active] = mei.spawn_ray(wo)
        count_emission &= ~med_active
        prev_it[med_active] = dr.detach(mei)
        prev_pdf[med_active] = ph_pdf

        # ------------------------ surface vertex -----------------------
        at_surf = active & ~scattered
        bsdf = si.bsdf(ray)
        null = at_surf & si.is_valid() & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Null)
        if dr.hint(table.partly_null, mode="scalar"):
            null &= ~vt.scatters(bsdf.flags())    # a mask is a surface: its sample may pass it
        real = at_surf & ~null
        # emission (camera rays, after delta bounces); escaped rays see the environment
        with dr.resume_grad(when=not primal):
            emitter = si.emitter(scene)
            em_hit = real & (emitter != None)  # noqa: E711
            if dr.hint(integ.hide_emitters, mode="scalar"):
                em_hit &= depth > 0
            ds_hit = mi.DirectionSample3f(scene, si, prev_it)
            pdf_hit = scene.pdf_emitter_direction(prev_it, ds_hit, em_hit & ~count_emission)
            w_hit = dr.select(count_emission, 1.0, mis_weight(prev_pdf, pdf_hit))
            Le = β * w_hit * emitter.eval(si, em_hit)
            Le = dr.select(em_hit, Le, 0.0)
            if dr.hint(not primal, mode="scalar"):
                _bw(δL * Le)
        L = (L + dr.detach(Le)) if primal else (L - dr.detach(Le))
        real &= si.is_valid()
        surf = real & (depth + 1 < max_depth)
        # NEE from the surface
        if dr.hint(not primal, mode="scalar"):
            nee_sampler2 = sampler.clone()
        act_s = surf & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        ds2, em_w2, act_s, sray2, sdist2 = _nee(table, scene, sampler, si, medium, act_s, sdf=sdf)
        med2 = dr.select(si.is_medium_transition(), si.target_medium(ds2.d), medium)
        T2 = vt.transmittance(table, scene, sray2, sdist2, med2, sampler, act_s)
        with dr.resume_grad(when=not primal):
            f_em, pdf_b = bsdf.eval_pdf(ctx, si, si.to_local(ds2.d), act_s)
            f_em = f_em * dr.select(ds2.delta, 1.0, mis_weight(ds2.pdf, dr.detach(pdf_b)))
            if dr.hint(not primal, mode="scalar"):
                em_val2 = scene.eval_emitter_direction(si, ds2, act_s)
                em_w2 = dr.select(act_s, em_val2 / dr.detach(dr.select(act_s, ds2.pdf, 1.0)), 0.0)
            contrib2 = dr.select(act_s & (T2 > 0), β * f_em * em_w2 * T2, 0.0)
            if dr.hint(not primal, mode="scalar"):
                _bw(δL * contrib2)
        L = (L + dr.detach(contrib2)) if primal else (L - dr.detach(contrib2))
        if dr.hint(not primal, mode="scalar"):
            _nee(table, scene, nee_sampler2, si, medium, surf & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth))
            vt.transmittance(table, scene, sray2, sdist2, med2, nee_sampler2, act_s, (δL, dr.detach(contrib2)))
        # BSDF sampling (null surfaces: pass straight through, no bounce counted)
        with dr.suspend_grad():
            bs, bsdf_w = bsdf.sample(ctx, si, sampler.next_1d(surf), sampler.next_2d(surf), surf)
        surf &= bs.pdf > 0
        if dr.hint(not primal, mode="scalar"):
            with dr.resume_grad():
                f = bsdf.eval(ctx, si, bs.wo, surf)
                fd = dr.detach(f)
                okb = surf & (dr.max(fd) > 0)
                _bw(δL * L * dr.select(okb, f / dr.select(fd != 0, fd, 1.0), 0.0))
        β[surf] *= bsdf_w
        η[surf] *= bs.eta
        wo_world = si.to_world(bs.wo)
        delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        bounce = mi.Bool(surf)
        if dr.hint(table.partly_null, mode="scalar"):
            # a mask's sample that passes it (1 - opacity) is no vertex: the MIS state of the
            # last real one stays, as its shadow rays pass masks with weight 1 - opacity
            bounce &= ~mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        count_emission = dr.select(bounce, delta, count_emission)
        prev_it[bounce] = dr.detach(si)
        prev_pdf[bounce] = bs.pdf
        ray[surf] = si.spawn_ray(wo_world)
        ray[null] = si.spawn_ray(ray.d)
        trans = (surf | null) & si.is_medium_transition()
        medium[trans] = si.target_medium(dr.select(null, ray.d, wo_world))
        depth[bounce] += 1
        active &= med_active | surf | null

        # ------------------------ Russian roulette ---------------------
        if dr.hint(russian_roulette, mode="scalar"):
            β_max = dr.max(β)
            rr_on = active & (depth >= rr_depth)
            q = dr.clip(β_max * dr.square(η), rr_min, 0.99)
            β[rr_on] *= dr.rcp(q)
            active &= ~rr_on | (sampler.next_1d(rr_on) < q)
        active &= dr.max(β) > 0
        active &= depth < max_depth
    return (L if primal else δL), valid | mi.Bool(scene.environment() is not None), aovs, L
