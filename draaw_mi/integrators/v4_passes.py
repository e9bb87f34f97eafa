"""How ``draaw_v4`` renders a pass: adaptively, stratified or uniformly, guided or not, and
with which sampler (the base class of :class:`~draaw_mi.integrators.v4.DraawV4Integrator`,
whose ``sample`` is the path tracer: this is what calls it; one base, as nanobind's
integrator classes take no mixins).

* A primal render of at least :data:`ADAPTIVE_MIN_SPP` spp whose samples are not stratified
  renders adaptively (:mod:`~draaw_mi.integrators.adaptive_sampling`): with ``stratify`` off,
  for a scene's first render whose pilot decides on guiding, and for glints.
* Other renders and gradient passes are uniform; where :meth:`V4Passes.stratified`, their
  samples come from V4's stratified sampler (:mod:`~draaw_mi.integrators.stratify`).
* A guided render (:mod:`~draaw_mi.integrators.guiding`) samples every pixel alike.
* Under a pixel filter other than box with a light's edges in view, a uniform render splats
  emission splitting's rays itself (:func:`~draaw_mi.integrators.film_splat.render_uniform`).
"""
from __future__ import annotations

import contextlib
import warnings

import drjit as dr
import mitsuba as mi

from . import adaptive_sampling as ads
from . import emission_split, film_splat, glints, guiding, pixel_reuse, reconnection, stratify
from .features import sampler_plugin, scene_shapes, sensor_gated_speedups
from .light_tables import LightTables
from .strata_sampler import strata_sampler

ADAPTIVE_MIN_SPP = 64   # below, the pilot (spp/16 < 4 samples) estimates variances too poorly


