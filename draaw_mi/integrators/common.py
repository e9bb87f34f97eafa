"""Machinery shared by the ``draaw_v1`` .. ``draaw_v4`` integrators.

* :class:`DraawIntegrator` -- the common base (a Mitsuba ``RBIntegrator``, i.e. path-replay
  differentiable): property validation, the AOV outputs and the per-render feature flags.
* Emitter sampling with a differentiable re-evaluation of the emitted radiance.
* Local frames (two-sided BSDFs seen from the back) and :func:`relative` gradients.

The legacy Phong-family model of V1/V2 is in :mod:`draaw_mi.integrators.phong`, V3's own
evaluation and sampling of the ``draaw`` model in :mod:`draaw_mi.integrators.draaw_lobes`.

AOVs (property ``aovs``, a comma-separated list, or ``"all"``); channel names as in OpenEXR:

=============  ==============================  ===============================================
``depth``      ``depth.Z``                     distance from the camera to the first hit
                                               along the ray (0 on a miss); GO-Draaw "Lin"
``depth_log``  ``depth_log.Z``                 ``ln(1 + depth)`` (0 on a miss); GO-Draaw "Log"
``normal``     ``N.X``, ``N.Y``, ``N.Z``       world-space shading normal (0 on a miss)
``albedo``     ``albedo.R``, ``albedo.G``,     ``draaw``: ``base_color``; other BSDFs: their
               ``albedo.B``                    diffuse reflectance clipped to [0, 1]
=============  ==============================  ===============================================

AOVs are taken at the first surface the camera ray hits (with ``hide_emitters``: the first
one that is not an area emitter) and are not differentiated (their adjoints are ignored).
"""
from __future__ import annotations

import math
from contextlib import contextmanager

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError, RenderError, suggest
from ..guard import RENDER_GUARD
from ..sdf.integration import hook
from ..sdf.tracer import TracerOptions
from . import pass_sensor, silhouettes
from .features import detect_features, refuse_border_sampling

RBIntegrator = mi.ad.integrators.common.RBIntegrator

AOV_CHANNELS: dict[str, tuple[str, ...]] = {
    "depth": ("depth.Z",),
    "depth_log": ("depth_log.Z",),
    "normal": ("N.X", "N.Y", "N.Z"),
    "albedo": ("albedo.R", "albedo.G", "albedo.B"),
}

INV_PI = 1.0 / math.pi
INV_TWO_PI = 0.5 / math.pi
LUM = (0.2126, 0.7152, 0.0722)


def lum(c: mi.Color3f) -> mi.Float:
    """Rec. 709 luminance of an RGB colour."""
    return LUM[0] * c.x + LUM[1] * c.y + LUM[2] * c.z


def mis_weight(pdf_a: mi.Float, pdf_b: mi.Float) -> mi.Float:
    """Power-heuristic weight of strategy ``a`` (detached; 0 where not finite), as
    ``1 / (1 + (b/a)^2)``: squaring the pdfs themselves overflows above 1.8e19 (a tiny or
    grazing area light) and gives inf / inf, weight 0 instead of 1."""
    ok = pdf_a > 0
    r = pdf_b / dr.select(ok, pdf_a, 1.0)
    w = dr.select(ok, dr.rcp(1.0 + dr.square(r)), 0.0)
    return dr.detach(dr.select(dr.isfinite(w), w, 0.0))


def safe_div(a, b, ok=None):
    """``a / b`` where ``ok`` (default ``b != 0``), else 0; never divides by 0."""
    if ok is None:
        ok = b != 0
    return dr.select(ok, a / dr.select(ok, b, 1.0), 0.0)


def separate_adjoints(mode) -> None:
    """Call between two ``dr.backward_from`` of one ``sample()``: in backward mode, evaluate
    the first one's gradient scatters before the second is traced. In one kernel, Dr.Jit 1.5
    (LLVM, two threads) loses part of a texture's gradient at random: V2's base_color texture
    gets 0.108-0.144 for one seed over six runs, and 0 in some (scalar parameters, a plain
    reduction, are not affected)."""
    if mode == dr.ADMode.Backward:
        dr.eval()


