"""Path reuse among neighbouring pixels: the light a camera path's first vertex receives after a
bounce, estimated from the paths of the pixels of its 2x2 tile (Bekaert, Sbert and Halton 2002,
"Accelerating path tracing by re-using paths").

A camera path's first vertex ``x1`` (a point seen in pixel ``c``) receives the light reflected
towards it by the surfaces around: ``I_c = int f_c(x2) G(x1, x2) V(x1, x2) Lr(x2) dA(x2)`` over
the surfaces' points ``x2`` (``f_c``: the BSDF at ``x1`` with its cosine, ``G``: the cosine at
``x2`` over the squared distance, ``Lr``: the light ``x2`` reflects; its emission is the direct
light, which the path's own multiple importance sampling estimates). ``path`` estimates it with
one sample, the point its BSDF sample finds, and the path traced on from there. Where ``x2`` is
Lambertian, ``Lr(x2)`` is the same towards every point on the side it was seen from, so the
point and its estimate serve the other pixels of the tile too: each sees it from its own
``x1`` (a shadow ray, its own BSDF value). The four pixels' samples are combined by the balance
heuristic over the four pixels' sampling densities (all in area measure at ``x2``)::

    I_c ~ sum_k f_c(y_k) G_ck V_ck Lr_k / sum_j p_j(y_k)

which is multiple importance sampling with one sample per technique, so unbiased where the
pixel's own technique covers its integrand (its BSDF samples every direction it reflects from)
and each density counted is that of a sample its pixel delivers: a pixel's path stops where its
first vertex reflects nothing (black), so there its density counts for nothing.
A pixel whose first vertex has a delta lobe (glass, a mirror, smooth plastic) takes no part: it
keeps its own sample, as do samples whose ``x2`` has one. Where ``x2``'s BSDF is not
Lambertian (glossy, a normal map the side test cannot see, transmissive) the light it reflects
depends on the direction it is seen from: :mod:`~.reconnection` evaluates that BSDF again
towards each pixel and weighs the samples by the densities of the whole connection (what
:class:`ShareTable` calls :data:`REEVALUATED`). The pixel filter is untouched: each camera
sample's radiance estimate stays unbiased given its ray.

The price: three shadow rays, four BSDF evaluations and a few gathers a sample (and, with
re-evaluated BSDFs, eight more BSDF evaluations and a ray for each path that brought light back
to ``x2``), which pays where most of the light arrives after the first bounce: a room lit
through a doorway, a floor lit by a glossy panel. Measured in
``benchmarks/results/speed_suite.md``.

The four lanes of a tile are the same sample index of four pixels, in the lane order of
Mitsuba's ``sample_rays`` (pixel-major, the samples of a pixel consecutive), which
:class:`Layout` names.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from . import guiding

TILE = 2            # tile side in pixels: 3 extra shadow rays a sample
PASS_LANES = 1 << 19  # lanes a pass, or one sample of every pixel where more (about 140 B a lane;
                      # 2^18 / 2^20: 1.39x / 1.29x the time of a pass without sharing at 256^2, 1.32x here)
SHARE_MIN = 0.15    # ``auto`` shares where guiding's indirect share is at least this
AUTO_MAX_PIXELS = 1 << 20   # ... in images up to this size: a pass keeps a sample of every
                            # pixel (1024^2: 324 MiB peak against path's 176; 2048^2 would add 0.6 GiB)


def large_enough(samples: int) -> bool:
    """Whether ``auto`` considers a render of ``samples`` samples in all: from
    :data:`~.guiding.PILOTED_MIN_SAMPLES` (2^20), at any count per pixel (a time-budgeted
    render's passes of 16 spp at 256^2 share: 0.35x the variance for 1.31x the time), where the
    pilot that measures the scene's indirect share (once per scene, 2^13 paths) costs little;
    previews, fits and small test renders do not pay it or the sharing kernels' compilation."""
    return samples >= guiding.PILOTED_MIN_SAMPLES


def sky_only(scene: mi.Scene) -> bool:
    """Whether only environments light ``scene``: their light after a bounce is smooth, and
    the balance heuristic's sum over four pixels adds more than it takes off (a diffuse floor
    and wall under a constant sky, 16^2 x 64 spp: 1.13x the variance of each pixel's own
    sample with a box filter, 1.55x with a gaussian; a point light over them: 0.43x), so
    ``auto`` leaves such scenes unshared."""
    emitters = scene.emitters()
    return len(emitters) > 0 and all(mi.has_flag(e.flags(), mi.EmitterFlags.Infinite) and
                                     not mi.has_flag(e.flags(), mi.EmitterFlags.Delta) for e in emitters)


def pass_seed(seed, i: int):
    """The seed of a render's ``i``-th pass where its sampler is not stratified across passes
    (the first keeps ``seed``; an int or, as ``mi.render`` takes, a Dr.Jit ``UInt32``). Not
    :func:`draaw_mi.rendering.passes.pass_seed`'s sequence, on purpose: a long render's own
    passes take that one, and with it the second part of its first pass would repeat its second
    pass's seed (the same random numbers for the same lanes).

    >>> pass_seed(7, 0), pass_seed(7, 1) != pass_seed(7, 2)
    (7, True)
    """
    if i == 0:
        return seed
    key = (0x85EBCA6B * i + 0x27D4EB2F) & 0xFFFFFFFF
    return (seed ^ key) & 0xFFFFFFFF if isinstance(seed, int) else seed ^ mi.UInt32(key)


class Layout:
    """The lanes of a primal pass that shares: ``width x height`` pixels (the film's crop),
    ``spp`` consecutive lanes a pixel, and the scene's BSDFs that share (``table``:
    :func:`share_table`)."""
    __slots__ = ("width", "height", "spp", "table")

    def __init__(self, width: int, height: int, spp: int, table: "ShareTable"):
        self.width, self.height, self.spp, self.table = int(width), int(height), int(spp), table

    @property
    def lanes(self) -> int:
        return self.width * self.height * self.spp

    @classmethod
    def of(cls, sensor: mi.Sensor, spp: int, table: "ShareTable") -> "Layout":
        size = sensor.film().crop_size()     # (films that sample their border are refused)
        return cls(size[0], size[1], spp, table)


_LAMBERTIAN = "SmoothDiffuse"          # Mitsuba's ``diffuse``


def is_lambertian(bsdf: mi.BSDF) -> bool:
    """Whether ``bsdf`` reflects the same light towards every direction of a side: Mitsuba's
    ``diffuse``, alone or as both sides of a ``twosided`` (textured or not). By class, not by
    flags: a normal or bump map over a ``diffuse`` has its flags, but the light it reflects
    depends on the direction (zero below the perturbed normal's horizon).

    >>> is_lambertian(mi.load_dict({"type": "twosided", "bsdf": {"type": "diffuse"}}))
    True
    >>> is_lambertian(mi.load_dict({"type": "roughplastic"}))
    False
    """
    name = bsdf.class_name()
    if name == _LAMBERTIAN:
        return True
    if name != "TwoSidedBRDF":
        return False
    nested = [n for n in mi.traverse(bsdf).hierarchy if isinstance(n, mi.BSDF) and n is not bsdf]
    return len(nested) > 0 and all(n.class_name() == _LAMBERTIAN for n in nested)


LAMBERTIAN, REEVALUATED = 1, 2     # codes of a BSDF in a ShareTable (0: not shared)


class ShareTable:
    """Per BSDF of a scene (by registry index, :attr:`codes`), how a second vertex on it shares:
    :data:`LAMBERTIAN` (:func:`is_lambertian`: the light it reflects, the same towards every
    neighbour), :data:`REEVALUATED` (no delta lobe: its BSDF evaluated again towards each
    neighbour, :mod:`~.reconnection`) or 0 (delta lobes: not shared); :attr:`reevaluates`
    whether any BSDF is :data:`REEVALUATED`; :attr:`lambertian_surfaces` whether a shape other
    than a light has a :data:`LAMBERTIAN` one."""
    __slots__ = ("codes", "reevaluates", "lambertian_surfaces", "_ids")

    def __init__(self, codes: dict, lambertian_surfaces: bool):
        table = [0] * (max(codes) + 1)
        for i, c in codes.items():
            table[i] = c
        self.codes = mi.UInt32(table)
        self.reevaluates = REEVALUATED in codes.values()
        self.lambertian_surfaces = bool(lambertian_surfaces)
        self._ids = dict(codes)

    def lambertian_only(self) -> "ShareTable | None":
        """This table without :data:`REEVALUATED` BSDFs (``None`` where no shape but lights
        has a Lambertian one)."""
        if not self.reevaluates:
            return self
        kept = {i: c for i, c in self._ids.items() if c == LAMBERTIAN}
        return ShareTable(kept, True) if kept and self.lambertian_surfaces else None

    def code(self, bsdf: mi.BSDFPtr, active: mi.Bool) -> mi.UInt32:
        """The codes of the BSDFs ``bsdf`` (0 where inactive or absent)."""
        index = dr.reinterpret_array(mi.UInt32, bsdf)
        active = active & (bsdf != None) & (index < dr.width(self.codes))  # noqa: E711
        return dr.gather(mi.UInt32, self.codes, index, active)


def share_code(bsdf: mi.BSDF) -> int:
    """How a second vertex on ``bsdf`` shares (:class:`ShareTable`).

    >>> share_code(mi.load_dict({"type": "diffuse"})), share_code(mi.load_dict({"type": "roughplastic"}))
    (1, 2)
    >>> share_code(mi.load_dict({"type": "dielectric"}))
    0
    """
    if is_lambertian(bsdf):
        return LAMBERTIAN
    return 0 if mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta) else REEVALUATED


