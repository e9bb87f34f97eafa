"""Guided paths: where light arrives indirectly, sample the directions it comes from.

Why: in a room lit through a doorway, or on a floor lit only by a lamp's reflection in a
glossy panel, almost every BSDF-sampled path misses what lights the surface; next-event
estimation cannot help either (the lamp is hidden). Path guiding (Müller et al. 2017,
"Practical Path Guiding"; OpenPGL) learns the incident radiance while rendering and samples
it. Here the learned structure is a fixed spatial grid over where the training paths' vertices
lie (their 1st to 99th percentiles per axis, not the scene's bounds) whose cells each
hold a directional histogram over the sphere (:data:`BINS_Z` x :data:`BINS_PHI` equal-area
bins: uniform in ``cos theta`` and ``phi``), in Dr.Jit arrays -- bounded memory
(at most 16^3 cells (:data:`MAX_GRID`) x 128 bins x 2 floats: 4 MiB; while it is learned, 32
bytes per recorded vertex of a batch of :data:`CHUNK_PATHS` paths, 12 MiB at 6 vertices,
and 29 bytes per light-path hit, 5.4 MiB a batch, whatever the image's size).

Learning (:func:`learn_guide`, once per scene, cached by ``draaw_v4``): a pass of at most
:data:`TRAIN_PATHS` camera paths (where adaptive sampling's pilot decides and has them all, the
pilot's own: :class:`~.guide_cache.PilotDecision`) records, at each vertex whose BSDF has no delta lobe, the
cell, the direction sampled and the radiance that came back along it, ``(L_end - L_k) /
beta_k``; each record adds ``luminance / pdf`` (an estimate of the incident radiance's
integral over its bin) to its cell's bin. Few of those records carry light where it arrives
only by a path the BSDF rarely samples, so :data:`LIGHT_PER_CAMERA` light paths per camera
path are traced from the emitters as well (:func:`_light_trace`, as guiding from photons:
Jensen 1995, Vorba et al. 2014): each surface hit after the first (the first is direct
light, which next-event estimation samples) adds its power to the bin it arrived from, in a
histogram of its own. Both are normalised per cell and averaged (:func:`_combined`): on the
glossy panel at 128^2 this took ``path``'s MSE ratio from 0.45 to 0.29 for 0.02 s more
training (``benchmarks/results/speed_suite.md``). Cells are smoothed with their neighbours,
and each cell's distribution keeps :data:`UNIFORM_SHARE` spread uniformly. (A second pass guided by
the first pass's histogram, as Müller et al. iterate, learned no better a guide for the same
number of paths -- glossy panel, 128^2 / 256^2: 0.440 / 0.336 of ``path``'s MSE with two
passes, 0.447 / 0.333 with one -- and took 20-35 % longer: one more loop trace and kernel.)

Sampling (``draaw_v4``'s loop, primal renders only): at a vertex without delta lobes, the
next direction comes from the guide with probability :data:`GUIDE_PROB`, else from the BSDF;
the weight is ``f cos / (a p_guide + (1 - a) p_bsdf)`` (one-sample MIS over the mixture)
for either choice, and the same mixture density enters the MIS weights against next-event
estimation, so the estimate stays unbiased whatever the guide learned. ``a = 0.75`` with a
uniform share of 0.1 took the glossy panel to 0.29 / 0.44x ``path``'s time to its error at
256^2 / 128^2, against 0.38 / 0.48 with ``a = 0.5`` and 0.2 (``benchmarks/guiding_sweep.py``,
16 / 24 renders); a BSDF-sampled direction the guide missed then weighs at most 4x what it
would unguided. Gradient passes (path replay) sample the BSDF alone and replay exactly that.

When (``guiding = "auto"``, once per scene; :mod:`~draaw_mi.integrators.guide_cache`): the share of the image's light that arrives
after the first bounce decides; guiding is on from :data:`SHARE_MIN` up. Adaptive sampling's
pilot measures it at no extra pass in renders of at least 64 spp and 2^20 samples (its
spp/16 samples gather the first vertex's light in one more per-pixel sum; the main pass is
then guided); other renders of at least 64 spp and 2^21 samples run :func:`indirect_share`,
a pilot of :data:`DECIDE_PATHS` camera paths (18-43 ms on the speed suite's scenes: 5-8 %
of a 64-spp render at 128^2, 2.5-4 % at 2^21 samples, which is why the piloted decision comes
first). The share is 1.0 behind the glossy panel; 0.67 in the thesis scene, where guiding
doubled the error at 256^2, its light being point-light glints on a near-mirror floor; 0.42
in the room lit through a doorway, 0.22-0.35 in the Cornell box and the open scenes of the
speed suite. The training pass takes at most the render's samples / :data:`TRAIN_SHARE`
paths (and at least :data:`MIN_TRAIN_PATHS`).
"""
from __future__ import annotations

