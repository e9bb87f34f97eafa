"""Render passes: how many samples each pass takes, and each pass's seed.

A render of many samples runs in passes (memory, progress, a time budget); each pass has its
own seed (:func:`pass_seeds`) and takes a sample count its sampler takes exactly
(:func:`sample_passes`).
"""
from __future__ import annotations

import mitsuba as mi

from ..scene.camera import count_kept

_SAMPLES_TAKEN: dict = {}         # (sampler class, count asked) -> count taken; sample_passes


def pass_seeds(seed: int, n: int) -> list[int]:
    """Independent per-pass seeds; the first pass uses ``seed`` itself.

    >>> pass_seeds(7, 3)[0]
    7
    """
    return [pass_seed(seed, i) for i in range(n)]


def pass_seed(seed: int, i: int) -> int:
    """The ``i``-th of :func:`pass_seeds` (without building the list: a preview asks for its
    ten-thousandth).

    >>> pass_seed(7, 5) == pass_seeds(7, 6)[-1]
    True
    """
    return seed if i == 0 else (seed * 0x9E3779B1 + 0x632BE5AB * i) & 0xFFFFFFFF


def sample_passes(mi_scene, spp: int, pass_spp: int, sensor: int = 0) -> list[int]:
    """Samples per pass: at most ``pass_spp`` each, ``spp`` in all, each a count the scene's
    sampler takes as it is. Stratifying samplers round other counts up (``multijitter``
    renders 35 samples when asked for 32, ``ldsampler`` rounds to powers of four), which
    would make a render take more samples than it says; 32 becomes 30 + 2 instead (the
    sampler of the scene's sensor ``sensor``, an index). Where a
    sampler takes no count below some size (``ldsampler``: 4), the last pass is rounded up.

    >>> import mitsuba as mi
    >>> scene = mi.load_dict({"type": "scene", "sensor": {"type": "perspective",
    ...     "sampler": {"type": "multijitter"}}})
    >>> sample_passes(scene, 32, 256), sample_passes(scene, 40, 16)
    ([30, 2], [16, 16, 8])
    """
    sampler = mi_scene.sensors()[sensor].sampler()
    # Mitsuba's own samplers round by their kind alone: remember what each takes (probing
    # costs a fork and two log-level switches, about 40 us a render). A Python sampler may
    # round by its own options, so it is probed every time.
    kind = sampler.class_name() if type(sampler) is mi.Sampler else None

    def taken(k: int) -> int:
        if kind is not None and (kind, k) in _SAMPLES_TAKEN:
            return _SAMPLES_TAKEN[(kind, k)]
        got = count_kept(sampler, k)
        if kind is not None:
            _SAMPLES_TAKEN[(kind, k)] = got
        return got

    out, left = [], int(spp)
    while left > 0:
        k = min(left, int(pass_spp))
        got = taken(k)
        while got != k and k > 1:
            k -= 1
            got = taken(k)
        out.append(got)                     # k, or (k = 1) a sampler's smallest count
        left -= got
    return out