def propagate_adjoint(mode, δL, Lo, separate: bool = False):
    """Path replay's adjoint step for the radiance ``Lo`` re-evaluated with AD at one vertex
    (as Mitsuba's ``prb``): in backward mode ``δL * Lo`` goes back to the parameters; in
    forward mode ``Lo``'s tangent is added to ``δL``. Returns ``δL`` (unchanged in backward
    mode, or when ``Lo`` carries no gradient). ``separate``: a backward step that follows
    another one of the same ``sample()`` (:func:`separate_adjoints`)."""
    if dr.grad_enabled(Lo):
        if mode == dr.ADMode.Backward:
            if separate:
                separate_adjoints(mode)
            dr.backward_from(δL * Lo)
        else:
            δL = δL + dr.forward_to(Lo)
    return δL


def parse_int(props: mi.Properties, plugin: str, name: str, default: int, low: int,
              allow_minus_one: bool = False) -> int:
    """Read an integer property and check ``value >= low`` (or ``-1`` where allowed)."""
    value = props.get(name, default)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParameterError(f"{plugin}: {name}={value!r}; expected an integer")
    if value < low and not (allow_minus_one and value == -1):
        extra = " or -1 (unbounded)" if allow_minus_one else ""
        raise ParameterError(f"{plugin}: {name}={value}; expected an integer >= {low}{extra}")
    return value


def parse_bool(props: mi.Properties, plugin: str, name: str, default: bool) -> bool:
    """Read a boolean property: only a bool (``bool()`` would read the string "false" as True)."""
    value = props.get(name, default)
    if not isinstance(value, bool):
        raise ParameterError(f"{plugin}: {name}={value!r}; expected a boolean (true or false)")
    return value


def parse_float(props: mi.Properties, plugin: str, name: str, default: float) -> float:
    """Read a number property: an int or float, not a bool (``float()`` reads ``True`` as 1.0)."""
    value = props.get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{plugin}: {name}={value!r}; expected a number")
    return float(value)


def parse_aovs(plugin: str, spec) -> tuple[str, ...]:
    """``"depth, normal"`` / ``"all"`` / ``""`` -> tuple of AOV names (validated, ordered)."""
    if spec is None:
        return ()
    if not isinstance(spec, str):
        raise ParameterError(f"{plugin}: aovs={spec!r}; expected a comma-separated string "
                             f"of {', '.join(AOV_CHANNELS)} or 'all'")
    names = [s.strip() for s in spec.split(",") if s.strip()]
    out = []
    for n in names:
        if n not in AOV_CHANNELS and n != "all":     # ("all" beside others: all of them)
            raise ParameterError(f"{plugin}: aovs entry {n!r} is unknown"
                                 f"{suggest(n, list(AOV_CHANNELS) + ['all'])}")
        if n not in out:
            out.append(n)
    return tuple(n for n in AOV_CHANNELS if n in out or "all" in out)


SHARED_PARAMETERS = """
     * - sdf_epsilon
       - |float|
       - SDF scenes: the sphere tracer's relative hit tolerance, in (0, 5e-5]
         (:mod:`draaw_mi.sdf.tracer`). (Default: 1e-5)

     * - sdf_max_steps
       - |int|
       - SDF scenes: the sphere tracer's iteration cap; a ray not converged by then is a
         miss. (Default: 256)

     * - sdf_relaxation
       - |float|
       - SDF scenes: over-relaxation factor of the sphere tracer, in [1, 2). (Default: 1.0)

     * - sdf_silhouettes
       - |bool|
       - SDF scenes: gradient passes add the boundary terms of outlines and shadow edges
         (:mod:`~draaw_mi.integrators.silhouettes`); |false| keeps the interior terms only.
         (Default: |true|)

     * - sdf_band
       - |float|
       - SDF scenes: width in pixels of the boundary terms' band, in (0, 8]. (Default: 1.0)

     * - sdf_creases
       - |bool|
       - SDF scenes: gradient passes add the shading jump at creases (sharp edges, sharp
         operators): unbiased but noisy. (Default: |false|)
"""


