"""V4's stratified sampler: correlated multi-jittered samples whose strata are permuted per
pixel and per dimension by a hash (Kensler 2013's pattern; the hashing after Burley 2020).

A pixel's ``n`` samples are spread over ``N = 2^ceil(log2 n)`` strata in every dimension the
path draws: a 1D draw puts sample ``i`` of the pixel in stratum ``pi(i)`` of ``N`` and
jitters it uniformly within; a 2D draw puts it in cell ``pi(i)`` of an ``m x r`` grid
(``m r = N``) and, as in correlated multi-jittering, in sub-column ``pi_x(row)`` and sub-row
``pi_y(column)`` of that cell, so both 1D projections are stratified into ``N`` too. ``pi``,
``pi_x`` and ``pi_y`` are bijections of ``k``-bit integers (an xor with a key, then odd
multiplications and an xor-shift, all mod ``2^k``) whose keys hash the pixel, the render's
seed and the draw's dimension.

**Why each estimate stays unbiased.** The first step of every permutation xors the index
with uniformly random key bits, so ``pi(i)`` is uniform over the ``N`` strata for every
``i``; the jitter is uniform within the stratum; so every sample is uniform in each draw.
Keys of different dimensions are independent hashes, so each sample is jointly uniform over
all the dimensions it uses (pairs are checked by ``tests/integrators/test_strata_sampler.py``;
Mitsuba 3.9.1's ``multijitter`` fails that check below 256 spp, its ``orthogonal`` sampler
passes it at 1.5x ``path``'s time per sample). A count ``n`` that is not a power of two uses
``n`` of the ``N`` strata, chosen at random per pixel and dimension: each sample stays
uniform, the stratification is partial.

Only ``next_1d``, ``next_2d``, ``sample_count`` and ``clone`` (all that V4's passes, Mitsuba's
``sample_rays`` and path replay and the SDF tracer call), and a Dr.Jit struct, so that a
symbolic loop carries its state (the dimension counter, the jitter's random stream).

>>> import mitsuba as mi
>>> s = strata_sampler(4, seed=1, wavefront=8)         # two pixels of 4 samples
>>> u = s.next_1d()
>>> sorted(int(x * 4) for x in list(u)[:4])               # one sample per quarter
[0, 1, 2, 3]
"""
from __future__ import annotations

import functools

import drjit as dr
import mitsuba as mi

GOLDEN = 0x9E3779B9            # dimension stride of the key hash
SEED_SALT = 0x5851F42D         # (the jitter's stream and the strata's keys differ)
ONE_MINUS_EPS = float.fromhex("0x1.fffffep-1")


def mix32(x: mi.UInt32) -> mi.UInt32:
    """A 32-bit integer hash with full avalanche (Wellons' ``lowbias32``)."""
    x = x ^ (x >> 16)
    x = x * 0x7FEB352D
    x = x ^ (x >> 15)
    x = x * 0x846CA68B
    return x ^ (x >> 16)


