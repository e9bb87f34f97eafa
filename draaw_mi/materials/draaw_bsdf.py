"""The ``draaw`` BSDF: GO-Draaw's metallic/roughness material as a differentiable Mitsuba plugin.

Model (design.md §3)::

    f(wi, wo) = (1 - metallic) * base_color / pi                 Lambert, energy taken by F:
                * (1 - F(cos_i)) (1 - F(cos_o)) / (1 - F_avg)    reciprocal, albedo (1 - F(cos_i))
              + F * D(h) * G(wi, wo) / (4 cos_i cos_o)           Cook-Torrance, GGX
    F   = F0 + (F90 - F0) * (1 - <wi, h>)^5                      Fresnel-Schlick, per channel
    F_avg = F0 + (F90 - F0) / 21                                 cosine-weighted mean of F(cos)
    F0  = lerp(0.08 * specular, base_color, metallic)            (specular 0.5 -> F0 = 0.04)
    F90 = min(1, 50 * F0)                                        so F0 = 0 gives F = 0
    alpha = sqrt(roughness^4 + alpha_min^2)                      smooth clamp, alpha >= alpha_min
    G   = G1(wi) G1(wo)                                          separable Smith, as Mitsuba

``specular = metallic = 0`` is exactly Lambertian (Mitsuba ``diffuse``); ``metallic = 1``,
``base_color = 1`` is exactly ``roughconductor`` (GGX, ``material = "none"``) up to the smooth
alpha clamp (alpha's relative change is about alpha_min^2 / (2 roughness^4): below 1e-4
for roughness >= 0.27 at the default alpha_min, 3e-4 at roughness 0.2).

Sampling mixes cosine-weighted hemisphere sampling with GGX visible-normal sampling; the
probability of the glossy lobe is the luminance of the Fresnel term at normal-ish incidence
over the sum of both lobes' estimated albedos (it depends only on ``wi`` so the mixture pdf is
exact), and the returned weight is always ``eval / pdf`` of the same mixture.

Plugin parameters

.. pluginparameters::

 * - base_color
   - |texture|
   - Albedo / metal tint, RGB >= 0. (Default: 0.5)

 * - roughness
   - |texture|
   - GGX alpha = roughness^2 (clamped), in [0, 1]. (Default: 0.5)

 * - metallic
   - |texture|
   - Metallic-workflow mix, in [0, 1]. (Default: 0.0)

 * - specular
   - |texture|
   - Dielectric F0 = 0.08 * specular, in [0, 1]. (Default: 0.5)

 * - reflection
   - |texture|
   - Legacy mirror weight (V1/V2 only), in [0, 1]. (Default: 0.0)

 * - direct_to_scatter
   - |texture|
   - Legacy direct/scatter split (V1/V2), in [0, 1]. (Default: 1.0)

 * - normalmap
   - |texture|
   - Tangent-space normal map, 3 channels: x along the surface's u direction, y (green) along
     v, z out of the surface. Height and bump maps are not supported. (Default: none)

 * - normalmap_encoding
   - |string|
   - ``"unsigned"`` (0..1) or ``"signed"`` (-1..1). (Default: ``"unsigned"``)

 * - two_sided
   - |bool|
   - Shade back faces like front faces. (Default: |false|)

 * - alpha_min
   - |float|
   - Smallest GGX alpha, in (0, 0.1]. (Default: 1e-3)

A Mitsuba ``bitmap`` texture nested for a data parameter (roughness, metallic, specular,
reflection, direct_to_scatter, normalmap: XML ``<texture type="bitmap" name="roughness">`` or a
dict) must be ``raw`` when Mitsuba would sRGB-decode it (8/16-bit PNG, JPEG; half floats):
without ``<boolean name="raw" value="true"/>`` (``"raw": True``) it raises
:class:`ParameterError`; a file name (``<string name="roughness" value="rough.png"/>``) is
read raw. The values of any nested texture (a bitmap's texels, a ``checkerboard``'s colours)
are checked against the parameter's range.

Values set at load time outside their range raise :class:`ParameterError`; values set by an
optimiser through ``mi.traverse`` are clamped into range when evaluated, with a straight-through
gradient (the derivative of the unclamped value), so an optimiser sitting exactly on a bound —
metallic = 0, roughness = 1 — is not stuck there with a zero gradient. Two starts are: roughness
0, where ``alpha = sqrt(roughness^4 + alpha_min^2)`` is flat (its derivative is exactly 0; a fit
moves roughness in log space from above its floor, and warns of a start near it), and a black
``base_color`` with metallic 1 or specular 0, where the BSDF is 0 and path replay stops (a fit
warns of it: start from 0.02).

Example::

    >>> import draaw_mi, mitsuba as mi
    >>> bsdf = mi.load_dict({'type': 'draaw', 'roughness': 0.3, 'metallic': 1.0})
    >>> 'roughness.value' in mi.traverse(bsdf).keys()
    True
"""
from __future__ import annotations