def with_shared_parameters(cls):
    """Class decorator of the draaw integrators: adds the rows of :data:`SHARED_PARAMETERS`
    (the options :class:`DraawIntegrator` parses for all four) to the end of the class
    docstring's ``pluginparameters`` table, so the plugin reference lists every option.

    >>> @with_shared_parameters
    ... class Demo:
    ...     \"\"\"Title.
    ...
    ...     .. pluginparameters::
    ...
    ...      * - max_depth
    ...        - |int|
    ...        - Longest path.
    ...
    ...     Text.\"\"\"
    >>> doc = Demo.__doc__; doc.index("max_depth") < doc.index("sdf_band") < doc.index("Text.")
    True
    """
    lines = cls.__doc__.split("\n")
    start = next(i for i, line in enumerate(lines) if ".. pluginparameters::" in line)
    end = start + 1
    while end < len(lines) and (not lines[end].strip() or lines[end].startswith("     ")):
        end += 1
    while not lines[end - 1].strip():
        end -= 1
    cls.__doc__ = "\n".join(lines[:end] + SHARED_PARAMETERS.rstrip("\n").split("\n") + lines[end:])
    return cls


class DraawIntegrator(RBIntegrator):
    """Base class of the draaw render versions (not registered itself)."""
    PLUGIN = "draaw"

    def __init__(self, props: mi.Properties):
        parse_int(props, self.PLUGIN, "max_depth", 6, 0, allow_minus_one=True)
        parse_int(props, self.PLUGIN, "rr_depth", 5, 1)
        super().__init__(props)
        self.aovs = parse_aovs(self.PLUGIN, props.get("aovs", ""))
        # SDF sphere-tracer knobs (sdf_epsilon, sdf_max_steps, sdf_relaxation; draaw_mi.sdf)
        self.sdf_tracer = TracerOptions.from_props(props, self.PLUGIN)
        # SDF outlines and shadow edges in the gradient passes (silhouettes.py)
        self.sdf_silhouettes = parse_bool(props, self.PLUGIN, "sdf_silhouettes", True)
        self.sdf_band_width = parse_float(props, self.PLUGIN, "sdf_band", 1.0)
        if not 0.0 < self.sdf_band_width <= 8.0:
            raise ParameterError(f"{self.PLUGIN}: sdf_band={self.sdf_band_width!r}; expected a "
                                 "band width in pixels in (0, 8]")
        self.sdf_band = None           # a Band while a gradient pass adds boundary terms
        # the shading jump at creases (sharp edges, sharp operators): unbiased but noisy
        self.sdf_creases = parse_bool(props, self.PLUGIN, "sdf_creases", False)

    # ------------------------------------------------------------------ interface
    def render(self, scene, sensor=0, seed=0, spp=0, develop=True, evaluate=True):
        """A primal render (what ``mi.render`` calls), under
        :data:`draaw_mi.guard.RENDER_GUARD`: a render of another scene in another thread (a
        notebook's preview beside its main thread) then waits for this one instead of
        breaking its ``dr.freeze`` recording. The gradient passes (``render_forward``,
        ``render_backward``) run inside Dr.Jit's AD traversal, where the guard is not taken."""
        with RENDER_GUARD, self.rendering(scene, sensor):
            return self.render_primal(scene, sensor, seed, spp, develop, evaluate)

    @contextmanager
    def rendering(self, scene, sensor):
        """A pass of ``sensor`` (an index or a Sensor): :func:`.pass_sensor.sensor_of` gives it to
        the media code on this thread; a film sampling beyond its border is refused."""
        with pass_sensor.rendering(self, scene, sensor) as obj:
            refuse_border_sampling(obj, self.PLUGIN, RenderError)
            self.before_pass(self, scene)
            yield

    #: ``before_pass(integrator, scene)``, called as each pass starts: what a version says of
    #: the scene (V1 / V2: :func:`.phong.say_diffuse_only`)
    before_pass = staticmethod(lambda integrator, scene: None)

    def render_primal(self, scene, sensor, seed, spp, develop, evaluate):
        """:meth:`render` itself: Mitsuba's path-replay primal render."""
        return super().render(scene, sensor, seed, spp, develop, evaluate)

    #: whether the version differentiates scenes with participating media (V1 / V2 march
    #: single scattering, primal-only)
    DIFFERENTIATES_MEDIA = True

    def _check_differentiable(self, scene) -> None:
        """A :class:`~draaw_mi.errors.RenderError` before a gradient pass of a scene this
        version renders primal-only: raised inside the traced loop, it reached the caller as
        Dr.Jit's "dr.if_stmt(): encountered an exception (see above)"."""
        if not self.DIFFERENTIATES_MEDIA and self.features(scene)["media"]:
            raise RenderError(f"{self.PLUGIN}: scenes with participating media are rendered primal-only "
                              "by V1/V2 (single-scattering march); differentiate with draaw_v3 / draaw_v4")

    def render_backward(self, scene, params, grad_in, sensor=0, seed=0, spp=0):
        """Mitsuba's path-replay adjoint (interior terms), then, for SDF shape parameters,
        the outline and shadow-edge terms (:mod:`~draaw_mi.integrators.silhouettes`)."""
        self._check_differentiable(scene)
        sensor = scene.sensors()[sensor] if isinstance(sensor, int) else sensor
        with self.rendering(scene, sensor), silhouettes.boundary_band(self, scene, sensor) as band:
            super().render_backward(scene, params, grad_in, sensor, seed, spp)
            if band is not None:
                silhouettes.backward(self, scene, grad_in, sensor, seed, spp)

    def render_forward(self, scene, params, sensor=0, seed=0, spp=0):
        """The gradient image: Mitsuba's path-replay tangents plus, for SDF shape parameters,
        the outline and shadow-edge terms."""
        self._check_differentiable(scene)
        sensor = scene.sensors()[sensor] if isinstance(sensor, int) else sensor
        with self.rendering(scene, sensor), silhouettes.boundary_band(self, scene, sensor) as band:
            grad = super().render_forward(scene, params, sensor, seed, spp)
            if band is not None:
                grad = grad + silhouettes.forward(self, scene, sensor, seed, spp)
        return grad

    def aov_names(self) -> list[str]:
        return [c for n in self.aovs for c in AOV_CHANNELS[n]]

    def features(self, scene: mi.Scene) -> dict[str, bool]:
        """Scene features (``detect_features``) plus this integrator's own AOV request."""
        f = detect_features(scene)
        f["aovs"] = bool(self.aovs)
        return f

    def sdf_hook(self, scene: mi.Scene, feats: dict[str, bool]):
        """The scene's SDF hook (``draaw_mi.sdf.integration.SDFHook``) or ``None`` when it has
        no SDF objects (then no SDF code is traced into the kernel)."""
        if not feats.get("sdf"):
            return None
        return hook(self, scene, feats)

    def to_string(self) -> str:
        depth = -1 if self.max_depth == 0xFFFFFFFF else self.max_depth
        return (f"{type(self).__name__}[max_depth={depth}, hide_emitters={self.hide_emitters}, "
                f"aovs={list(self.aovs)}{self._extra_repr()}]")

    def _extra_repr(self) -> str:
        return ""

    # ------------------------------------------------------------------ helpers
    #: whether the version shades with normal maps (V1 and V2 read the draaw parameters and
    #: other BSDFs' diffuse reflectance, which Mitsuba's normalmap / bumpmap pass by)
    READS_NORMAL_MAPS = True

    def ray_flags(self, feats: dict[str, bool]) -> mi.RayFlags:
        """Surface-interaction fields the scene needs: all of them for textures / normal maps
        (uv, dp/du; normal maps only for versions that read them, :attr:`READS_NORMAL_MAPS`)
        and anisotropic BSDFs (a shading frame whose tangent follows dp/du: without it the
        tangent is arbitrary and every anisotropic lobe turns, 14 % of a sphere's pixels
        beyond 3 sigma of ``path``'s); otherwise position, normals and shading frame."""
        if feats["textures"] or feats["anisotropic"] or (feats["normal_maps"] and self.READS_NORMAL_MAPS):
            return mi.RayFlags.All
        return mi.RayFlags.ShadingFrame

    def eval_aovs(self, si: mi.SurfaceInteraction3f, bsdf: mi.BSDFPtr, active: mi.Bool,
                  feats: dict[str, bool], cam_origin=None, sdf=None) -> list[mi.Float]:
        """AOV channel values at the camera ray's first hit ``si`` (primal only);
        ``cam_origin``: where the camera ray started, when it may have been continued from a
        hidden emitter (:meth:`trace_camera`): depth is measured from there, not from the
        emitter (or, through a sphere light, from the emitter's far side). ``sdf``: the
        scene's SDF hook, whose smooth blends of materials give the albedo AOV the blend of
        their albedos (:meth:`draaw_mi.sdf.integration.SDFHook.blended`), whichever material
        ``si`` was given for shading."""
        valid = active & si.is_valid()
        t = si.t if cam_origin is None else dr.norm(si.p - cam_origin)
        out: list[mi.Float] = []
        for name in self.aovs:
            if name == "depth":
                out.append(dr.select(valid, t, 0.0))
            elif name == "depth_log":
                out.append(dr.select(valid, dr.log(1.0 + dr.select(valid, t, 0.0)), 0.0))
            elif name == "normal":
                n = si.sh_frame.n
                out += [dr.select(valid, n.x, 0.0), dr.select(valid, n.y, 0.0),
                        dr.select(valid, n.z, 0.0)]
            elif name == "albedo":
                def albedo(b, m):
                    alb = mi.Color3f(0.0)
                    if feats["other_materials"]:
                        alb = dr.clip(b.eval_diffuse_reflectance(si, m), 0.0, 1.0)
                    if feats["draaw_materials"]:
                        has = m & b.has_attribute("albedo", m)
                        alb = dr.select(has, b.eval_attribute("albedo", si, has), alb)
                    return alb
                alb = albedo(bsdf, valid) if sdf is None else sdf.blended(si, bsdf, albedo, valid)
                alb = dr.select(valid, alb, 0.0)
                out += [alb.x, alb.y, alb.z]
        return out

    def trace_camera(self, scene: mi.Scene, ray: mi.Ray3f, active: mi.Bool,
                     feats: dict[str, bool]):
        """First intersection of the camera rays: ``(ray, pi, valid, cam_origin)``.

        With ``hide_emitters``, area emitters are skipped (as Mitsuba's ``path`` / ``prb``
        do): ``ray`` then starts on the last skipped emitter, and ``cam_origin`` is the camera
        rays' own origin, for depth AOVs (None when nothing can be skipped). ``valid`` (the
        alpha channel) is set where the ray hits a surface, or everywhere when a visible
        environment is shown.
        """
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
        cam_origin = None
        if self.hide_emitters and feats["area_lights"]:
            skip = active & pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711
            si_skip = pi.compute_surface_interaction(ray, mi.RayFlags.Minimal, skip)
            ray_skip = si_skip.spawn_ray(ray.d)
            pi_after = self.skip_area_emitters(scene, ray_skip, True, skip)
            cam_origin = mi.Point3f(ray.o)
            pi = dr.select(skip, pi_after, pi)
            ray = dr.select(skip, ray_skip, ray)
        valid = active & pi.is_valid()
        if feats["environment"] and not self.hide_emitters:
            valid = mi.Bool(active)
        return ray, pi, valid, cam_origin

    def first_hit(self, scene: mi.Scene, sampler: mi.Sampler, ray: mi.Ray3f, active: mi.Bool,
                  feats: dict[str, bool], flags: mi.RayFlags, primal: bool):
        """The camera rays' first surface interaction, with SDF objects and the AOVs there:
        ``(ray, si, valid, sdf, aovs)``. ``ray`` and ``valid`` as :meth:`trace_camera` gives
        them (with SDF hits in ``valid``); ``sdf`` the scene's SDF hook (:meth:`sdf_hook`, or
        ``None``); ``aovs`` the AOV values at the hit (zeros outside primal renders). V1-V3
        start their paths here; V4 finds its first interaction inside its loop."""
        ray, pi, valid, cam_origin = self.trace_camera(scene, ray, active, feats)
        si = pi.compute_surface_interaction(ray, ray_flags=flags, active=active)
        sdf = self.sdf_hook(scene, feats)            # SDF objects (feature 'sdf')
        if sdf is not None:
            si = sdf.intersect(ray, si, sampler, active)
            valid |= active & si.is_valid()
        aovs = self.zero_aovs()
        if primal and len(self.aovs) > 0:
            aovs = self.eval_aovs(si, si.bsdf(ray), active, feats, cam_origin, sdf)
        return ray, si, valid, sdf, aovs

    def zero_aovs(self) -> list[mi.Float]:
        return [mi.Float(0.0) for _ in self.aov_names()]

    def camera_aovs(self, scene: mi.Scene, ray: mi.Ray3f, active: mi.Bool, feats: dict[str, bool],
                    sdf=None) -> list[mi.Float]:
        """AOVs of the camera ray's first surface, for ``sample()`` bodies that follow the ray
        their own way (through media): the first intersection, a medium's null boundary
        included, as Mitsuba's ``aov`` integrator reports it (a medium has no depth, normal
        or albedo of its own). Nothing is traced when no AOV is asked for."""
        if not self.aovs:
            return []
        ray, pi, _, cam_origin = self.trace_camera(scene, mi.Ray3f(dr.detach(ray)), active, feats)
        si = pi.compute_surface_interaction(ray, ray_flags=self.ray_flags(feats), active=active)
        if sdf is not None:
            si = sdf.intersect(ray, si, None, active)      # (no random numbers: the largest weight)
        return self.eval_aovs(si, si.bsdf(ray), active, feats, cam_origin, sdf)


