"""Are a Mitsuba sampler's dimensions jointly uniform? (issue 45: why V4 does not stratify).

A randomised stratified sampler keeps every estimator unbiased only if each sample's random
numbers are jointly uniform, pair by pair of dimensions. This draws ``2^16 x spp`` samples
(one wavefront, ``spp`` per pixel) and bins pairs of them: two consecutive ``next_1d``, and
pairs across ``next_2d`` calls; it prints each pair's chi^2 per degree of freedom against the
uniform histogram (about 1.0 when uniform) and its most-off cell. Usage::

    .venv/bin/python benchmarks/sampler_uniformity.py                  # multijitter, 4-256 spp
    .venv/bin/python benchmarks/sampler_uniformity.py --sampler ldsampler --spp 16,64
    .venv/bin/python benchmarks/sampler_uniformity.py --sampler v4 --bins 16   # V4's own

Measured (Mitsuba 3.9.1, 2026-12-05): ``multijitter``'s consecutive 1D pair at 4 / 16 / 64 /
256 spp, 4x4 bins: chi^2/dof 546 / 205 / 1.9 / 0.6, cells up to 32 / 9 / 0.4 / 0.2 % off
(its 1D permutations are seeded by neighbouring integers; at 64 spp ``--bins 64`` gives 1.45
on 4095 degrees of freedom, far outside the 1.00 +- 0.02 of a uniform pair); the
``independent`` sampler 0.3-1.5 everywhere (``benchmarks/results/speed_suite.md``).
V4's own sampler (``draaw_mi/integrators/strata_sampler.py``, ``--sampler v4 --bins 16``):
chi^2/dof 0.79-1.09 on every pair at 4 / 16 / 64 / 256 spp (255 degrees of freedom: 1.00 +- 0.09
when uniform; the same pairs of the independent sampler 0.82-1.18).
"""
from __future__ import annotations

import argparse

import mitsuba as mi
import numpy as np


def pairs(kind: str, spp: int, pixels: int = 1 << 16, seed: int = 7) -> dict:
    """Named pairs of dimensions of ``pixels * spp`` samples, as float64 arrays (``kind``: a
    Mitsuba sampler plugin, or ``v4`` for V4's own stratified sampler)."""
    if kind == "v4":
        from draaw_mi.integrators.strata_sampler import strata_sampler
        s = strata_sampler(spp, seed, pixels * spp)
    else:
        s = mi.load_dict({"type": kind, "sample_count": spp})
        s.set_samples_per_wavefront(spp)
        s.seed(seed, pixels * spp)
    p = s.next_2d()
    a, b = s.next_1d(), s.next_1d()
    c = s.next_2d()
    d = s.next_1d()
    v = {k: np.array(x, dtype=np.float64) for k, x in
         dict(px=p.x, a=a, b=b, cx=c.x, cy=c.y, d=d).items()}
    return {"1d, next 1d": (v["a"], v["b"]), "pixel x, 2d x": (v["px"], v["cx"]),
            "2d y, next 1d": (v["cy"], v["d"])}


def chi2(u: np.ndarray, w: np.ndarray, bins: int) -> tuple[float, float]:
    """``(chi^2 per degree of freedom, largest relative deviation of a cell)`` of the pair's
    ``bins x bins`` histogram against uniform."""
    h = np.histogram2d(u, w, bins=bins, range=[[0, 1], [0, 1]])[0]
    expected = u.size / bins ** 2
    return float(((h - expected) ** 2 / expected).sum() / (bins ** 2 - 1)), float(np.abs(h / expected - 1).max())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sampler", default="multijitter")
    ap.add_argument("--spp", default="4,16,64,256")
    ap.add_argument("--bins", type=int, default=4)
    args = ap.parse_args(argv)
    mi.set_variant("llvm_ad_rgb")
    for kind in (args.sampler, "independent"):
        for spp in (int(x) for x in args.spp.split(",")):
            for name, (u, w) in pairs(kind, spp).items():
                c, off = chi2(u, w, args.bins)
                print(f"{kind:12s} {spp:4d} spp  {name:15s} chi2/dof {c:8.2f}  worst cell {100 * off:5.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