def share_table(shapes) -> ShareTable | None:
    """The :class:`ShareTable` of the BSDFs of ``shapes``, or ``None`` where no shape but
    lights has a BSDF that shares: nothing worth sharing (a shape without a BSDF of its own,
    as a light often is, has Mitsuba's default ``diffuse``)."""
    codes, surfaces, lambertian = {}, False, False
    for shape in shapes:
        bsdf = shape.bsdf()
        code = share_code(bsdf) if bsdf is not None else 0
        if code:
            codes[int(dr.reinterpret_array(mi.UInt32, mi.BSDFPtr(bsdf))[0])] = code
            surfaces |= not shape.is_emitter()
            lambertian |= code == LAMBERTIAN and not shape.is_emitter()
    return ShareTable(codes, lambertian) if surfaces else None


def takes_part(bsdf: mi.BSDFPtr, valid: mi.Bool) -> mi.Bool:
    """Whether a first vertex with ``bsdf`` takes part in its tile's estimate: a surface hit
    without delta lobes (its BSDF sampling has a density over the whole sphere)."""
    return valid & ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)


class SecondVertex:
    """What a path keeps of its second vertex ``x2`` for its tile: the point, and its geometric
    and shading normals turned towards the first vertex (the side a neighbour must see it
    from). Filled by :meth:`record` within the path loop."""
    DRJIT_STRUCT = {"p": mi.Point3f, "n": mi.Vector3f, "sh_n": mi.Vector3f}

    def __init__(self, p=None, n=None, sh_n=None):
        self.p = mi.Point3f(0.0) if p is None else p
        self.n = mi.Vector3f(0.0) if n is None else n
        self.sh_n = mi.Vector3f(0.0) if sh_n is None else sh_n

    def record(self, si: mi.SurfaceInteraction3f, d: mi.Vector3f, active: mi.Bool) -> None:
        """``si``: the second vertex, reached along ``d``, where ``active``."""
        self.p = dr.select(active, si.p, self.p)
        self.n = dr.select(active, dr.mulsign(si.n, -dr.dot(si.n, d)), self.n)
        sh_n = si.sh_frame.n
        self.sh_n = dr.select(active, dr.mulsign(sh_n, -dr.dot(sh_n, d)), self.sh_n)