import contextlib
import math

import drjit as dr
import mitsuba as mi
import numpy as np

BINS_Z, BINS_PHI = 8, 16            # directional bins per cell (equal solid angle)
BINS = BINS_Z * BINS_PHI
MAX_GRID = 16                       # cells per axis at most
RECORDS_PER_CELL = 400              # the grid is as fine as the records allow
TRAIN_PATHS = 3 << 17               # camera paths of the training pass, at most
CHUNK_PATHS = 1 << 16               # traced at a time (records: 12 MiB at 6 vertices)
DECIDE_PATHS = 1 << 13              # camera paths of the pilot that decides ("auto")
GUIDE_SEED = 0x6D1DE
GUIDE_PROB = 0.75                   # share of directions drawn from the guide (weights <= 4x the BSDF's)
UNIFORM_SHARE = 0.1                 # of each cell's distribution, spread over all bins
SHARE_MIN = 0.8                     # indirect share from which "auto" guides
MAX_RECORD_DEPTH = 16               # vertices recorded per path at most
AUTO_MIN_SPP = 64                   # "auto" looks for a guide from this many spp ...
AUTO_MIN_SAMPLES = 1 << 21          # ... and this many samples in the render
PILOTED_MIN_SAMPLES = 1 << 20       # ... or this many, where adaptive sampling's pilot decides
TRAIN_SHARE = 32                    # training paths: at most the render's samples / this ...
MIN_TRAIN_PATHS = 3 << 13           # ... but at least this many
LIGHT_HITS = 4                      # light paths: surface hits traced (recorded from the 2nd)
LIGHT_PER_CAMERA = 0.5              # light paths per camera path of the training pass


def _opaque_grid(lo, scale):
    """A grid's corner and cells per unit as opaque Dr.Jit values (one kernel for all grids)."""
    lo, scale = np.asarray(lo, np.float64).ravel(), np.asarray(scale, np.float64).ravel()
    return (mi.Point3f(*(dr.opaque(mi.Float, float(v)) for v in lo)),
            mi.Vector3f(*(dr.opaque(mi.Float, float(v)) for v in scale)))


class Guide:
    """A learned spatial-directional distribution (see the module docstring).

    A plain class: ``dr.syntax`` loops read the integrator, and Dr.Jit would take the arrays
    of a dataclass or tuple attribute as loop state. The grid's corner, scale and size are
    opaque Dr.Jit values, not literals: each learned guide has its own, and as literals each
    compiled its guided render anew (0.1-0.2 s: a first guided render of the glossy panel at
    128^2 took 2.1x ``path``'s time instead of 1.1x).
    """
    __slots__ = ("lo", "scale", "res", "_res", "prob", "cdf")

    def __init__(self, lo, scale, res: int, prob: np.ndarray):
        self.lo, self.scale = _opaque_grid(lo, scale)
        self.res, self._res = int(res), dr.opaque(mi.Int32, int(res))
        self.prob = mi.Float(prob.ravel().astype(np.float32))
        cdf = np.cumsum(prob.reshape(-1, BINS), axis=1)
        self.cdf = mi.Float(cdf.ravel().astype(np.float32))

    def cell(self, p: mi.Point3f) -> mi.UInt32:
        return cell_of(p, self.lo, self.scale, self._res)

    def pdf(self, p: mi.Point3f, d: mi.Vector3f, active: mi.Bool) -> mi.Float:
        """Solid-angle density of direction ``d`` (world) at ``p``."""
        key = self.cell(p) * BINS + bin_of(d)
        return dr.gather(mi.Float, self.prob, key, active) * (BINS / (4.0 * math.pi))

    def sample(self, p: mi.Point3f, u: mi.Point2f, active: mi.Bool):
        """``(direction, pdf)``: a bin by the cell's cumulative table, a direction uniform in it."""
        base = self.cell(p) * BINS
        b = dr.binary_search(0, BINS - 1, lambda i: dr.gather(mi.Float, self.cdf, base + i, active) <= u.x)
        hi = dr.gather(mi.Float, self.cdf, base + b, active)
        pb = dr.gather(mi.Float, self.prob, base + b, active)
        t = dr.clip((u.x - (hi - pb)) * dr.select(pb > 0, dr.rcp(pb), 0.0), 0.0, 1.0)
        bz = b // BINS_PHI
        z = -1.0 + 2.0 * (mi.Float(bz) + t) / BINS_Z
        phi = 2.0 * math.pi * (mi.Float(b - bz * BINS_PHI) + u.y) / BINS_PHI
        r = dr.safe_sqrt(1.0 - z * z)
        d = mi.Vector3f(r * dr.cos(phi), r * dr.sin(phi), z)
        return d, pb * (BINS / (4.0 * math.pi))


