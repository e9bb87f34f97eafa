"""V4's stratified sampler (``draaw_mi/integrators/strata_sampler.py``): its permutations are
bijections, each sample is jointly uniform over every pair of dimensions (or estimates are
biased), a pixel's samples are stratified in every draw, and a symbolic loop carries it."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from scipy import stats

from draaw_mi.integrators.strata_sampler import StrataSampler, permute, strata_sampler


def test_permute_is_a_bijection_of_k_bit_integers():
    """Every key permutes 0..2^k-1 onto itself (a non-bijection would drop strata and
    double others: samples no longer uniform)."""
    keys = mi.UInt32(np.random.default_rng(1).integers(0, 2 ** 32, 64, dtype=np.uint64).astype(np.uint32))
    for bits in range(0, 11):
        n = 1 << bits
        i = dr.tile(dr.arange(mi.UInt32, n), 64)
        k = dr.repeat(keys, n)
        out = np.array(permute(i, k, bits), dtype=np.int64).reshape(64, n) if bits else np.zeros((64, 1))
        assert (np.sort(out, axis=1) == np.arange(n)).all(), bits


def _draws(s) -> list:
    """Seven dimensions drawn as a path draws them (2D, 1D, 1D, 2D, 1D)."""
    p0, a, b, p1, c = s.next_2d(), s.next_1d(), s.next_1d(), s.next_2d(), s.next_1d()
    return [np.array(x, dtype=np.float64) for x in (p0.x, p0.y, a, b, p1.x, p1.y, c)]


def _worst_pair(dims: list, bins: int = 8) -> tuple[float, tuple]:
    """Largest chi^2 of a pair of dimensions binned ``bins x bins``, and the pair."""
    expected = dims[0].size / bins ** 2
    worst = (0.0, None)
    for i in range(len(dims)):
        for j in range(i + 1, len(dims)):
            h = np.histogram2d(dims[i], dims[j], bins=bins, range=[[0, 1], [0, 1]])[0]
            worst = max(worst, (float(((h - expected) ** 2 / expected).sum()), (i, j)))
    return worst


LIMIT = stats.chi2.ppf(1 - 1e-6, 8 ** 2 - 1)        # per pair; 21 pairs, 4 counts


@pytest.mark.parametrize("spp", [2, 4, 16, 100])
def test_each_sample_is_jointly_uniform_pair_by_pair(spp):
    """2^16 pixels x ``spp`` samples, seven dimensions, every pair binned 8x8: chi^2 within
    its 1e-6 quantile (stratification bins more evenly than random, so this is
    conservative). Keys of neighbouring dimensions that were not independent (Mitsuba's
    multijitter, below), or a permutation whose first step does not xor a uniform key, fail
    it."""
    worst, pair = _worst_pair(_draws(strata_sampler(spp, 7, (1 << 16) * spp)))
    assert worst < LIMIT, (spp, pair, worst / 63)


def test_the_uniformity_check_catches_a_correlated_sampler():
    """The check above on Mitsuba 3.9.1's multijitter at 4 spp, whose consecutive 1D
    dimensions are permuted by correlated seeds: it fails (measured chi^2/dof 546 at 4x4)."""
    s = mi.load_dict({"type": "multijitter", "sample_count": 4})
    s.set_samples_per_wavefront(4)
    s.seed(7, (1 << 16) * 4)
    worst, _ = _worst_pair(_draws(s))
    assert worst > 10 * LIMIT, worst / 63


@pytest.mark.parametrize("spp, grid", [(16, (4, 4)), (8, (2, 4)), (64, (8, 8))])
def test_a_pixels_samples_are_stratified_in_every_draw(spp, grid):
    """Within each pixel, a 1D draw puts one sample in each 1/spp stratum; a 2D draw one in
    each cell of its ``m x r`` grid and one in each 1/spp stratum of both projections
    (correlated multi-jittering). The independent sampler, or permutations shared across
    samples of a pixel, would not."""
    pixels = 32
    s = strata_sampler(spp, 3, pixels * spp)
    m, r = grid
    for _ in range(3):
        u = np.array(s.next_1d()).reshape(pixels, spp)
        assert (np.sort(np.floor(u * spp), axis=1) == np.arange(spp)).all()
        p = s.next_2d()
        x, y = (np.array(c).reshape(pixels, spp) for c in (p.x, p.y))
        for c in (x, y):
            assert (np.sort(np.floor(c * spp), axis=1) == np.arange(spp)).all()
        cells = np.floor(x * m) * r + np.floor(y * r)
        assert (np.sort(cells, axis=1) == np.arange(spp)).all()


def test_a_count_that_is_no_power_of_two_takes_distinct_strata():
    """100 spp over 128 strata: no two samples of a pixel in one stratum of a 1D draw."""
    s = strata_sampler(100, 5, 16 * 100)
    for _ in range(3):
        strata = np.floor(np.array(s.next_1d()).reshape(16, 100) * 128)
        assert all(len(set(row)) == 100 for row in strata)


def test_a_symbolic_loop_carries_the_sampler():
    """Draws in consecutive iterations of a ``dr.while_loop`` are new dimensions: jointly
    uniform with the first, and not the same strata (a loop that lost the dimension counter
    would repeat the first iteration's strata)."""
    spp, pixels = 16, 1 << 14
    s = strata_sampler(spp, 11, pixels * spp)
    first = s.next_1d()
    i = mi.UInt32(0)
    second = mi.Float(0)

    def body(i, s, second):
        second = s.next_1d()
        return i + 1, s, second

    i, s, second = dr.while_loop((i, s, second), lambda i, s, second: i < 2, body)
    a, b = np.array(first, dtype=np.float64), np.array(second, dtype=np.float64)
    assert isinstance(s, StrataSampler) and type(s).spp == spp
    assert not np.array_equal(np.floor(a * spp), np.floor(b * spp))
    worst, _ = _worst_pair([a, b])
    assert worst < LIMIT


def test_seeds_give_independent_renders_and_bad_counts_are_refused():
    a = np.array(strata_sampler(4, 1, 64).next_1d())
    assert np.array_equal(a, np.array(strata_sampler(4, 1, 64).next_1d()))
    assert not np.array_equal(a, np.array(strata_sampler(4, 2, 64).next_1d()))
    with pytest.raises(ValueError, match="spp=0"):
        strata_sampler(0, 1, 64)
    with pytest.raises(ValueError, match="wavefront=10"):
        strata_sampler(4, 1, 10)


def test_a_clone_draws_the_same_numbers():
    """Mitsuba's path replay traces a gradient pass's paths twice, the first time from a
    clone: the clone must draw what the sampler draws from there on (dimension and jitter),
    and neither may advance the other."""
    s = strata_sampler(8, 4, 8 * 16)
    s.next_2d()
    twin = s.clone()
    for draw in ("next_1d", "next_2d", "next_1d"):
        a, b = getattr(s, draw)(), getattr(twin, draw)()
        assert np.array_equal(np.array(a), np.array(b)), draw
    s.next_1d()
    assert not np.array_equal(np.array(s.next_1d()), np.array(twin.next_1d()))


@pytest.mark.parametrize("make", [lambda s: s, lambda s: mi.UInt32(s), lambda s: np.uint32(s)],
                         ids=["int", "UInt32", "numpy"])
def test_a_new_seed_compiles_no_new_kernel(make):
    """Seeds as Python ints, Dr.Jit literals or numpy integers: two seeds run the same kernel
    (a literal seed baked into the kernel compiled one per render: 0.374 s against 0.222 s
    for a 128x128 64-spp Cornell box)."""
    def kernels(seed) -> set:
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            u = strata_sampler(4, make(seed), 64).next_1d()
            dr.eval(u)
            hist = dr.kernel_history()
        return {k["hash"] for k in hist if k.get("type") == dr.KernelType.JIT}
    a, b = kernels(2), kernels(3)
    assert a and a == b, (a, b)