class SharedLight:
    """A path's part in its tile's estimate, as ``draaw_v4``'s loop state: whether its light
    after the second vertex is the tile's (``shared``: its first vertex takes part, its second
    is Lambertian), the throughput from the second vertex on (``β``), the light the second
    vertex reflects (``L``, its emission left out) and the vertex (``x2``)."""
    DRJIT_STRUCT = {"shared": mi.Bool, "β": mi.Spectrum, "L": mi.Spectrum, "x2": SecondVertex}

    def __init__(self, shared=None, β=None, L=None, x2=None):
        self.shared = mi.Bool(False) if shared is None else shared
        self.β = mi.Spectrum(1.0) if β is None else β
        self.L = mi.Spectrum(0.0) if L is None else L
        self.x2 = SecondVertex() if x2 is None else x2
        self._w = None                    # after the loop (weigh): each sample's weight

    def visit(self, table: ShareTable, depth: mi.UInt32, active: mi.Bool, si: mi.SurfaceInteraction3f,
              bsdf: mi.BSDFPtr, d: mi.Vector3f) -> None:
        """At each vertex ``si`` (reached along ``d``): the first says whether it takes part,
        the second whether it shares (``table``) and where it is."""
        self.shared = dr.select(active & (depth == 0), takes_part(bsdf, si.is_valid()), self.shared)
        at_x2 = active & (depth == 1)
        self.shared &= ~at_x2 | (table.code(bsdf, at_x2 & si.is_valid()) != 0)
        self.x2.record(si, d, at_x2)

    def own_part(self, depth: mi.UInt32, Le: mi.Spectrum, Lr: mi.Spectrum, Le_raw, Lr_raw) -> mi.Spectrum:
        """The part of a vertex's light that stays the path's own: all of it before a shared
        path's second vertex, and there the emission it shows (direct light, weighted against
        the first vertex's light sample); the rest (``Le_raw``, ``Lr_raw``: the emission and
        light sample without the path's throughput, ``None`` where the scene has none) goes
        to :attr:`L`."""
        rel = self.shared & (depth >= 1)
        if Le_raw is not None:
            self.L += dr.select(rel & (depth >= 2), self.β * Le_raw, 0.0)
        if Lr_raw is not None:
            self.L += dr.select(rel, self.β * Lr_raw, 0.0)
        return dr.select(rel, dr.select(depth == 1, Le, 0.0), Le + Lr)

    _first_kept = 1       # the depth from which BSDF weights count in β

    def bounce(self, depth: mi.UInt32, weight: mi.Spectrum) -> None:
        """A BSDF sample's weight, counted from the second vertex on."""
        self.β = dr.select(depth >= self._first_kept, self.β * weight, self.β)

    def prepare(self, scene: mi.Scene, layout: "Layout", ray: mi.Ray3f, pi: mi.PreliminaryIntersection3f,
                active: mi.Bool, flags: mi.RayFlags, guide) -> None:
        """After the loop, what :meth:`weigh` and :meth:`contribution` read beyond the loop
        state (nothing here). ``ray``, ``pi``, ``active``: the camera rays, their first intersections, the
        lanes rendered; ``flags``: the loop's ray flags; ``guide``: the paths' guide or ``None``."""

    def weigh(self, density) -> None:
        """Each lane's sample's weight before the BSDF at the first vertex that sees it: the
        balance heuristic over the tile's four densities for its second vertex,
        ``Lr / sum p``. ``density(lanes)``: for lanes ``lanes``, the density of each slot's
        pixel for their second vertices (area measure; 0 where it does not deliver it)."""
        total = sum(density(dr.arange(mi.UInt32, dr.width(self.L))))
        self._w = dr.select(total > 0, self.L / dr.maximum(total, 1e-30), 0.0)
        dr.eval(self._w)

    def contribution(self, member: mi.UInt32, slot: mi.UInt32, f: mi.Spectrum) -> mi.Spectrum:
        """The sample of lane ``member`` (a tile member's) in the estimate of the lanes
        at hand, whose pixels are in slot ``slot`` of the tile, whose BSDF value towards its
        second vertex times the geometry term is ``f`` (after :meth:`weigh`)."""
        return f * dr.gather(mi.Spectrum, self._w, member)