def cell_of(p: mi.Point3f, lo, scale, res) -> mi.UInt32:
    """Grid cell of point ``p`` (clamped to the grid) for a grid of ``res``^3 cells from
    ``lo`` with ``scale`` cells per unit (``res``: an int, or an opaque ``mi.Int32``)."""
    g = (p - lo) * scale
    i = [dr.clip(mi.Int32(dr.floor(c)), 0, res - 1) for c in (g.x, g.y, g.z)]
    return mi.UInt32((i[2] * res + i[1]) * res + i[0])


def bin_of(d: mi.Vector3f) -> mi.UInt32:
    """Equal-area bin of unit direction ``d``: ``cos theta = d.z`` and ``phi`` uniform."""
    bz = dr.clip(mi.Int32(dr.floor((d.z + 1.0) * (0.5 * BINS_Z))), 0, BINS_Z - 1)
    phi = dr.atan2(d.y, d.x)
    phi = dr.select(phi < 0, phi + 2.0 * math.pi, phi)
    bp = dr.clip(mi.Int32(dr.floor(phi * (BINS_PHI / (2.0 * math.pi)))), 0, BINS_PHI - 1)
    return mi.UInt32(bz * BINS_PHI + bp)


class Records:
    """Per-vertex records of a training pass (filled by ``draaw_v4``'s loop while
    :func:`recording`): the vertex's point and sampled direction, the path's radiance so far
    ``L`` and ``q = beta * pdf`` (throughput after the vertex times the direction's density;
    0 where nothing was recorded); ``L_end`` the paths' final radiance. 32 bytes a vertex:
    a batch of 2^16 paths of 6 vertices takes 12 MiB. ``stride``: of a wavefront's lanes,
    every ``stride``-th is recorded (adaptive sampling's pilot, :class:`~.guide_cache.PilotDecision`), the
    ``n`` recorded paths in lane order."""
    __slots__ = ("n", "depth", "stride", "p", "d", "L", "q", "L_end")

    def __init__(self, n: int, depth: int, stride: int = 1):
        self.n, self.depth, self.stride = n, depth, int(stride)
        m = n * depth
        self.p = dr.zeros(mi.Point3f, m)
        self.d = dr.zeros(mi.Vector3f, m)
        self.L, self.q = dr.zeros(mi.Float, m), dr.zeros(mi.Float, m)
        self.L_end = None

    def valid(self) -> mi.Bool:
        return self.q > 0

    def _kept(self, lane: mi.UInt32):
        """``(index of the recorded path, whether the lane is recorded)``."""
        if self.stride == 1:
            return lane, mi.Bool(True)
        return lane // self.stride, (lane % self.stride) == 0

    def put(self, lane: mi.UInt32, depth: mi.UInt32, p, d, L, beta, pdf, active) -> None:
        path, kept = self._kept(lane)
        active = active & kept & (path < self.n) & (depth < self.depth)
        idx = path * self.depth + depth
        for arr, v in ((self.p, p), (self.d, d), (self.L, L), (self.q, beta * pdf)):
            dr.scatter(arr, v, idx, active)

    def finish(self, L: mi.Spectrum) -> None:
        """Keep the recorded lanes' final radiance (luminance) from the wavefront's ``L``."""
        value = (L.x + L.y + L.z) / 3.0
        if self.stride == 1 and dr.width(value) == self.n:
            self.L_end = value
            return
        path, kept = self._kept(dr.arange(mi.UInt32, dr.width(value)))
        self.L_end = dr.zeros(mi.Float, self.n)
        dr.scatter(self.L_end, value, path, kept & (path < self.n))

    def arrays(self) -> tuple:
        """What to evaluate with the pass that records."""
        return self.p, self.d, self.L, self.q, self.L_end