class V4Passes(LightTables):
    """``draaw_v4``'s render and gradient passes (see the module docstring). Needs the
    integrator's ``adaptive``, ``stratify``, ``guides``, ``aovs``, ``max_depth``,
    ``emission_split``, ``hide_emitters``, ``sdf_band``, ``_guide``, ``_stratify_scene``, ``_glints_memo``, ``_strata_part``,
    ``_said_gates`` and its ``features``, ``prepare_selection`` and ``edge_map``."""

    def render_primal(self, scene, sensor, seed, spp, develop, evaluate):
        """Primal render; with ``adaptive`` and ``spp >= ADAPTIVE_MIN_SPP`` (no AOVs, a plain
        seed, no guide) the unbiased two-pass adaptive render of
        :mod:`draaw_mi.integrators.adaptive_sampling`, otherwise ``RBIntegrator.render`` (or,
        under a pixel filter other than box with a light's edges in view,
        :func:`~draaw_mi.integrators.film_splat.render_uniform`, which splats the split rays).

        Guiding (:meth:`GuideCache.for_primal
        <draaw_mi.integrators.guide_cache.GuideCache.for_primal>`): where the adaptive pilot runs
        and ``auto`` has not decided on the scene yet, the pilot measures the indirect share
        and the main pass is guided if it calls for it. A guided render samples every pixel
        alike: with the guide, adaptive allocation from a pilot of spp/16 raised the error
        (glossy panel, 128^2 / 256^2: 0.63 / 0.43x ``path``'s MSE adaptive, 0.46 / 0.33x
        uniform; speed_suite.md)."""
        with self._sampling(scene):
            return self._render_primal(scene, sensor, seed, spp, develop, evaluate)

    def _render_primal(self, scene, sensor, seed, spp, develop, evaluate):
        self.prepare_selection(scene)
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        self._say_sensor_gates(sensor)
        n = int(spp) if spp else int(sensor.sampler().sample_count())
        adaptive = self.adaptive_applies(scene, sensor, seed, n, develop)
        decide = None
        # (not in recordings: a guide is learned from read-back results; not with media, which
        # V4 hands to volume.py)
        if self.guides.mode != "off" and not dr.flag(dr.JitFlag.FreezingScope) \
                and not self.features(scene)["media"]:
            self._guide, decide = self.guides.for_primal(self, scene, sensor, n, adaptive)
        try:
            if adaptive and self._guide is None:
                alpha = mi.has_flag(sensor.film().flags(), mi.FilmFlags.Alpha)
                rest = None
                if decide is not None and self.stratified(scene, sensor, n):
                    # adaptive only for the pilot's decision: left unguided, the rest of the
                    # samples render stratified, the rest of the pilot's pattern of n
                    def rest(count, pilot_seed):
                        self._strata_part = (n, n - count)
                        try:
                            return self._render_uniform(scene, sensor, pilot_seed, count, develop, evaluate)
                        finally:
                            self._strata_part = None
                return ads.render_adaptive(self, scene, sensor, seed, n, alpha, decide, rest)
            return self._render_uniform(scene, sensor, seed, spp, develop, evaluate)
        finally:
            self._guide = None

    def adaptive_applies(self, scene, sensor, seed, n: int, develop: bool = True, guides=None) -> bool:
        """Whether a primal render of ``n`` spp with ``seed`` renders adaptively (unless a
        guide is in use; :meth:`render_primal`). Where it would render stratified
        (:meth:`stratified`) only while its pilot is to decide on guiding (``guides``, the
        integrator's by default: :meth:`GuideCache.pilot_decides
        <draaw_mi.integrators.guide_cache.GuideCache.pilot_decides>`)."""
        # max_depth 1 (emitters seen directly): only pixel jitter is noisy, nothing to adapt
        possible = bool(self.adaptive and develop and not self.aovs and n >= ADAPTIVE_MIN_SPP
                        and self.max_depth > 1
                        and isinstance(seed, int) and ads.supported(sensor)
                        and not self._has_glints(scene))
        if not possible or not self.stratified(scene, sensor, n):
            return possible
        guides = self.guides if guides is None else guides
        return guides.pilot_decides(self, scene, sensor, n)

    def stratified(self, scene, sensor, n: int) -> bool:
        """Whether a render or gradient pass of ``scene`` of ``n`` spp through ``sensor``
        samples with V4's stratified sampler: ``stratify``, :func:`~draaw_mi.integrators.stratify.applies`
        (the independent sampler), no guide, no participating media, and not delta lights'
        glints on near-mirror surfaces
        (:func:`~draaw_mi.integrators.glints.has_glints`); guided renders and
        glints measured worse stratified (:mod:`~draaw_mi.integrators.stratify`)."""
        return self.independent_because(scene, sensor, n) is None

    def independent_because(self, scene, sensor, n: int) -> str | None:
        """Why a pass of ``n`` spp keeps independent samples, in a few words (``draaw-mi
        info``), or ``None`` where it stratifies (:meth:`stratified`)."""
        if not self.stratify:
            return "stratify=false"
        if self._guide is not None:
            return "a guide is learned"
        if not stratify.applies(sensor, n):
            return "one sample per pixel" if n < 2 else "the scene's own sampler"
        if self.features(scene)["media"]:
            return "participating media"
        if self._has_glints(scene):
            return "glints of delta lights on near-mirrors"
        return None

    def _has_glints(self, scene) -> bool:
        """:func:`~draaw_mi.integrators.glints.has_glints`, read once per render or gradient
        pass of ``scene`` (:meth:`_sampling`): it reads the BSDFs' roughness values back (0.8 ms
        for a 1024^2 roughness map), and a render asks up to three times."""
        memo = self._glints_memo
        if memo is not None and memo[0] is scene:
            return memo[1]
        value = glints.has_glints(scene)
        if self._stratify_scene is scene:
            self._glints_memo = (scene, value)
        return value

    @contextlib.contextmanager
    def _sampling(self, scene):
        """Within this block (a render or gradient pass) :meth:`prepare` may stratify (it is
        not given the scene), and :meth:`_has_glints` answers once."""
        previous = self._stratify_scene, self._glints_memo
        self._stratify_scene, self._glints_memo = scene, None
        try:
            yield
        finally:
            self._stratify_scene, self._glints_memo = previous

    def prepare(self, sensor, seed=0, spp=0, aovs=()):
        """The sampler of a render or gradient pass (Mitsuba's ``prepare``): V4's stratified
        sampler inside this integrator's passes where :meth:`stratified`, except in a gradient
        pass that adds the boundary terms of SDF shapes (all of it: they reseed their sampler
        for the rays of a band); else the sensor's."""
        sampler, n = super().prepare(sensor, seed, spp, list(aovs))   # (the film prepared)
        if self._reuse_table is not None:      # a pass of a shared render: its lanes as taken
            self._reuse_layout = pixel_reuse.Layout.of(sensor, n, self._reuse_table.value)
        scene = self._stratify_scene
        if scene is not None and self.sdf_band is None and self.stratified(scene, sensor, n):
            return strata_sampler(n, seed, sampler.wavefront_size(), self._strata_part), n
        return sampler, n

    def render_backward(self, scene, params, grad_in, sensor=0, seed=0, spp=0):
        with self._sampling(scene):
            return super().render_backward(scene, params, grad_in, sensor, seed, spp)

    def render_forward(self, scene, params, sensor=0, seed=0, spp=0):
        with self._sampling(scene):
            return super().render_forward(scene, params, sensor, seed, spp)

    def _render_uniform(self, scene, sensor, seed, spp, develop, evaluate):
        own_emission = (develop and not sensor.film().rfilter().is_box_filter()
                        and emission_split.applies(self.emission_split, self.hide_emitters, sensor,
                                                   self.features(scene))
                        and self.edge_map(scene, sensor) is not None)
        table = self.reuse_table(scene, sensor, spp) if develop else None
        try:
            if table is not None:
                return self._render_shared(scene, sensor, seed, spp, evaluate, own_emission, table)
            if own_emission:
                return film_splat.render_uniform(self, scene, sensor, seed, spp, develop, evaluate)
            return super().render_primal(scene, sensor, seed, spp, develop, evaluate)
        finally:
            self._primary = self._reuse_layout = self._reuse_table = None

    def _render_shared(self, scene, sensor, seed, spp, evaluate, own_emission, table):
        """A uniform render whose paths share their light within 2x2 pixel tiles
        (:mod:`~draaw_mi.integrators.pixel_reuse`), in passes of at most
        :data:`~.pixel_reuse.PASS_LANES` lanes (the tiles' exchange keeps each lane's second
        vertex in memory) splatted into one film: each pass the next part of a stratified
        pattern, or with its own seed."""
        n = int(spp) if spp else int(sensor.sampler().sample_count())
        size = sensor.film().crop_size()
        per_pass = max(1, pixel_reuse.PASS_LANES // (int(size[0]) * int(size[1])))
        stratified = self.stratified(scene, sensor, n)
        given = self._strata_part
        pattern, offset = given or (n, 0)
        splat = None
        self._reuse_table = emission_split.Held(table)   # (prepare() sets each pass's layout,
        try:                        # with the count its sampler takes: ldsampler rounds 11 up to 16)
            for i, start in enumerate(range(0, n, per_pass)):
                count = min(per_pass, n - start)
                self._strata_part = (pattern, offset + start)
                splat = film_splat.splat_pass(self, scene, sensor,
                                              seed if stratified else pixel_reuse.pass_seed(seed, i),
                                              count, splat, own_emission)
        finally:
            self._strata_part = given
        img = splat.develop()
        if evaluate:
            dr.eval(img)
        return img

    def reuse_table(self, scene, sensor, spp):
        """The BSDFs that share (:func:`~.pixel_reuse.share_table`) for a
        uniform primal pass of ``spp`` samples per pixel (0: the sensor's) that shares the
        light reflected at its first vertices within 2x2 pixel tiles
        (:mod:`~draaw_mi.integrators.pixel_reuse`), else ``None`` (:meth:`reuse_decision`)."""
        return self.reuse_decision(scene, sensor, spp)[0]

    def reuse_decision(self, scene, sensor, spp) -> tuple:
        """``(table | None, why)``: :meth:`reuse_table` and the reason in a few words
        (``draaw-mi info``). ``pixel_reuse``: ``on``, or ``auto`` where the scene's indirect
        share (guiding's pilot) is at least :data:`~.pixel_reuse.SHARE_MIN` in renders of 2^20
        samples or more (:func:`~.pixel_reuse.large_enough`) of images up to
        :data:`~.pixel_reuse.AUTO_MAX_PIXELS` pixels with the independent sampler (V4's stratified one in its place; other samplers round each
        pass's count up: ``on`` then takes more samples than asked), unless only environments
        light it (:func:`~.pixel_reuse.sky_only`); ``auto`` shares second vertices on
        Lambertian BSDFs only, except in guided renders of images up to
        :data:`~.reconnection.AUTO_MAX_PIXELS` pixels (every BSDF without delta lobes:
        :mod:`~.reconnection`). Never in ``dr.freeze`` recordings, with media or SDF objects,
        ``max_depth`` 2 or less, or without a surface that is not a light whose BSDF has no
        delta lobe."""
        if self.pixel_reuse == "off":
            return None, "pixel_reuse=off"
        if dr.flag(dr.JitFlag.FreezingScope):
            return None, "a frozen render"
        if 0 <= self.max_depth <= 2:
            return None, f"max_depth={self.max_depth}: no light after a bounce"
        table, unshared = self._share_table(scene)
        if table is None:
            return None, "no shape but lights has a BSDF without delta lobes"
        if unshared is not None:
            return None, unshared
        if self.pixel_reuse == "on":
            return table, "pixel_reuse=on"
        # re-evaluating other BSDFs (reconnection.py) costs 1.6-2.4x a sample's time: it paid
        # on the glossy panel, guided (0.085x path's MSE), not on the open scenes' metals and
        # glass unguided (speed_suite.md, session 77)
        size = sensor.film().crop_size()
        pixels = int(size[0]) * int(size[1])
        guided = self._guide is not None and pixels <= reconnection.AUTO_MAX_PIXELS
        others = ""
        if not guided:
            others = ("; its other BSDFs in guided renders up to "
                      f"2^{reconnection.AUTO_MAX_PIXELS.bit_length() - 1} pixels" if table.reevaluates else "")
            table = table.lambertian_only()
            if table is None:
                return None, ("auto: no shape but lights has a Lambertian BSDF (Mitsuba's diffuse; "
                              "others share in guided renders up to "
                              f"2^{reconnection.AUTO_MAX_PIXELS.bit_length() - 1} pixels)")
        n = int(spp) if spp else int(sensor.sampler().sample_count())
        if self._strata_part is not None:       # the rest of a pattern after adaptive sampling's
            n = self._strata_part[0]            # pilot: the render's count decides
        if not pixel_reuse.large_enough(n * pixels):
            return None, f"auto: renders of 2^{guiding.PILOTED_MIN_SAMPLES.bit_length() - 1} samples or more"
        if pixels > pixel_reuse.AUTO_MAX_PIXELS:
            return None, (f"auto: images up to 2^{pixel_reuse.AUTO_MAX_PIXELS.bit_length() - 1} pixels "
                          "(a pass keeps one sample of every pixel)")
        kind = sampler_plugin(sensor.sampler())
        if kind != "independent":
            return None, f"auto: the scene's {kind} sampler (which would round each pass's count)"
        if pixel_reuse.sky_only(scene):
            return None, "auto: only environments light the scene"
        share = self.guides.indirect_share(self, scene, self.selection_key(scene))
        if share < pixel_reuse.SHARE_MIN:
            return None, f"auto: {share:.0%} of the light arrives after a bounce (< {pixel_reuse.SHARE_MIN:.0%})"
        return table, (f"auto: {share:.0%} of the light arrives after a bounce"
                       + (", guided: every BSDF without delta lobes" if guided and table.reevaluates else others))

    def _share_table(self, scene) -> tuple:
        """``(table, why not)`` of ``scene``, kept for its next renders:
        :func:`~.pixel_reuse.share_table`, and where the scene's features rule sharing
        out (media, SDF objects), why (else ``None``). (A feature walk costs 40 ms on the
        2,000-light scene: once per scene, not per render.)"""
        key = self.selection_key(scene)
        memo = self._share_memo
        if memo is None or memo[0] != key:
            table = pixel_reuse.share_table(scene_shapes(scene))
            feats = self.features(scene) if table is not None else {}
            why = ("participating media" if feats.get("media") else
                   "SDF objects" if feats.get("sdf") else None)
            memo = self._share_memo = (key, table, why)
        return memo[1], memo[2]

    def _say_sensor_gates(self, sensor) -> None:
        """A ``RuntimeWarning``, once per integrator and reason, when the film or the lens
        turns adaptive sampling or emission splitting off (both on by default)."""
        if not (self.adaptive or self.emission_split > 1):
            return
        gated = sensor_gated_speedups(sensor)
        if gated is not None and gated not in self._said_gates:
            self._said_gates.add(gated)
            warnings.warn(f"draaw_v4: {gated}", RuntimeWarning, stacklevel=2)