# ---------------------------------------------------------------------------------------
#  Emitters
# ---------------------------------------------------------------------------------------

def sample_emitter(scene: mi.Scene, si: mi.SurfaceInteraction3f, sample: mi.Point2f,
                   active: mi.Bool, primal: bool, sdf=None):
    """Sample one emitter direction with a shadow ray (detached); in the differential phases
    re-evaluate the emitted radiance with AD (call under ``dr.resume_grad(when=not primal)``).

    Returns ``(ds, weight, active)``: ``weight`` = radiance / pdf (0 if occluded);
    ``active`` is cleared where the sample is invalid or occluded. ``sdf``: the scene's SDF
    hook (SDF objects occlude the shadow ray; in the differential phases the sample's
    direction and distance factor follow an SDF point's re-attached position, and a visible
    sample near an SDF's shadow edge carries that edge's gradient: ``SDFHook.shadow_boundary``).
    """
    with dr.suspend_grad():
        ds, em_weight = scene.sample_emitter_direction(si, sample, True, active)
    active = active & (ds.pdf != 0.0)
    if sdf is not None:
        blocked = sdf.occluded(si, ds, active)
        active &= ~blocked
        em_weight = dr.select(blocked, 0.0, em_weight)
    if not primal:
        # (with SDFs the point's motion enters through sdf.emitter_geometry instead)
        em_val = scene.eval_emitter_direction(si if sdf is None else dr.detach(si), ds, active)
        em_weight = dr.replace_grad(em_weight, safe_div(em_val, dr.detach(ds.pdf), active))
        if sdf is not None:
            ds, em_weight = sdf.emitter_geometry(si, ds, em_weight, active)
            em_weight = sdf.shadow_boundary(si, ds, em_weight, active)
    return ds, em_weight, active


