"""V3's glossy split against ``path`` with many renders: bias, or a skewed estimator?

The per-pixel expectation test (``tests/integrators``) uses 12 renders per pixel. V3's glossy
split (emitter hits by BSDF sampling, no MIS) is right-skewed; under a stratified sampler, which
removes most other noise, 12 renders no longer estimate its variance and the z-scores lean
positive. This script repeats the comparison with more renders and also compares the image
means (each render's mean is one sample), which skew does not bias.

Usage::

    .venv/bin/python benchmarks/expectation_tails.py RENDERS SPP [SAMPLER]   # e.g. 96 1024 multijitter
"""
import os
import sys

import numpy as np

import draaw_mi
import mitsuba as mi

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests", "integrators"))
from integrators_helpers import z_summary, zscores  # noqa: E402


def main(argv) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    k, spp = int(argv[0]), int(argv[1])
    sampler = argv[2] if len(argv) > 2 else "multijitter"
    scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "cornell.toml"), resolution=(16, 16),
                                sampler=sampler).mi_scene

    def stack(props, base):
        integ = mi.load_dict({"max_depth": 6, **props})
        return np.stack([np.array(mi.render(scene, integrator=integ, spp=spp, seed=s))[..., :3]
                         for s in range(base, base + k)])

    ref = stack({"type": "path"}, 0)
    for name, props, base in (("v3 (glossy split)", {"type": "draaw_v3"}, 10000),
                              ("v3 without split", {"type": "draaw_v3", "glossy_alpha": 0.0}, 20000)):
        st = stack(props, base)
        z = z_summary(zscores(ref, st))
        a, b = st.reshape(k, -1).mean(1), ref.reshape(k, -1).mean(1)
        d, se = a.mean() - b.mean(), np.sqrt(a.var(ddof=1) / k + b.var(ddof=1) / k)
        print(f"{name}: per-pixel z mean {z['mean']:.3f}, std {z['std']:.3f}, beyond 3 sigma "
              f"{100 * z['frac_gt3']:.2f} %; image mean vs path {100 * d / b.mean():+.4f} % "
              f"+- {100 * se / b.mean():.4f} % ({d / se:+.1f} SE)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