def permute(i: mi.UInt32, key: mi.UInt32, bits: int) -> mi.UInt32:
    """A bijection of ``bits``-bit integers chosen by ``key``: ``i`` xor the key's low bits
    (uniform when the key is), then an odd multiplication, an xor-shift and an odd
    multiply-add, each mod ``2^bits``.

    >>> sorted(int(v) for v in permute(dr.arange(mi.UInt32, 8), mi.UInt32(12345), 3))
    [0, 1, 2, 3, 4, 5, 6, 7]
    """
    if bits == 0:
        return mi.UInt32(0)
    mask = (1 << bits) - 1
    x = (i ^ key) & mask
    x = (x * ((key >> 16) | 1)) & mask
    x = x ^ (x >> ((bits + 1) // 2))
    k2 = mix32(key)
    return (x * (k2 | 1) + (k2 >> 16)) & mask


class StrataSampler:
    """``spp`` correlated multi-jittered samples per pixel over a wavefront of
    ``pixels x spp`` lanes (Mitsuba's order: pixel-major), seeded by ``seed``.

    The count is a class attribute (:func:`strata_sampler` makes one class per count), since
    Dr.Jit's loops rebuild the sampler from its :attr:`DRJIT_STRUCT` fields with ``type(s)()``.
    """
    DRJIT_STRUCT = {"index": mi.UInt32, "key": mi.UInt32, "dim": mi.UInt32, "rng": mi.PCG32}
    spp = 0                    # samples per pixel
    bits = 0                   # N = 2^bits strata >= the pattern's samples
    pattern = 0                # samples of the pixel's whole pattern (spp, or more: a part)
    offset = 0                 # this pass's first sample of the pattern

    def __init__(self, seed=None, wavefront: int = 0):
        """Seeded for ``wavefront`` lanes (a multiple of :attr:`spp`), or empty (no ``seed``:
        Dr.Jit fills the fields)."""
        if seed is None:
            return
        spp = self.spp
        if spp < 1 or wavefront % spp:
            raise ValueError(f"StrataSampler: spp={spp}, wavefront={wavefront}; expected spp >= 1 "
                             "dividing the wavefront")
        idx = dr.arange(mi.UInt32, wavefront)
        pixel = idx >> self.bits if spp == 1 << self.bits else idx // spp
        self.index = idx - pixel * spp + self.offset
        # (opaque: a literal seed, a Python or a Dr.Jit one, would compile a kernel per seed)
        if isinstance(seed, int):
            seed = dr.opaque(mi.UInt32, seed & 0xFFFFFFFF)
        else:
            seed = mi.UInt32(seed)
            dr.make_opaque(seed)
        self.key = mix32(pixel ^ mix32(seed ^ SEED_SALT))
        self.dim = mi.UInt32(0)
        # (keyed by the sample's place in its pixel's pattern, ``idx`` for a whole pattern:
        # two parts of one pattern draw apart)
        v0, v1 = mi.sample_tea_32(seed, pixel * self.pattern + self.index)
        self.rng = mi.PCG32(wavefront, v0, v1)

    def sample_count(self) -> int:
        return self.spp

    def clone(self) -> "StrataSampler":
        """A sampler in the same state that draws the same numbers from here on (Mitsuba's
        path replay draws a gradient pass's paths twice: its primal replay from a clone)."""
        twin = type(self)()
        twin.index, twin.key, twin.dim = self.index, self.key, self.dim
        twin.rng = mi.PCG32(self.rng)
        return twin

    def _key(self) -> mi.UInt32:
        key = mix32(self.key + self.dim * GOLDEN)
        self.dim = self.dim + 1
        return key

    def next_1d(self, active: mi.Bool = True) -> mi.Float:
        """A 1D sample: stratum ``pi(i)`` of ``N``, jittered."""
        key = self._key()
        u = self.rng.next_float32(active)
        s = mi.Float(permute(self.index, key, self.bits))
        return dr.minimum((s + u) * (1.0 / (1 << self.bits)), ONE_MINUS_EPS)

    def next_2d(self, active: mi.Bool = True) -> mi.Point2f:
        """A 2D sample: cell ``pi(i)`` of an ``m x r`` grid, sub-column ``pi_x(row)``,
        sub-row ``pi_y(column)`` (both projections stratified into ``N``), jittered."""
        key = self._key()
        ux = self.rng.next_float32(active)
        uy = self.rng.next_float32(active)
        kx = self.bits // 2                          # m = 2^kx columns, r = 2^(bits - kx) rows
        ky = self.bits - kx
        cell = permute(self.index, key, self.bits)
        col = cell & ((1 << kx) - 1)
        row = cell >> kx
        k2 = mix32(key ^ GOLDEN)
        sx = permute(row, k2, ky)
        sy = permute(col, mix32(k2), kx)
        scale = 1.0 / (1 << self.bits)
        x = (mi.Float(col * (1 << ky) + sx) + ux) * scale
        y = (mi.Float(row * (1 << kx) + sy) + uy) * scale
        return mi.Point2f(dr.minimum(x, ONE_MINUS_EPS), dr.minimum(y, ONE_MINUS_EPS))


@functools.lru_cache(maxsize=None)
def _sampler_class(spp: int, pattern: int, offset: int) -> type:
    return type(f"StrataSampler{spp}_{pattern}_{offset}", (StrataSampler,),
                {"spp": spp, "bits": (pattern - 1).bit_length(), "pattern": pattern, "offset": offset})


def strata_sampler(spp: int, seed, wavefront: int, part: tuple | None = None) -> StrataSampler:
    """A :class:`StrataSampler` of ``spp`` samples per pixel over ``wavefront`` lanes.
    ``part = (pattern, offset)``: these are samples ``offset`` to ``offset + spp`` of each
    pixel's pattern of ``pattern`` (with the same ``seed``): passes over the parts of a
    pattern draw what one pass over all of it would, strata and all (each with its own
    jitter).

    >>> a = strata_sampler(1, seed=3, wavefront=1, part=(4, 0)).next_1d()
    >>> b = strata_sampler(3, seed=3, wavefront=3, part=(4, 1)).next_1d()
    >>> sorted(int(x * 4) for x in list(a) + list(b))      # one sample per quarter
    [0, 1, 2, 3]
    """
    pattern, offset = part if part is not None else (spp, 0)
    if int(spp) < 1 or not 0 <= int(offset) <= int(pattern) - int(spp):
        raise ValueError(f"strata_sampler: spp={spp}, part={part}; expected a count >= 1 "
                         "within its pattern")
    return _sampler_class(int(spp), int(pattern), int(offset))(seed, wavefront)