def emitter_sample_one(emitter: mi.Emitter, scene: mi.Scene, si: mi.SurfaceInteraction3f,
                       sample: mi.Point2f, active: mi.Bool, primal: bool, sdf=None):
    """Like :func:`sample_emitter` for one given emitter (used to light from every emitter)."""
    with dr.suspend_grad():
        ds, em_weight = emitter.sample_direction(si, sample, active)
        active = active & (ds.pdf != 0.0)
        occluded = scene.ray_test(si.spawn_ray_to(ds.p), active)
        if sdf is not None:
            occluded |= sdf.occluded(si, ds, active & ~occluded)
        active &= ~occluded
    if not primal:
        em_val = emitter.eval_direction(si if sdf is None else dr.detach(si), ds, active)
        em_weight = dr.replace_grad(em_weight, safe_div(em_val, dr.detach(ds.pdf), active))
        if sdf is not None:
            ds, em_weight = sdf.emitter_geometry(si, ds, em_weight, active)
            em_weight = sdf.shadow_boundary(si, ds, em_weight, active)
    return ds, dr.select(active, em_weight, 0.0), active


# ---------------------------------------------------------------------------------------
#  Local frames
# ---------------------------------------------------------------------------------------

def side_sign(bsdf: mi.BSDFPtr, si: mi.SurfaceInteraction3f, active: mi.Bool) -> mi.Float:
    """-1 where a two-sided BSDF is seen from its back (shade in the mirrored frame), else 1."""
    back = active & (mi.Frame3f.cos_theta(si.wi) < 0)
    back &= mi.has_flag(bsdf.flags(), mi.BSDFFlags.BackSide)
    return dr.select(back, -1.0, 1.0)


def flip_z(v: mi.Vector3f, sign: mi.Float) -> mi.Vector3f:
    return mi.Vector3f(v.x, v.y, v.z * sign)


def relative(f: mi.Color3f) -> mi.Color3f:
    """``dr.replace_grad(1, f / detach(f))`` that is 1 (and has no gradient) where f == 0."""
    fd = dr.detach(f)
    return dr.replace_grad(mi.Color3f(1.0), f / dr.select(fd != 0, fd, 1.0))