@contextlib.contextmanager
def recording(integrator, records: Records):
    """Within this block ``integrator`` (``draaw_v4``) writes :class:`Records` and samples the
    BSDF alone."""
    integrator._guide_records, integrator._guide = records, None
    try:
        yield
    finally:
        integrator._guide_records, integrator._guide = None, None


def _record_depth(integrator) -> int:
    """Vertices recorded per path: the integrator's ``max_depth``, at most :data:`MAX_RECORD_DEPTH`."""
    depth = integrator.max_depth if integrator.max_depth <= MAX_RECORD_DEPTH else MAX_RECORD_DEPTH
    return max(int(depth), 1)


def _trace(integrator, scene: mi.Scene, paths: int, seed: int) -> Records:
    sensor = scene.sensors()[0]
    rec = Records(paths, _record_depth(integrator))
    with dr.suspend_grad():
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, paths)
        ray, w = sensor.sample_ray_differential(time=sensor.shutter_open(), sample1=0.5,
                                                sample2=sampler.next_2d(), sample3=mi.Point2f(0.5))
        with recording(integrator, rec):
            L, _, _, _ = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=sampler,
                                           ray=ray, depth=mi.UInt32(0), δL=None, δaovs=None,
                                           state_in=None, active=mi.Bool(True))
        rec.finish(L)
        dr.eval(rec.arrays())
    return rec


def _incident(rec: Records):
    """Per record: ``(valid, luminance of the incident radiance / pdf)``, as numpy arrays."""
    lane = dr.arange(mi.UInt32, rec.n * rec.depth) // rec.depth
    L_end = dr.gather(mi.Float, rec.L_end, lane)
    valid = rec.valid()
    val = dr.select(valid, dr.maximum(L_end - rec.L, 0.0) / rec.q, 0.0)
    return valid, dr.select(dr.isfinite(val), val, 0.0)


def share_after(total: float, after: float) -> float:
    """The indirect share ``after / total``; 0 for a black (or non-finite) image."""
    return after / total if total > 0 and math.isfinite(total) else 0.0


def indirect_share(integrator, scene: mi.Scene, paths: int = DECIDE_PATHS) -> float:
    """Share of the light of ``paths`` camera paths that arrives after their first vertex
    (:func:`share_after`)."""
    rec = _trace(integrator, scene, paths, GUIDE_SEED ^ 0xD)
    first = dr.arange(mi.UInt32, rec.n) * rec.depth
    L0 = dr.select(dr.gather(mi.Float, rec.q, first) > 0, dr.gather(mi.Float, rec.L, first), rec.L_end)
    total = float(dr.sum(rec.L_end)[0]) if dr.width(rec.L_end) else 0.0
    return share_after(total, float(dr.sum(rec.L_end - L0)[0]))


def _binned(p: mi.Point3f, d: mi.Vector3f, value: mi.Float, active: mi.Bool, lo: np.ndarray,
            scale: np.ndarray, res: int) -> np.ndarray:
    """``value`` summed per grid cell of ``p`` and bin of direction ``d`` where ``active``
    (and positive): a (res, res, res, BINS) numpy histogram."""
    key = cell_of(p, *_opaque_grid(lo, scale), dr.opaque(mi.Int32, int(res))) * BINS + bin_of(d)
    hist = dr.zeros(mi.Float, res ** 3 * BINS)
    dr.scatter_reduce(dr.ReduceOp.Add, hist, value, key, active & (value > 0))
    return np.array(hist, dtype=np.float64).reshape(res, res, res, BINS)


def _histogram(rec: Records, lo: np.ndarray, scale: np.ndarray, res: int) -> np.ndarray:
    """The camera records' estimates of incident radiance per cell and bin (a record outside
    the grid counts in its nearest cell)."""
    valid, val = _incident(rec)
    return _binned(rec.p, rec.d, val, valid, lo, scale, res)


def _distribution(hist: np.ndarray) -> np.ndarray:
    """Per cell: smoothed with its 26 neighbours (half weight), normalised, a uniform share."""
    res = hist.shape[0]
    pad = np.pad(hist, ((1, 1), (1, 1), (1, 1), (0, 0)))
    near = sum(pad[1 + i:1 + i + res, 1 + j:1 + j + res, 1 + k:1 + k + res]
               for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1))
    h = hist + 0.5 * (near - hist) / 26.0
    tot = h.sum(-1, keepdims=True)
    p = np.where(tot > 0, (1.0 - UNIFORM_SHARE) * h / np.where(tot > 0, tot, 1.0) + UNIFORM_SHARE / BINS,
                 1.0 / BINS)
    return p


