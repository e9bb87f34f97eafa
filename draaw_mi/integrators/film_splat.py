"""V4's speed-ups under any pixel filter: samples splatted with per-sample weights.

Mitsuba's film splats each sample into every pixel whose filter covers it and divides by the
summed filter weights: pixel ``p = sum_s f(x_s - p) L_s / sum_s f(x_s - p)``. With samples
spread uniformly over the film this converges to ``int f(x - p) L(x) dx / int f(x - p) dx``,
the filtered image: what ``path`` renders with that filter. Two of V4's speed-ups change the
samples:

* **adaptive sampling** gives pixel ``q`` its own count ``d_q``, so samples are denser where
  noise is. Each sample's filter weight and value are scaled by ``1 / d_q`` (its pixel's
  count), which makes both sums estimate the same integrals as with uniform samples
  (``E[sum_s f(x_s - p) g(x_s) / d(x_s)] = int f(x - p) g(x) dx``): same limit as ``path``.
* **emission splitting**'s extra rays (:mod:`~draaw_mi.integrators.emission_split`) estimate
  the emission seen at the first hit from stratified positions over the sample's pixel. With
  a box filter every position of a pixel has the same weight, so their mean replaces the
  camera ray's own. With another filter each extra ray has its own filter weight, and the
  emission seen at the first hit gets an image block of its own: every camera sample puts
  it there (at its position, with its weight ``1 / d``), except in edge pixels, where each of the
  ``k`` extra rays puts its own at its position with the weight ``1 / (k d)``. Each block
  divides by the weights of its own samples: pixel ``p`` =
  ``sum_s f(x_s - p) L'_s / sum_s f(x_s - p)`` (``L'``: the paths without their first hit's
  emission) ``+ sum_r f(y_r - p) Le_r / sum_r f(y_r - p)`` (``r``: the emission's samples),
  each the filtered image of its part. One block for both, with the extra rays'
  emission over the camera samples' weights, keeps the expectation too, but a pixel inside
  a light next to its edge then divides a stratified sum by a random one: that doubled the
  variance of the light's inner pixels under a tent filter and made splitting a loss there
  (Cornell box under a tent filter at 128x128: V4's error 0.61x ``path``'s with
  splitting, 0.44x without).

So both are as unbiased as ``path``'s own ratio (consistent; its ``O(1/n)`` bias is that of
the film's division), for box, tent, gaussian, Lanczos, Mitchell and Catmull-Rom filters
alike (negative lobes are weights like any other). With a box filter the renderers keep
their per-pixel sums (a box splat is the same thing, and those kernels are unchanged).

:class:`FilmSplat` is the accumulation (the film's own :class:`mitsuba.ImageBlock` and its
:meth:`develop`), :func:`render_uniform` V4's primal render at one count per pixel when a
light's edges are in view under such a filter (otherwise Mitsuba's ``render`` is used as is).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .emission_split import PrimaryRays, film_mapping


class FilmSplat:
    """Samples of one render splatted through ``film``'s pixel filter, each with a weight.

    ``put`` adds a camera sample: ``value`` (film units: radiance times the camera weight),
    ``alpha`` and ``weight`` (the sample's ``1 / d``) into the value, alpha and weight channels;
    ``put_emission`` adds a sample of the emission seen at the first hit to the emission's own
    block (value and weight: see the module docstring). ``develop`` divides each block by its
    summed weights (0 where no weight arrived), adds the emission's image to the colour and
    leaves the sum in the film (``film.bitmap()`` after a render reads the image); once per
    FilmSplat, which several passes may fill (V4's adaptive pilot and main pass, each sample
    weighted by its pass's share over its pixel's count).

    >>> import draaw_mi, mitsuba as mi
    >>> scene = mi.load_dict(mi.cornell_box())
    >>> film = scene.sensors()[0].film()
    >>> _ = film.prepare([])
    >>> s = FilmSplat(film)
    >>> s.put(mi.Point2f(10.5, 20.5), mi.Color3f(2.0), mi.Float(1.0), mi.Float(0.5))
    >>> s.put_emission(mi.Point2f(10.5, 20.5), mi.Color3f(0.25), mi.Float(0.25), True)
    >>> img = s.develop()
    >>> [round(float(v), 3) for v in img.array[(20 * 256 + 10) * 3:(20 * 256 + 10) * 3 + 3]]
    [3.0, 3.0, 3.0]
    """
    __slots__ = ("film", "block", "alpha", "extra", "emission")

    def __init__(self, film: mi.Film, aov_count: int = 0):
        """``film``: prepared (``film.prepare(aov_names)``) for ``aov_count`` AOV channels."""
        self.film = film
        self.block = film.create_block()
        self.alpha = mi.has_flag(film.flags(), mi.FilmFlags.Alpha)
        self.extra = aov_count
        self.emission = None           # R, G, B, weight of the emission seen at the first hit

    def put(self, pos: mi.Point2f, value: mi.Color3f, alpha: mi.Float, weight: mi.Float,
            aovs=(), active: mi.Bool = True) -> None:
        chans = [value.x * weight, value.y * weight, value.z * weight]
        if self.alpha:
            chans.append(alpha * weight)
        chans.append(weight + 0.0 * value.x)
        chans += [a * weight for a in aovs]
        self.block.put(pos, chans, active)

    def put_emission(self, pos: mi.Point2f, value: mi.Color3f, weight: mi.Float,
                     active: mi.Bool) -> None:
        """Adds emission seen at a first hit: ``value`` in film units, already times
        ``weight`` (the sample's share ``1 / d``, or ``1 / (k d)`` for a split ray)."""
        if self.emission is None:
            b = self.block
            self.emission = mi.ImageBlock(b.size(), b.offset(), 4, self.film.rfilter(),
                                          border=b.has_border())
        self.emission.put(pos, [value.x, value.y, value.z, weight + 0.0 * value.x], active)

    def tensors(self) -> list:
        """The blocks' tensors (to evaluate a pass's splats with the kernel that traced them)."""
        return [b.tensor() for b in (self.block, self.emission) if b is not None]

    def develop(self) -> mi.TensorXf:
        """The film's developed image (once). The blocks are released on the way and, for
        large images, Dr.Jit's cache of freed memory is returned to the system (it keeps what
        is freed for arrays of the same size, which the image's are not:
        :func:`release_cache`), so that no more than the merged block is alive beside the
        film's own storage when the film develops."""
        if self.block is None:
            raise RuntimeError("FilmSplat.develop: already developed; a FilmSplat renders one image")
        block, self.block = self.block, None
        pixels = int(block.size()[0]) * int(block.size()[1])
        if self.emission is not None:
            merged = with_emission(block.tensor(), self.emission.tensor(), 3 + int(self.alpha))
            dr.eval(merged)
            self.emission = None
            block = mi.ImageBlock(merged, block.offset(), self.film.rfilter(), border=block.has_border())
            del merged
            release_cache(pixels)
        self.film.put_block(block)
        del block
        release_cache(pixels)
        return self.film.develop()


#: blocks of at least this many pixels return Dr.Jit's cache of freed buffers on develop
RELEASE_PIXELS = 1 << 18


def release_cache(pixels: int | None = None) -> None:
    """Dr.Jit's cache of freed buffers back to the system: for an image of ``pixels`` pixels
    from :data:`RELEASE_PIXELS` up (there the cache's copies of the image's buffers count; a
    small uniform render, repeated in a fit or a preview, would only pay to allocate them
    again), always where ``pixels`` is None (V4's adaptive render: 64 spp or more); never
    while a frozen function records (Dr.Jit refuses to free its cache then, and the
    recording would fail)."""
    if (pixels is None or pixels >= RELEASE_PIXELS) and not dr.flag(dr.JitFlag.FreezingScope):
        dr.flush_malloc_cache()


def with_emission(t: mi.TensorXf, e: mi.TensorXf, w: int) -> mi.TensorXf:
    """Block tensor ``t`` (H, W, C; channel ``w`` its weights) whose colour channels gain the
    developed emission of block tensor ``e`` (H, W, 4: R, G, B, weight) times ``t``'s own
    weight, so that developing ``t`` gives both images' sum."""
    h, wd, c = t.shape
    i = dr.arange(mi.UInt32, h * wd * c)         # one element-wise kernel, no scatter
    px = i // c
    ch = i - px * c
    colour = ch < 3
    ew = dr.gather(mi.Float, e.array, px * 4 + 3, colour)
    own_w = dr.gather(mi.Float, t.array, px * c + w, colour)
    e_value = dr.gather(mi.Float, e.array, px * 4 + ch, colour)
    flat = t.array + dr.select(colour & (ew != 0.0), e_value * own_w / ew, 0.0)
    return mi.TensorXf(flat, (h, wd, c))


def render_uniform(integrator, scene: mi.Scene, sensor: mi.Sensor, seed, spp: int,
                   develop: bool, evaluate: bool):
    """Mitsuba's path-replay primal render (``ADIntegrator.render``) with emission splitting's
    extra rays splatted through the film's filter (see the module docstring)."""
    if not develop:
        raise ValueError("render_uniform: develop=False; AD integrators render with develop=True")
    img = splat_pass(integrator, scene, sensor, seed, spp, None, own_emission=True).develop()
    if evaluate:
        dr.eval(img)
    return img


def splat_pass(integrator, scene: mi.Scene, sensor: mi.Sensor, seed, spp: int,
               splat: FilmSplat | None, own_emission: bool) -> FilmSplat:
    """One uniform pass of ``spp`` samples per pixel into ``splat`` (``None``: a new one, for
    the film as this pass prepares it), evaluated; returns the splat. With
    ``own_emission`` the emission seen at the first hit goes to its own block (a filter other
    than box with a light's edges in view); else ``sample()`` adds it to the path's light."""
    with dr.suspend_grad():
        sampler, spp = integrator.prepare(sensor=sensor, seed=seed, spp=spp, aovs=integrator.aov_names())
        if splat is None:
            splat = FilmSplat(sensor.film(), len(integrator.aov_names()))
        ray, weight, pos = integrator.sample_rays(scene, sensor, sampler)
        one = mi.Float(1.0)
        if own_emission:
            scale, offset = film_mapping(sensor.film())
            integrator.set_primary_rays(PrimaryRays(ray, sensor, dr.floor(pos), scale, offset, weight,
                                                    splat=(splat, one, pos)))
        try:
            L, valid, aovs, _ = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=sampler,
                                                  ray=ray, depth=mi.UInt32(0), δL=None, δaovs=None,
                                                  state_in=None, active=mi.Bool(True))
        finally:
            integrator.set_primary_rays(None)
        splat.put(pos, L * weight, dr.select(valid, 1.0, 0.0), one, aovs)
        del sampler, ray, weight, L, valid, aovs
        dr.eval(splat.tensors())
    return splat