import weakref

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError
from . import textures

INV_PI = 1.0 / 3.141592653589793
# Luminance weights (Rec. 709) used to pick the sampled lobe.
_LUM = (0.2126, 0.7152, 0.0722)

SCALAR_PARAMS = {
    # name: (default, low, high)
    "roughness": (0.5, 0.0, 1.0),
    "metallic": (0.0, 0.0, 1.0),
    "specular": (0.5, 0.0, 1.0),
    "reflection": (0.0, 0.0, 1.0),
    "direct_to_scatter": (1.0, 0.0, 1.0),
}
COLOR_PARAMS = {"base_color": (0.5, 0.0, None)}
ALL_PARAMS = tuple(COLOR_PARAMS) + tuple(SCALAR_PARAMS)
OPTIONS = ("normalmap", "normalmap_encoding", "two_sided", "alpha_min")
# how far a float normal map's components may overshoot their encoding's range (rounding of
# a normalised vector, resampling): 1e30 and Inf texels are what the range check is for
NORMALMAP_SLACK = 1e-2
NORMALMAP_ENCODINGS = ("unsigned", "signed")


def _lum(c):
    return _LUM[0] * c.x + _LUM[1] * c.y + _LUM[2] * c.z


def clamp_st(x, lo, hi):
    """Clamp the value into [lo, hi] but pass the gradient straight through (documented)."""
    clamped = dr.maximum(x, lo) if hi is None else dr.clip(x, lo, hi)
    return dr.replace_grad(clamped, x)


def _schlick(f0, f90, cos_theta):
    m = dr.clip(1.0 - cos_theta, 0.0, 1.0)
    m2 = dr.square(m)
    return f0 + (f90 - f0) * (m2 * m2 * m)


# Every live DraawBSDF. A dr.freeze recording that makes a BSDF virtual call fails when a
# Python BSDF instance is alive but not among its inputs (Dr.Jit 1.5 checks the whole registry
# domain; C++ plugins are not affected): draaw_mi.rendering.frozen.freeze_render passes these along.
LIVE_INSTANCES: "weakref.WeakSet" = weakref.WeakSet()