def _light_trace(scene: mi.Scene, paths: int, seed: int):
    """``(p, d, power, valid)`` of ``paths`` light paths' surface hits after their first
    (the first is direct light, next-event estimation's), at most :data:`LIGHT_HITS` - 1 per
    path, where the BSDF has no delta lobe: the point, the direction the light arrived from,
    its power (luminance). BSDFs sampled in importance transport, delta lobes passed through."""
    m = paths * (LIGHT_HITS - 1)
    p, d = dr.zeros(mi.Point3f, m), dr.zeros(mi.Vector3f, m)
    power, valid = dr.zeros(mi.Float, m), dr.zeros(mi.Bool, m)
    if not scene.emitters():
        return p, d, power, valid
    lane = dr.arange(mi.UInt32, paths) * (LIGHT_HITS - 1)
    with dr.suspend_grad():
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, paths)
        ray, w, _ = scene.sample_emitter_ray(0.0, sampler.next_1d(), sampler.next_2d(), sampler.next_2d(), True)
        active = dr.all(dr.isfinite(w)) & (dr.max(w) > 0)
        ctx = mi.BSDFContext(mi.TransportMode.Importance)

        def hit(ray, w, active, k, sampler):
            """One surface hit: recorded from the second on, then the BSDF sampled."""
            si = scene.ray_intersect(ray, active)
            active &= si.is_valid()
            bsdf = si.bsdf(ray)
            keep = active & (k >= 1) & ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)
            idx = lane + k - 1
            for arr, v in ((p, si.p), (d, -ray.d), (power, (w.x + w.y + w.z) / 3.0), (valid, keep)):
                dr.scatter(arr, v, idx, keep)
            bs, bw = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), active & (k + 1 < LIGHT_HITS))
            w = w * bw
            active &= (k + 1 < LIGHT_HITS) & (bs.pdf > 0) & dr.all(dr.isfinite(w)) & (dr.max(w) > 0)
            return si.spawn_ray(si.to_world(bs.wo)), w, active, k + 1, sampler

        # one symbolic loop: the BSDFs' (Python) code is traced once, not once per hit
        dr.while_loop((ray, w, active, mi.UInt32(0), sampler), lambda ray, w, active, k, s: active, hit,
                      labels=("ray", "w", "active", "k", "sampler"), label="guiding light paths")
        dr.eval(p, d, power, valid)
    return p, d, power, valid


def _inside(p: mi.Point3f, lo: np.ndarray, scale: np.ndarray, res: int) -> mi.Bool:
    lo_, scale_ = _opaque_grid(lo, scale)
    g = (p - lo_) * scale_
    return dr.all((g >= 0) & (g < dr.opaque(mi.Float, float(res))))


def _light_histogram(rec, lo: np.ndarray, scale: np.ndarray, res: int) -> np.ndarray:
    """Per cell and bin: the power of the light paths' hits in the cell arriving from the bin
    (hits outside the grid dropped)."""
    p, d, power, valid = rec
    return _binned(p, d, power, valid & _inside(p, lo, scale, res), lo, scale, res)


def _combined(camera: np.ndarray, light: np.ndarray) -> np.ndarray:
    """The two histograms normalised per cell and averaged where both saw light, else the
    one that did."""
    def normalised(h):
        tot = h.sum(-1, keepdims=True)
        return np.where(tot > 0, h / np.where(tot > 0, tot, 1.0), 0.0)
    a, b = normalised(camera), normalised(light)
    both = (a.sum(-1, keepdims=True) > 0) & (b.sum(-1, keepdims=True) > 0)
    return np.where(both, 0.5 * (a + b), a + b)