def tile_member(layout: "Layout", lane: mi.UInt32, k) -> tuple:
    """For lanes ``lane`` of a pass: ``(member, inside)``, the lane of the same sample in the
    pixel in slot ``k`` (an int or a ``mi.UInt32``; ``x + 2 y`` in the tile) of the lane's
    tile, or the lane itself where that pixel lies outside the film, and whether it is inside."""
    pixel = lane // layout.spp
    s = lane - pixel * layout.spp
    py = pixel // layout.width
    px = pixel - py * layout.width
    qx, qy = px - px % TILE + k % TILE, py - py % TILE + k // TILE
    inside = (qx < layout.width) & (qy < layout.height)
    return dr.select(inside, (qy * layout.width + qx) * layout.spp + s, lane), inside


def tile_members(layout: "Layout", lane: mi.UInt32) -> tuple:
    """For lanes ``lane`` of a pass: ``(members, inside, slot)``: :func:`tile_member` for
    each slot of the tile, and the lane's own slot."""
    members, inside = zip(*(tile_member(layout, lane, k) for k in range(TILE * TILE)))
    pixel = lane // layout.spp
    py = pixel // layout.width
    px = pixel - py * layout.width
    return list(members), list(inside), px % TILE + TILE * (py % TILE)


def tile_estimate(scene: mi.Scene, layout: "Layout", ray: mi.Ray3f, pi: mi.PreliminaryIntersection3f,
                  flags: mi.RayFlags, active: mi.Bool, shared: mi.Bool, share: SharedLight,
                  guide=None) -> mi.Spectrum:
    """The reflected light at each lane's first vertex from its tile's shared samples (the
    sum over ``k`` in the module docstring). ``ray``, ``pi``: the camera rays and their first
    intersections; ``shared``: whether a lane's own sample is shared (its first vertex takes
    part, its second shares); ``share``: the loop's :class:`SharedLight` (its second vertex,
    and what its :meth:`~SharedLight.contribution` reads); ``guide``: where the paths were
    guided (:mod:`~.guiding`), whose mixture densities count."""
    n = dr.width(shared)
    if n != layout.lanes:
        raise ValueError(f"pixel_reuse.tile_estimate: {n} lanes; expected {layout.lanes} "
                         f"({layout.width}x{layout.height} pixels x {layout.spp} spp)")
    share.prepare(scene, layout, ray, pi, active, flags, guide)
    si = pi.compute_surface_interaction(ray, ray_flags=flags, active=active)
    bsdf = si.bsdf(ray)
    part = active & takes_part(bsdf, si.is_valid())
    ctx = mi.BSDFContext()

    lane = dr.arange(mi.UInt32, n)
    members, inside, slot = tile_members(layout, lane)

    # this lane's BSDF value and density towards each member's x2 (area measure at x2)
    f, p = [], []
    for k, m in enumerate(members):
        own = m == lane
        q = dr.gather(SecondVertex, share.x2, m)
        ok = part & inside[k] & dr.gather(mi.Bool, shared, m)
        v = q.p - si.p
        d2 = dr.squared_norm(v)
        d = v * dr.rsqrt(dr.maximum(d2, 1e-30))
        cos2 = dr.abs(dr.dot(q.n, d))
        # a neighbour sees x2 from the side its own path did, unoccluded (the own path: by
        # construction, and its sample counts here whatever rounding says)
        seen = (d2 > 0) & (dr.dot(q.n, d) < 0) & (dr.dot(q.sh_n, d) < 0)
        ok &= own | (seen & ~scene.ray_test(si.spawn_ray_to(q.p), ok & seen & ~own))
        value, pdf = bsdf.eval_pdf(ctx, si, si.to_local(d), ok)
        if guide is not None:
            pdf = guiding.mix_pdf(guide, si.p, d, pdf, ok)
        g = cos2 / dr.maximum(d2, 1e-30)
        f.append(dr.select(ok, value * g, 0.0))
        # a density counts where this pixel's path would carry the sample on: where its BSDF
        # reflects (a black first vertex, as a light's default BSDF or a black texel, stops
        # its path there, and counting its density would darken the tile)
        p.append(dr.select(ok & (dr.max(value) > 0), pdf * g, 0.0))
    dr.eval(f, p)

    # each sample's weight, once per sample: the balance heuristic over its tile's densities
    # (p[k] at lane j: lane j's for the x2 of the member in slot k)
    slots = TILE * TILE
    p_at = dr.zeros(mi.Float, n * slots)
    for k in range(slots):
        dr.scatter(p_at, p[k], lane * slots + k)

    def density(lanes):
        mem, ins, own = tile_members(layout, lanes)
        return [dr.select(ins[j], dr.gather(mi.Float, p_at, mj * slots + own), 0.0) for j, mj in enumerate(mem)]

    share.weigh(density)
    out = mi.Spectrum(0.0)
    for k, m in enumerate(members):
        out += share.contribution(m, slot, f[k])
    return out