class DraawBSDF(mi.BSDF):
    """Metallic/roughness GGX + Lambert BSDF with GO-Draaw's legacy knobs (see module doc)."""
    # Every dr.freeze replay traverses each Python plugin's instance __dict__ (Dr.Jit's
    # traverse_py_cb_ro), paying per entry: about 3 us for a plain Python value, 5 us for a
    # nested texture. So plain options live in slots, outside the __dict__, an absent normal
    # map is the class attribute, and constant parameters are bare Dr.Jit arrays rather than
    # uniform textures: 0.56 -> 0.27 ms per frozen render of the Cornell box (5 BSDFs),
    # benchmarks/results/render_overhead.md.
    __slots__ = ("normalmap_signed", "two_sided", "alpha_min", "__dict__", "__weakref__")
    normalmap = None

    def __init__(self, props: mi.Properties):
        mi.BSDF.__init__(self, props)
        LIVE_INSTANCES.add(self)
        # each parameter: a bare Dr.Jit array when constant, else the texture
        for name, (default, lo, hi) in COLOR_PARAMS.items():
            tex = textures.texture_property(props, name, default, lo, hi, color=True)
            setattr(self, name, textures.as_parameter(tex))
        for name, (default, lo, hi) in SCALAR_PARAMS.items():
            tex = textures.texture_property(props, name, default, lo, hi, color=False)
            setattr(self, name, textures.as_parameter(tex))
        enc = props.get("normalmap_encoding", "unsigned")
        if enc not in NORMALMAP_ENCODINGS:
            raise ParameterError(f"draaw BSDF: normalmap_encoding={enc!r}; expected one of "
                                 f"{', '.join(NORMALMAP_ENCODINGS)}")
        self.normalmap_signed = enc == "signed"
        if "normalmap" in props:
            # values within the encoding's range (a texel of 1e30 or Inf would overflow the
            # normalisation into black patches; NaN and zero-length texels fall back)
            lo, hi = (-1.0, 1.0) if self.normalmap_signed else (0.0, 1.0)
            lo, hi = lo - NORMALMAP_SLACK, hi + NORMALMAP_SLACK
            self.normalmap = textures.texture_property(props, "normalmap", None, lo, hi, color=True)
            n = textures.channels(self.normalmap)
            if n is not None and n != 3:
                # (a grey map would be looked up as equal x, y, z: a height map's 0.7 tilts
                # every normal 55 degrees towards (1, 1))
                raise ParameterError(f"draaw BSDF: normalmap has {n} channel(s); expected a 3-channel "
                                     "(RGB) tangent-space normal map (height and bump maps are not "
                                     "supported)")
        two_sided = props.get("two_sided", False)
        if not isinstance(two_sided, bool):
            raise ParameterError(f"draaw BSDF: two_sided={two_sided!r}; expected true or false")
        self.two_sided = two_sided
        alpha_min = props.get("alpha_min", 1e-3)
        if isinstance(alpha_min, bool) or not isinstance(alpha_min, (int, float)):
            raise ParameterError(f"draaw BSDF: alpha_min={alpha_min!r}; expected a number in (0, 0.1]")
        self.alpha_min = float(alpha_min)
        if not (0.0 < self.alpha_min <= 0.1):
            raise ParameterError(f"draaw BSDF: alpha_min={self.alpha_min}; expected a value in (0, 0.1]")

        side = mi.BSDFFlags.FrontSide | (mi.BSDFFlags.BackSide if self.two_sided else mi.BSDFFlags(0))
        diff = mi.BSDFFlags.DiffuseReflection | side
        glossy = mi.BSDFFlags.GlossyReflection | side
        if any(textures.is_spatially_varying(getattr(self, n)) for n in ALL_PARAMS) or self.normalmap:
            diff |= mi.BSDFFlags.SpatiallyVarying
            glossy |= mi.BSDFFlags.SpatiallyVarying
        self.m_components = [diff, glossy]
        self.m_flags = diff | glossy

    # ------------------------------------------------------------------ parameters
    def _params(self, si, active):
        # Clamp into range with a straight-through gradient: an optimiser that sits exactly on
        # a bound (metallic = 0, roughness = 1) still sees which way the loss wants to go.
        base = clamp_st(textures.evaluate(self.base_color, si, active), 0.0, None)
        rough = clamp_st(textures.evaluate_1(self.roughness, si, active), 0.0, 1.0)
        metallic = clamp_st(textures.evaluate_1(self.metallic, si, active), 0.0, 1.0)
        specular = clamp_st(textures.evaluate_1(self.specular, si, active), 0.0, 1.0)
        alpha = dr.sqrt(dr.square(dr.square(rough)) + self.alpha_min ** 2)
        f0 = dr.lerp(mi.Color3f(0.08 * specular), base, metallic)
        f90 = dr.minimum(1.0, 50.0 * f0)
        kd = base * (1.0 - metallic)
        return kd, f0, f90, alpha

    def _spec_probability(self, kd, f0, f90, cos_i):
        """Probability of sampling the glossy lobe; depends on wi only (exact mixture pdf)."""
        w_spec = _lum(_schlick(f0, f90, cos_i))
        w_diff = _lum(kd) * (1.0 - w_spec)
        total = w_spec + w_diff
        # clipped: a base colour above 1 (an optimiser's step) makes w_diff negative; unclipped,
        # p > 1 and the mixture pdf is negative in 11 % of directions
        return dr.clip(dr.select(total > 0, w_spec / dr.select(total > 0, total, 1.0), 0.5), 0.0, 1.0)

    # ------------------------------------------------------------------ shading frame
    def _local_frame(self, si, active):
        """Return (wi, to_shading) where to_shading maps local directions to the (normal-mapped,
        two-sided-flipped) shading frame; identity when neither feature is on."""
        wi = si.wi
        flip = None
        if self.two_sided:
            flip = mi.Frame3f.cos_theta(wi) < 0
            wi = mi.Vector3f(wi.x, wi.y, dr.select(flip, -wi.z, wi.z))
        frame = None
        if self.normalmap is not None:
            v = self.normalmap.eval(si, active)
            n = mi.Vector3f(v.x, v.y, v.z) if self.normalmap_signed else mi.Vector3f(2 * v.x - 1, 2 * v.y - 1, 2 * v.z - 1)
            n_len = dr.norm(n)
            ok = (n_len > 1e-6) & (n.z > 1e-4)
            n = dr.select(ok, n / dr.select(ok, n_len, 1.0), mi.Vector3f(0, 0, 1))
            # Tangent: the local x axis made orthogonal to n (as Mitsuba's normalmap does with dp_du).
            t = mi.Vector3f(1, 0, 0) - n * n.x
            t_len = dr.norm(t)
            t = dr.select(t_len > 1e-6, t / dr.select(t_len > 1e-6, t_len, 1.0), mi.Vector3f(1, 0, 0))
            frame = mi.Frame3f(t, dr.cross(n, t), n)
        return wi, flip, frame

    @staticmethod
    def _flip(v, flip):
        return v if flip is None else mi.Vector3f(v.x, v.y, dr.select(flip, -v.z, v.z))

    # ------------------------------------------------------------------ core model
    def _eval_pdf_local(self, ctx, kd, f0, f90, alpha, wi, wo, active):
        """BSDF value (times cos_o) and mixture pdf for local directions wi, wo."""
        has_diff = ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0)
        has_spec = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1)
        cos_i = mi.Frame3f.cos_theta(wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        ok = active & (cos_i > 0) & (cos_o > 0)
        h = wi + wo
        h_len = dr.norm(h)
        h = dr.select(h_len > 1e-12, h / dr.select(h_len > 1e-12, h_len, 1.0), mi.Vector3f(0, 0, 1))
        F = _schlick(f0, f90, dr.dot(wi, h))
        value = mi.Color3f(0.0)
        pdf = mi.Float(0.0)
        p_spec = self._spec_probability(kd, f0, f90, cos_i) if (has_diff and has_spec) else (
            mi.Float(1.0 if has_spec else 0.0))
        if has_diff:
            # (1 - F(wi.h)) here would not conserve energy at grazing wi (albedo up to 1.9):
            # couple to F at both cosines instead (white furnace <= 1, still reciprocal).
            f_avg = f0 + (f90 - f0) * (1.0 / 21.0)
            t_i = dr.maximum(1.0 - _schlick(f0, f90, cos_i), 0.0)
            t_o = dr.maximum(1.0 - _schlick(f0, f90, cos_o), 0.0)
            value += kd * (t_i * t_o / dr.maximum(1.0 - f_avg, 1e-6)) * (INV_PI * cos_o)
            pdf += (1.0 - p_spec) * mi.warp.square_to_cosine_hemisphere_pdf(wo)
        if has_spec:
            distr = mi.MicrofacetDistribution(mi.MicrofacetType.GGX, alpha, True)
            D = distr.eval(h)
            G = distr.G(wi, wo, h)
            value += F * (D * G / (4.0 * dr.select(ok, cos_i, 1.0)))
            dot_oh = dr.abs(dr.dot(wo, h))
            pdf += p_spec * distr.pdf(wi, h) / (4.0 * dr.select(dot_oh > 0, dot_oh, 1.0))
        ok &= dr.isfinite(pdf)
        return dr.select(ok, value, 0.0), dr.select(ok, pdf, 0.0)

    def _prepare(self, si, active):
        """Parameters and shading frame at ``si``: what eval, pdf and sample all start from."""
        return self._params(si, active), self._local_frame(si, active)

    def _eval_pdf_prepared(self, ctx, prepared, wo, active):
        (kd, f0, f90, alpha), (wi, flip, frame) = prepared
        wo_l = self._flip(wo, flip)
        active = active & (mi.Frame3f.cos_theta(wo_l) > 0) & (mi.Frame3f.cos_theta(wi) > 0)
        if frame is not None:
            wi, wo_l = frame.to_local(wi), frame.to_local(wo_l)
        return self._eval_pdf_local(ctx, kd, f0, f90, alpha, wi, wo_l, active)

    def _sample_prepared(self, ctx, prepared, sample1, sample2, active):
        (kd, f0, f90, alpha), (wi_g, flip, frame) = prepared
        wi = frame.to_local(wi_g) if frame is not None else wi_g
        cos_i = mi.Frame3f.cos_theta(wi)
        active = active & (cos_i > 0) & (mi.Frame3f.cos_theta(wi_g) > 0)
        has_diff = ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0)
        has_spec = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1)
        bs = dr.zeros(mi.BSDFSample3f)
        if not (has_diff or has_spec):
            return bs, mi.Color3f(0.0)
        if has_diff and has_spec:
            p_spec = self._spec_probability(kd, f0, f90, cos_i)
        else:
            p_spec = mi.Float(1.0 if has_spec else 0.0)
        choose_spec = sample1 < p_spec
        wo = mi.warp.square_to_cosine_hemisphere(sample2)
        if has_spec:
            distr = mi.MicrofacetDistribution(mi.MicrofacetType.GGX, alpha, True)
            m, _ = distr.sample(dr.select(active, wi, mi.Vector3f(0, 0, 1)), sample2)
            wo = dr.select(choose_spec, mi.reflect(wi, m), wo)
        value, pdf = self._eval_pdf_local(ctx, kd, f0, f90, alpha, wi, wo, active)
        if frame is not None:
            wo = frame.to_world(wo)
        wo = self._flip(wo, flip)
        ok = active & (pdf > 0) & (mi.Frame3f.cos_theta(self._flip(wo, flip)) > 0)
        bs.wo = wo
        bs.pdf = dr.select(ok, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_component = dr.select(choose_spec, mi.UInt32(1), mi.UInt32(0))
        bs.sampled_type = dr.select(choose_spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection),
                                    mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
        weight = dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)
        return bs, weight

    # ------------------------------------------------------------------ mi.BSDF interface
    def eval(self, ctx, si, wo, active=True):
        return self._eval_pdf_prepared(ctx, self._prepare(si, active), wo, active)[0]

    def pdf(self, ctx, si, wo, active=True):
        return self._eval_pdf_prepared(ctx, self._prepare(si, active), wo, active)[1]

    def eval_pdf(self, ctx, si, wo, active=True):
        return self._eval_pdf_prepared(ctx, self._prepare(si, active), wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        return self._sample_prepared(ctx, self._prepare(si, active), sample1, sample2, active)

    def eval_pdf_sample(self, ctx, si, wo, sample1, sample2, active=True):
        """``eval_pdf(wo)`` and ``sample()`` in one call that evaluates the parameters and the
        shading frame once: a path tracer asks for both at every vertex (its light sample's
        value and the next direction), and one BSDF call instead of two is one virtual-call
        dispatch less per bounce (``draaw_v4`` and Mitsuba's ``path`` call this)."""
        prepared = self._prepare(si, active)
        value, pdf = self._eval_pdf_prepared(ctx, prepared, wo, active)
        bs, weight = self._sample_prepared(ctx, prepared, sample1, sample2, active)
        return value, pdf, bs, weight

    # ------------------------------------------------------------------ attributes
    def eval_diffuse_reflectance(self, si, active=True):
        return self._params(si, active)[0]

    def has_attribute(self, name, active=True):
        # "normalmap": whether this BSDF perturbs its shading frame (draaw_v3 samples those
        # lanes with sample(), in that frame)
        return name in ALL_PARAMS or name == "albedo" or (name == "normalmap" and self.normalmap is not None)

    def eval_attribute(self, name, si, active=True):
        if name in ("base_color", "albedo"):
            return mi.Color3f(textures.evaluate(self.base_color, si, active))
        if name in SCALAR_PARAMS:
            return mi.Color3f(textures.evaluate_1(getattr(self, name), si, active))
        return mi.Color3f(0.0)

    def eval_attribute_1(self, name, si, active=True):
        if name in SCALAR_PARAMS:
            return mi.Float(textures.evaluate_1(getattr(self, name), si, active))
        if name in ("base_color", "albedo"):
            return _lum(textures.evaluate(self.base_color, si, active))
        return mi.Float(0.0)

    def eval_attribute_3(self, name, si, active=True):
        return self.eval_attribute(name, si, active)

    def traverse(self, cb):
        # a constant under the key its uniform texture would have: NAME.value
        for name in ALL_PARAMS:
            value = getattr(self, name)
            if isinstance(value, mi.Texture):
                cb.put(name, value, mi.ParamFlags.Differentiable)
            else:
                cb.put(name + ".value", value, mi.ParamFlags.Differentiable)
        if self.normalmap is not None:
            cb.put("normalmap", self.normalmap, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        # A constant set to a Python number is a literal: kept so, every new value would
        # compile new kernels (a slider drag would recompile per step).
        for name in ALL_PARAMS:
            value = getattr(self, name)
            if not isinstance(value, mi.Texture):
                dr.make_opaque(value)

    def to_string(self):
        fields = ", ".join(f"{n}={textures.describe(getattr(self, n))}" for n in ALL_PARAMS)
        nm = f", normalmap={textures.describe(self.normalmap)} ({'signed' if self.normalmap_signed else 'unsigned'})"\
            if self.normalmap is not None else ""
        return f"DraawBSDF[{fields}{nm}, two_sided={self.two_sided}]"


def register_draaw_bsdf() -> None:
    mi.register_bsdf("draaw", lambda props: DraawBSDF(props))