def _chunks(paths: int) -> list[int]:
    """``paths`` as batches of at most :data:`CHUNK_PATHS`."""
    n = -(-paths // CHUNK_PATHS)
    return [paths // n + (k < paths % n) for k in range(n)]


def learn_guide(integrator, scene: mi.Scene, paths: int = TRAIN_PATHS,
                first: Records | None = None) -> Guide | None:
    """The guide learned from one pass of ``paths`` camera paths, traced in batches of at
    most :data:`CHUNK_PATHS` paths so that the records stay small; ``None`` when they saw no
    indirect light. ``first``: paths already recorded (adaptive sampling's pilot's,
    :class:`~.guide_cache.PilotDecision`), the first batch; only the rest of ``paths`` is traced."""
    if first is None:
        sizes = _chunks(max(int(paths), 1))
        first = _trace(integrator, scene, sizes[0], GUIDE_SEED)
    else:
        sizes = [first.n] + (_chunks(int(paths) - first.n) if paths > first.n else [])
    valid = np.array(first.valid())
    n_valid = int(np.count_nonzero(valid))
    if n_valid < 64:
        return None
    # the grid spans where the paths' vertices are (1st-99th percentile), not the scene's
    # bounds: a large floor or a far lamp would leave most cells empty
    pts = np.array(first.p, dtype=np.float64).T[valid]
    sub = pts[::max(1, len(pts) // 16384)]             # (quantiles of 2^14 points: enough)
    lo, hi = np.percentile(sub, 1, axis=0), np.percentile(sub, 99, axis=0)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return None
    ext = np.maximum(hi - lo, 1e-3 * max(float(np.max(hi - lo)), 1e-3))
    lo, hi = lo - 1e-3 * ext, hi + 1e-3 * ext
    lsizes = _chunks(max(int(paths * LIGHT_PER_CAMERA), 1))
    lfirst = _light_trace(scene, lsizes[0], GUIDE_SEED ^ 0x5A17)
    n_light = int(np.count_nonzero(np.array(lfirst[3] & _inside(lfirst[0], lo, 1.0 / (hi - lo), 1))))
    expected = n_valid * sum(sizes) / sizes[0] + n_light * sum(lsizes) / lsizes[0]
    res = int(np.clip(round((expected / RECORDS_PER_CELL) ** (1 / 3)), 2, MAX_GRID))
    scale = res / (hi - lo)
    hist = _histogram(first, lo, scale, res)
    del first, pts, valid
    for k, n in enumerate(sizes[1:], 1):
        hist += _histogram(_trace(integrator, scene, n, GUIDE_SEED + 7919 * k), lo, scale, res)
    light = _light_histogram(lfirst, lo, scale, res)
    del lfirst
    for k, n in enumerate(lsizes[1:], 1):
        light += _light_histogram(_light_trace(scene, n, (GUIDE_SEED ^ 0x5A17) + 7919 * k), lo, scale, res)
    dr.flush_malloc_cache()           # the records' memory
    hist = _combined(hist, light)
    if not hist.any():
        return None
    return Guide(lo, scale, res, _distribution(hist))


def mix_sample(guide: Guide, bsdf, ctx, si, bs, bsdf_w, sampler, guidable):
    """The next direction from the one-sample mixture of ``guide`` (probability
    :data:`GUIDE_PROB`) and the BSDF sample ``bs`` already drawn, at the ``guidable`` lanes:
    ``(bs, weight)`` with ``bs.wo`` the direction taken, ``bs.pdf`` the mixture's density
    (what the MIS weights at the next emitter hit use) and ``weight = f cos / pdf``."""
    u = sampler.next_1d()
    u2 = sampler.next_2d()
    use_g = guidable & (u < GUIDE_PROB)
    d_g, pg_g = guide.sample(si.p, u2, use_g)
    wo_g = si.to_local(d_g)
    f_g, pb_g = bsdf.eval_pdf(ctx, si, wo_g, use_g)
    pg_b = guide.pdf(si.p, si.to_world(bs.wo), guidable & ~use_g)
    pb = dr.select(use_g, pb_g, bs.pdf)
    mix = GUIDE_PROB * dr.select(use_g, pg_g, pg_b) + (1.0 - GUIDE_PROB) * pb
    f = dr.select(use_g, f_g, bsdf_w * bs.pdf)
    w = dr.select(mix > 0, f * dr.rcp(mix), 0.0)
    bs.wo = dr.select(use_g, wo_g, bs.wo)
    bs.pdf = dr.select(guidable, mix, bs.pdf)
    return bs, dr.select(guidable, w, bsdf_w)


def mix_pdf(guide: Guide, p, d, pdf_bsdf, guidable):
    """The mixture's density of direction ``d`` (world) at ``p``, where ``guidable``."""
    return dr.select(guidable, GUIDE_PROB * guide.pdf(p, d, guidable) + (1.0 - GUIDE_PROB) * pdf_bsdf,
                     pdf_bsdf)
