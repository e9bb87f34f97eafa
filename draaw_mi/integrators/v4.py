"""``draaw_v4`` -- physically based path tracer, optimised (GO-Draaw "V4")."""
from __future__ import annotations

import contextlib

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError
from . import emission_split, guide_cache, guiding, pixel_reuse, reconnection
from .common import mis_weight, with_shared_parameters, parse_bool, parse_float, propagate_adjoint, relative, sample_emitter, separate_adjoints
from .sampling import PowerSelection, only_constant_environment, roulette
from .scene_view import scene_view
from .v4_passes import ADAPTIVE_MIN_SPP, V4Passes

RR_THRESHOLD = 0.25     # throughput below which roulette may stop a path (see sampling.py)
LIGHT_SELECTION = "auto"
__all__ = ["DraawV4Integrator", "ADAPTIVE_MIN_SPP", "RR_THRESHOLD"]


@with_shared_parameters
class DraawV4Integrator(V4Passes):
    r"""
    .. _integrator-draaw_v4:

    draaw V4: optimised physically based path tracer (:monosp:`draaw_v4`)
    ----------------------------------------------------------------------

    .. pluginparameters::

     * - max_depth
       - |int|
       - Longest path depth (-1: unbounded). 1 renders only directly visible emitters, 2 direct
         lighting, and so on (GO-Draaw "depth"). (Default: 6)

     * - rr_depth
       - |int|
       - Path depth (number of segments) from which *Russian roulette* may stop paths: never
         on the first bounce. (Default: 2)

     * - rr_threshold
       - |float|
       - Roulette only stops paths whose throughput ``max(beta) * eta^2`` is below this; they
         survive with probability ``throughput / rr_threshold`` (see
         :mod:`~draaw_mi.integrators.sampling`). (Default: 0.25)

     * - rr_min
       - |float|
       - Smallest survival probability of Russian roulette, in (0, 1]. (Default: 0.05)

     * - light_selection
       - |string|
       - ``auto``: ``power`` where that applies and the emitters are all area lights or all
         point lights, else
         ``learned`` (two or more emitters);
         ``learned``: next-event estimation picks an emitter in proportion to the square root
         of its contribution's second moment, measured by a pilot of camera paths before the
         first render of a scene (:mod:`~draaw_mi.integrators.light_pilot`; a fifth of the
         probability spread uniformly);
         ``power``: in proportion to its power (the mean of its ``sample_ray`` weights: a
         spot's cone and a textured light's texture count) where the scene's emitters differ
         in strength and none is an environment (uniform otherwise);
         ``uniform``: Mitsuba's uniform choice. (Default: ``auto``)

     * - constant_env_nee
       - |bool|
       - Sample a constant environment by next-event estimation when it is the only light;
         by default such scenes use BSDF sampling alone (no shadow rays: cosine / GGX
         sampling already matches a constant sky better than uniform sphere samples).
         (Default: |false|)

     * - emission_split
       - |int|
       - Rays per camera sample that estimate the emission of a light seen directly, in the
         pixels on its edges (1: off; a square: a ``sqrt x sqrt`` stratified grid over the
         pixel; see :mod:`~draaw_mi.integrators.emission_split`). (Default: 16)

     * - adaptive
       - |bool|
       - Unbiased adaptive sampling for primal renders of at least 64 spp (any pixel filter, no
         AOVs, ``max_depth`` > 1, the independent sampler, not stratified: ``stratify``): a pilot pass of spp/16 estimates
         each pixel's variance and path length, the rest of the budget goes where it lowers
         the error most per unit of cost (:mod:`draaw_mi.integrators.adaptive_sampling`). (Default: |true|)

     * - stratify
       - |bool|
       - Where the sensor's sampler is ``independent`` (Mitsuba's default), draw the
         samples of renders and gradient passes from V4's own stratified sampler instead (correlated
         multi-jittered, permuted per pixel and dimension by a hash:
         :mod:`~draaw_mi.integrators.strata_sampler`, :mod:`~draaw_mi.integrators.stratify`);
         these renders are uniform (no adaptive sampling) except a scene's first render whose
         adaptive pilot decides on guiding. Same expectation. (Default: |true|)

     * - guiding
       - |string|
       - Guided paths in primal renders (:mod:`~draaw_mi.integrators.guiding`): ``auto``
         guides renders of at least 64 spp and 2^20 samples (2^21 without adaptive
         sampling) where a pilot (adaptive sampling's, or else one of 2^13 camera paths)
         finds most of the light arriving after the first bounce (once per scene); ``on``
         always; ``off`` never. Guided renders sample every pixel alike. Gradient passes
         sample the BSDF alone. (Default: ``auto``)

     * - pixel_reuse
       - |string|
       - Path reuse in primal renders (:mod:`~draaw_mi.integrators.pixel_reuse`): the light
         a path's first vertex receives after a bounce off a surface without delta lobes is
         shared among the four pixels of a 2x2 tile, each seeing the others' second vertices
         through a shadow ray (their BSDF evaluated again towards it unless Lambertian),
         combined by the balance heuristic (the expectation stays ``path``'s). ``auto``
         shares in renders of 2^20 samples or more (any spp), images up to 2^20 pixels, with
         the independent sampler (V4's stratified one in its place), of scenes with such a
         surface other than a light, not lit by environments alone, where a pilot finds at
         least 15 % of the light arriving after the first bounce (once per scene); ``on``
         wherever sharing can run; ``off`` never. It never runs in adaptive sampling's
         passes, gradient passes, ``dr.freeze`` recordings, or with media, SDF objects or
         ``max_depth`` <= 2 (``draaw-mi info SCENE`` says whether and why).
         (Default: ``auto``)

     * - hide_emitters
       - |bool|
       - Do not show directly visible emitters (area emitters are skipped, the environment
         is transparent), as Mitsuba's ``path``. (Default: |false|)

     * - aovs
       - |string|
       - Comma-separated AOVs: ``depth``, ``depth_log``, ``normal``, ``albedo`` or ``all``
         (channels ``depth.Z``, ``depth_log.Z``, ``N.X/Y/Z``, ``albedo.R/G/B``; see
         ``draaw_mi.integrators.common``). (Default: none)

    The same model and the same expectation as ``draaw_v3`` and Mitsuba's ``path`` (any BSDF
    through the generic interface; the ``draaw`` BSDF samples its own mixture of cosine and
    GGX *visible-normal* sampling), with the variance and speed optimisations of a production
    path tracer:

    - emitter sampling and BSDF sampling combined by multiple importance sampling (power
      heuristic);
    - Russian roulette from ``rr_depth`` on that stops only weak paths (throughput below
      ``rr_threshold``), so bright paths in open scenes and metals are never cut;
    - emitter selection by power in many-light scenes (5 % spread evenly, so a dark light
      still gets the samples its gradient needs);
    - emission splitting: where a light is seen directly, its emission in the pixels on its
      edges comes from 16 stratified extra camera rays (no shading, one intersection each);
    - stratified samples where the scene asks for the independent sampler (V4's own
      correlated multi-jittered sampler: :mod:`~draaw_mi.integrators.stratify`);
    - adaptive sampling (per-pixel spp map from a pilot pass; the estimator stays unbiased),
      under any pixel filter (:mod:`~draaw_mi.integrators.film_splat`), where the samples are
      not stratified;
    - guided paths where light arrives indirectly (a learned grid of directional histograms
      in a one-sample MIS mixture with the BSDF);
    - path reuse among the pixels of 2x2 tiles where light arrives after a bounce
      (Bekaert et al. 2002, with the reconnection shift at glossy vertices; a room lit
      through a doorway: 0.3x the variance for 1.5x the time; a floor lit by a glossy
      panel, guided: 0.25x for 1.9x);
    - a kernel specialised to the scene: each feature of
      :func:`~draaw_mi.integrators.features.detect_features` (area / delta / environment
      emitters, delta BSDFs, textures and normal maps, AOVs) is a Python-level branch, so an
      absent feature adds no code to the JIT kernel (for example, a scene lit only by point
      lights has no MIS and no emitter lookups at surface hits, a scene without textures
      computes no uv / dp/du). BSDF calls trace the BSDFs of every scene alive in the
      process, so another live scene's materials add their code (``del`` unused scenes;
      ``draaw_mi.scene.loading.release_wrapped()`` lets go of the bare ``mi.Scene`` objects
      ``draaw_mi.render`` keeps for replays).

    What is on by default and why (``benchmarks/results/speed_suite.md``, eighteen scenes of
    different kinds, time to reach ``path``'s 64-spp error): the roulette threshold because
    ``path``-style roulette from depth 2 costs up to 1.7x the time in environment-lit scenes
    (stopping bright paths adds variance) while never roulette costs speed in enclosed
    scenes; power selection because it cuts the error of the 24-light scene about 8x at the
    same cost; where it does not apply (emitters of similar power, or an environment among
    them: an environment's power says little about what it gives the visible surfaces, and
    on the thesis scene a power table starves the point light, whose glints carry most of the
    variance; or lights of different kinds: a spot aimed at the objects in view beside an
    area light over the floor, ``spot_and_area``, reads 0.53x ``path``'s time to its error
    with the power table and 0.23x with the learned one) selection learned by a pilot of 2^16
    camera paths (2^18 where delta lights meet near-mirrors; once per scene,
    :mod:`~draaw_mi.integrators.light_pilot`), which takes the thesis glass scene from 0.90x to
    0.59x ``path``'s variance x time at 256x256 and the material spheres (sky and area light)
    to 0.76x of uniform selection's; it loses 10 % to the power table on the 24-light scene,
    hence ``auto``; emission splitting because in a scene that shows its lights most of a
    low-spp image's error sits in the pixels on their edges (87 % of the variance of the
    Cornell box at 128x128, in 0.7 % of its pixels): variance x time against ``path`` at 128x128
    and 4 spp goes from 1.0 to 0.13 on the Cornell box and from 1.0 to 0.015 on the scene with a
    small bright bulb in view, at 0-5 % more kernel time, and nothing changes where no emitting
    surface is in view (``benchmarks/variance_study.py``); adaptive sampling because the error of
    most images is dominated by few pixels (emitter edges, highlights, caustics), and it is
    off for small renders (< 64 spp: the preview and the fit loop, where a pilot pass would be
    too small) and for differentiated renders' adjoint passes, which sample uniformly. Adaptive sampling lowers
    the *absolute* squared error; dark pixels get fewer samples, so a relative error measure
    (relMSE) can rise (``adaptive=False`` turns it off). Each pixel keeps at least half the
    uniform count and no pixel takes more than a capped share, which bounds the loss where a
    small pilot misses rare bright paths. Scenes whose error sits in glints of delta lights on
    near-mirror surfaces (the thesis glass scene) render uniformly: a small pilot misses them
    (:func:`~draaw_mi.integrators.glints.has_glints`). Stratified samples
    (``stratify``) come before adaptive sampling: they take more off the error of most suite
    scenes, and adaptive sampling on top of a stratified pattern measured 1.23-1.44x the
    variance x time of uniform V4 with the same sampler; so V4 renders stratified scenes
    (its own sampler or the scene's ``multijitter``, ``ldsampler``, ...) uniformly, and
    samples adaptively with ``stratify=False`` or where guiding or glints keep the
    independent sampler (:meth:`~draaw_mi.integrators.v4.DraawV4Integrator.stratified`). See
    ``benchmarks/results/speed_suite.md``.

    Differentiable by path replay (``RBIntegrator``: primal, forward and backward modes) with
    respect to BSDF and emitter parameters. Limitations: no geometry / visibility gradients
    (no projective sampling), detached sampling (delta-lobe
    parameters such as a glass IOR get no gradient).

    Deviations from GO-Draaw's V4 (``go-draaw-spec.md`` §3.6-3.7): GO-Draaw's V4 family is its
    V2M shader on a lean BVH with texture slots and view-independent "reflections" along the
    light's mirror direction, albedo gathered as if it were radiance and no pdf divisions.
    draaw_v4 renders the physically based ``draaw`` model (design.md §3) with an unbiased
    estimator; textures and normal maps are ordinary Mitsuba textures on the BSDF; the "Lin"
    / "Log" grades are tone curves of the post chain, and GO-Draaw's "Normals" mode is the
    ``normal`` AOV.

    .. tabs::

        .. code-tab:: python

            'type': 'draaw_v4',
            'max_depth': 8,
            'aovs': 'depth,normal'
    """
    PLUGIN = "draaw_v4"

    def __init__(self, props: mi.Properties):
        if "rr_depth" not in props:
            props["rr_depth"] = 2
        super().__init__(props)
        self.rr_min = parse_float(props, "draaw_v4", "rr_min", 0.05)
        if not (0.0 < self.rr_min <= 1.0):
            raise ParameterError(f"draaw_v4: rr_min={self.rr_min}; expected a value in (0, 1]")
        self.rr_threshold = parse_float(props, "draaw_v4", "rr_threshold", RR_THRESHOLD)
        if not (0.0 < self.rr_threshold < float("inf")):     # (inf: every path rouletted at rr_min)
            raise ParameterError(f"draaw_v4: rr_threshold={self.rr_threshold}; expected a finite value > 0")
        self.adaptive = parse_bool(props, "draaw_v4", "adaptive", True)
        self.stratify = parse_bool(props, "draaw_v4", "stratify", True)
        self._stratify_scene = None    # the scene of the primal render, for prepare() (_sampling)
        self._glints_memo = None       # (scene, has_glints) within one pass (_sampling)
        self._strata_part = None       # (pattern, offset): a render of part of a pattern (prepare)
        self.light_selection = str(props.get("light_selection", LIGHT_SELECTION))
        if self.light_selection not in ("auto", "learned", "power", "uniform"):
            raise ParameterError(f"draaw_v4: light_selection={self.light_selection!r}; expected "
                                 "'auto', 'learned', 'power' or 'uniform'")
        self._light_sums = None        # per-emitter second-moment sums while a light pilot runs
        self._tables = {}              # selection key -> (emitter array, table | None, learned)
        self._frozen_selection = None  # (PowerSelection | None,) while a recording runs
        self.skip_constant_nee = not parse_bool(props, "draaw_v4", "constant_env_nee", False)
        self.want_depth = False        # set by draaw_mi.integrators.adaptive_sampling around its pilot pass
        self.last_depth = None
        self.want_first = False        # ... and this, where the pilot decides on guiding
        self.last_first = None
        self.init_emission_split(props)
        self._said_gates = set()         # the film / lens notes already warned (_say_sensor_gates)
        mode = str(props.get("guiding", "auto"))
        if mode not in ("auto", "on", "off"):
            raise ParameterError(f"draaw_v4: guiding={mode!r}; expected 'auto', 'on' or 'off'")
        self.guides = guide_cache.GuideCache(mode)
        self._guide = self._guide_records = None    # set around guided primal renders (guiding.py)
        self._reuse_layout = None      # pixel_reuse.Layout of a uniform primal pass that shares
        self._reuse_table = None       # its BSDFs that share (Held: not loop state) while a shared render runs
        self._share_memo = None        # (scene's selection_key, ShareTable | None, why not | None)
        self.pixel_reuse = str(props.get("pixel_reuse", "auto"))
        if self.pixel_reuse not in ("auto", "on", "off"):
            raise ParameterError(f"draaw_v4: pixel_reuse={self.pixel_reuse!r}; expected 'auto', 'on' or 'off'")

    def _extra_repr(self) -> str:
        return f", rr_depth={self.rr_depth}, rr_min={self.rr_min}, rr_threshold={self.rr_threshold}"

    def freeze_state(self, scene, memo: dict | None = None, sensor=None):
        """The scene-dependent state that a ``dr.freeze`` recording of this integrator takes as
        input (:meth:`Session.recording <draaw_mi.rendering.session.Session.recording>`): the light table's arrays (or ``None``)
        and the edge map of ``sensor`` (default the scene's first) for emission splitting (or
        ``None``). Computed here, outside the recording, so frozen and traced renders choose
        alike. ``memo``: a dict that lives as long as ``scene`` (:func:`~.scene_view.scene_view`),
        which makes this per-render step cheaper (0.05 ms on the Cornell box, more with many lights)."""
        view = scene_view(scene, memo)
        sel = self._table(scene, learn=True, key=view.key)
        return None if sel is None else sel.arrays(), self.frozen_edge_map(scene, view, sensor)

    @contextlib.contextmanager
    def frozen_state(self, state):
        """Within this block (a recording's body) use ``state`` from :meth:`freeze_state`."""
        sel, edges = state
        self._frozen_selection = None if sel is None else (PowerSelection.from_arrays(sel),)
        self._frozen_edges = emission_split.Held(edges)
        try:
            yield
        finally:
            self._frozen_selection = self._frozen_edges = None

    @dr.syntax
    def sample(self, mode, scene, sampler, ray, δL, state_in, active, **kwargs):
        primal = mode == dr.ADMode.Primal
        if dr.hint(self.max_depth == 0, mode="scalar"):
            return mi.Spectrum(0.0), mi.Bool(False), self.zero_aovs(), mi.Spectrum(0.0)
        feats = self.features(scene)
        # ---- participating media (draaw_mi.integrators.volume), only when the scene has them
        if dr.hint(feats["media"], mode="scalar"):
            from . import volume  # (60 ms to import: paid by scenes with media only)
            return volume.sample(self, mode, scene, sampler, ray, δL, state_in, active,
                                 russian_roulette=True)
        # ---- end media
        flags = self.ray_flags(feats)
        has_nee = len(scene.emitters()) > 0           # any emitter to sample
        if self.skip_constant_nee and only_constant_environment(scene):
            has_nee = False          # BSDF sampling alone is better and cheaper (sampling.py)
        hit_em = feats["hittable_lights"]             # area or environment emitters
        mis_em = hit_em                               # NEE needs MIS only against those
        delta_em = feats["delta_lights"]
        delta_bsdf = feats["delta_bsdfs"]
        ctx = mi.BSDFContext()
        sel = self.emitter_selection(scene) if has_nee else None
        guide = self._guide if primal else None       # guided paths (guiding.py)
        rec = self._guide_records if primal else None # a guide's training pass
        lane = dr.arange(mi.UInt32, dr.width(ray)) if rec is not None else None
        # emitters seen directly: from stratified extra camera rays (emission_split.py)
        primary, edges = self.split_inputs(scene, ray, feats)
        split = edges is not None                     # an emitting surface in view
        edge = None                                   # samples in edge pixels (when split)

        # --------------------- Configure loop state ----------------------
        ray = mi.Ray3f(dr.detach(ray))                # Current ray
        depth = mi.UInt32(0)                          # Depth of current vertex
        L = mi.Spectrum(0 if primal else state_in)    # Radiance accumulator
        δL = mi.Spectrum(δL if δL is not None else 0) # Differential/adjoint radiance
        β = mi.Spectrum(1)                            # Path throughput weight
        η = mi.Float(1)                               # Index of refraction
        active = mi.Bool(active)                      # Active SIMD lanes
        ray, pi, valid, cam_origin = self.trace_camera(scene, ray, active, feats)
        splat = split and primal and primary.splat is not None   # a filter other than box
        if dr.hint(split, mode="scalar"):
            edge = emission_split.edges_of(primary, edges, active)
            if dr.hint(splat, mode="scalar"):        # the emission seen here: a block of its own
                emission_split.splat_own_emission(scene, primary, ray, pi, flags, active & ~edge)
            L_vis, δL_vis = emission_split.visible_emission(
                mode, scene, primary, sampler, self.emission_split, flags, edge, δL)
            separate_adjoints(mode)      # (its backward_from before the main loop's)
            L = (L + L_vis) if primal else (L - L_vis)
            if dr.hint(mode == dr.ADMode.Forward, mode="scalar"):
                δL += δL_vis

        # Previous vertex (for MIS of emitters hit by BSDF sampling)
        prev_si = dr.zeros(mi.Interaction3f)          # p, n only: a smaller loop state
        prev_pdf = mi.Float(1.0)
        prev_delta = mi.Bool(True)

        sdf = self.sdf_hook(scene, feats)            # SDF objects (feature 'sdf')

        # the light reflected at the first vertex, shared with the pixel's 2x2 tile
        # (pixel_reuse.py) in the passes that name their lanes' layout
        layout = self._reuse_layout if primal and rec is None and sdf is None else None
        reuse = layout is not None
        reconnect = reuse and layout.table.reevaluates    # a BSDF other than Lambertian shares
        share = (reconnection.ReconnectedLight() if reconnect else pixel_reuse.SharedLight()) if reuse else None
        if dr.hint(reuse, mode="scalar"):
            shares = layout.table
            ray0, pi0, active0 = mi.Ray3f(ray), pi, mi.Bool(active)
            dr.eval(ray0, pi0, active0)    # (read again after the loop: traced once)

        # the light gathered by the first vertex (R + G + B), for adaptive sampling's pilot
        # where it decides on guiding (guiding.indirect_share's measure, at no extra pass)
        L_first = mi.Float(0.0) if primal and self.want_first else None

        aovs = self.zero_aovs()
        if dr.hint(primal and len(self.aovs) > 0, mode="scalar"):
            si0 = pi.compute_surface_interaction(ray, ray_flags=flags, active=active)
            if dr.hint(sdf is not None, mode="scalar"):
                si0 = sdf.intersect(ray, si0, None, active)
            aovs = self.eval_aovs(si0, si0.bsdf(ray), active, feats, cam_origin, sdf)
            del si0

        while dr.hint(active, max_iterations=self.max_depth,
                      label=f"draaw_v4 ({mode.name})"):
            active_next = mi.Bool(active)
            si = pi.compute_surface_interaction(ray, ray_flags=flags, active=active)
            if dr.hint(sdf is not None, mode="scalar"):
                si = sdf.intersect(ray, si, sampler, active)
                valid |= active & (depth == 0) & si.is_valid()
            bsdf = si.bsdf(ray)
            if dr.hint(reuse, mode="scalar"):
                share.visit(shares, depth, active, si, bsdf, ray.d)

            # ---------------------- Direct emission ----------------------
            Le = mi.Spectrum(0.0)
            Le_raw = Lr_raw = None                    # the same without β, for path reuse
            Le_em = pl_em = wo_em = E_em = rpl_em = None     # (ditto, unweighted: reconnection)
            if dr.hint(hit_em, mode="scalar"):
                em_active = mi.Bool(active)
                if dr.hint(self.hide_emitters, mode="scalar"):
                    em_active &= depth > 0
                elif dr.hint(splat, mode="scalar"):
                    em_active &= depth > 0               # splatted before the loop
                elif dr.hint(split, mode="scalar"):
                    em_active &= (depth > 0) | ~edge     # edge pixels: from the split rays
                ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
                if dr.hint(not has_nee, mode="scalar"):
                    w_bsdf = mi.Float(1.0)                # BSDF sampling is the only strategy
                elif dr.hint(sel is not None, mode="scalar"):
                    em_pdf = sel.pdf_direction(prev_si, ds, em_active & ~prev_delta)
                    w_bsdf = mis_weight(prev_pdf, em_pdf)
                    pl_em = em_pdf
                else:
                    em_pdf = scene.pdf_emitter_direction(prev_si, ds, em_active & ~prev_delta)
                    w_bsdf = mis_weight(prev_pdf, em_pdf)
                    pl_em = em_pdf
                with dr.resume_grad(when=not primal):
                    Le_em = ds.emitter.eval(si, em_active)
                    Le = β * w_bsdf * Le_em
                Le_raw = w_bsdf * Le_em

            active_next &= (depth + 1 < self.max_depth) & si.is_valid()
            if dr.hint(guide is not None or rec is not None, mode="scalar"):
                guidable = active_next & ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)

            # ---------------------- Emitter sampling ----------------------
            Lr_dir = mi.Spectrum(0.0)
            if dr.hint(has_nee, mode="scalar"):
                active_em = mi.Bool(active_next)
                if dr.hint(delta_bsdf, mode="scalar"):
                    active_em &= mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                with dr.resume_grad(when=not primal):
                    si_em = si
                    if dr.hint(sdf is not None and not primal, mode="scalar"):
                        si_em = sdf.reattach(ray, si, active_em)   # SDF shape derivatives
                    if dr.hint(sel is not None, mode="scalar"):
                        s_em = sampler.next_2d()
                        ds, em_w, active_em = sel.sample(scene, si_em, s_em, active_em, primal, sdf)
                    else:
                        ds, em_w, active_em = sample_emitter(scene, si_em, sampler.next_2d(),
                                                              active_em, primal, sdf)
                    wo = si_em.to_local(ds.d)
                    if dr.hint(primal, mode="scalar"):
                        # the light sample's value and the next direction in one BSDF call,
                        # as Mitsuba's path: one virtual-call dispatch less per bounce, 1-8 %
                        # less kernel time on the speed suite (render_overhead.md)
                        f_em, pdf_em, bs, bsdf_w = bsdf.eval_pdf_sample(
                            ctx, si, wo, sampler.next_1d(), sampler.next_2d(), active_next)
                        f_em = dr.select(active_em, f_em, 0.0)
                    elif dr.hint(mis_em, mode="scalar"):
                        f_em, pdf_em = bsdf.eval_pdf(ctx, si_em, wo, active_em)
                    else:
                        f_em = bsdf.eval(ctx, si_em, wo, active_em)
                    if dr.hint(mis_em, mode="scalar"):
                        if dr.hint(guide is not None, mode="scalar"):
                            pdf_em = guiding.mix_pdf(guide, si.p, ds.d, pdf_em, guidable)
                        w_em = mis_weight(ds.pdf, pdf_em)
                        if dr.hint(delta_em, mode="scalar"):
                            w_em = dr.select(ds.delta, 1.0, w_em)
                        Lr_dir = β * w_em * f_em * em_w
                        Lr_raw = w_em * f_em * em_w
                        if dr.hint(reconnect, mode="scalar"):
                            rpl_em = dr.select(ds.delta | (ds.pdf <= 0), 0.0, dr.rcp(ds.pdf))
                    else:
                        Lr_dir = β * f_em * em_w
                        Lr_raw = f_em * em_w
                        rpl_em = mi.Float(0.0)             # (delta lights only: not hit)
                    if dr.hint(reconnect, mode="scalar"):
                        wo_em, E_em = wo, dr.select(active_em, em_w, 0.0)
                    if dr.hint(self._light_sums is not None and sel is not None, mode="scalar"):
                        # light pilot (light_pilot.py): second moment per emitter
                        idx, _, pmf = sel.sample_index(s_em.x, active_em)
                        dr.scatter_reduce(dr.ReduceOp.Add, self._light_sums,
                                          mi.Float64(dr.square(mi.luminance(Lr_dir)) * pmf),
                                          idx, active_em)

            # ------------------ Detached BSDF sampling -------------------
            if dr.hint(not (has_nee and primal), mode="scalar"):     # else fused above
                bs, bsdf_w = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), active_next)
            if dr.hint(guide is not None, mode="scalar"):
                bs, bsdf_w = guiding.mix_sample(guide, bsdf, ctx, si, bs, bsdf_w, sampler, guidable)

            if dr.hint(reconnect, mode="scalar"):
                share.record(depth, ray, wo_em, E_em, rpl_em, bs.wo, Le_em,
                             pl_em if pl_em is not None else mi.Float(0.0))
            if dr.hint(reuse, mode="scalar"):
                L += share.own_part(depth, Le, Lr_dir, Le_raw, Lr_raw)
            else:
                L = (L + Le + Lr_dir) if primal else (L - Le - Lr_dir)
            if dr.hint(L_first is not None, mode="scalar"):
                L_first = dr.select(depth == 0, L.x + L.y + L.z, L_first)
            ray_next = si.spawn_ray(si.to_world(bs.wo))
            β *= bsdf_w
            if dr.hint(reuse, mode="scalar"):
                share.bounce(depth, bsdf_w)
            if dr.hint(rec is not None, mode="scalar"):
                rec.put(lane, depth, si.p, si.to_world(bs.wo), (L.x + L.y + L.z) / 3.0,
                        (β.x + β.y + β.z) / 3.0, bs.pdf, guidable)
            if dr.hint(delta_bsdf, mode="scalar"):
                η *= bs.eta
                prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            else:
                prev_delta = mi.Bool(False)
            if dr.hint(hit_em, mode="scalar"):
                prev_si = mi.Interaction3f(dr.detach(si, True))
                prev_pdf = bs.pdf

            # -------------------- Stopping criterion ---------------------
            if dr.hint(reuse, mode="scalar"):
                β, active_next, share.β = roulette(β, η, depth, self.rr_depth, self.rr_threshold,
                                                   self.rr_min, sampler.next_1d(), active_next, share.β)
            else:
                β, active_next = roulette(β, η, depth, self.rr_depth, self.rr_threshold, self.rr_min,
                                          sampler.next_1d(), active_next)

            pi_next = scene.ray_intersect_preliminary(ray_next, coherent=False,
                                                      active=active_next)

            # ------------------ Differential phase only ------------------
            if dr.hint(not primal, mode="scalar"):
                with dr.resume_grad():
                    si_f, wo_f = si, bs.wo
                    if dr.hint(sdf is not None, mode="scalar"):       # SDF shape derivatives
                        si_f, wo_f = sdf.reattach_sampled(ray, si, bs.wo, active_next)
                    f = bsdf.eval(ctx, si_f, wo_f, active_next)
                    Lo = Lr_dir + L * relative(f)
                    if dr.hint(sdf is not None, mode="scalar"):       # blended materials' weights
                        Lo = Lo * sdf.pick_weight(si_f, active_next)
                    δL = propagate_adjoint(mode, δL, Le + Lo)

            depth[si.is_valid()] += 1
            active = active_next
            pi = pi_next
            ray = ray_next

        if dr.hint(reuse, mode="scalar"):
            dr.eval(L, valid, depth, share)         # the loop's outputs, in one kernel
            L += pixel_reuse.tile_estimate(scene, layout, ray0, pi0, flags, active0,
                                           share.shared & (depth >= 2), share, guide)
        if dr.hint(primal and self.want_depth, mode="scalar"):
            self.last_depth = depth        # path lengths, for adaptive sampling's cost model
        if dr.hint(L_first is not None, mode="scalar"):
            self.last_first = L_first
        return (L if primal else δL), valid, aovs, L


def register() -> None:
    mi.register_integrator("draaw_v4", lambda props: DraawV4Integrator(props))
