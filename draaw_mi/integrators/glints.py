"""Glints: the highlights of delta lights (point, spot, sun) on near-mirror surfaces, where a
scene's error sits in events too rare for a pilot of a few samples; ``draaw_v4`` renders such
scenes uniformly, with the scene's own sampler.

* Adaptive sampling (:mod:`~draaw_mi.integrators.adaptive_sampling`): its pilot misses most
  of the pixels that carry the variance, and every pixel it judged quiet loses samples:
  measured on the thesis scene (a point light over a floor of roughness 0.05), adaptive
  sampling costs 2.0x ``path``'s variance x time at 256x256 (24 renders) where V4 without it
  costs 1.15x.
* V4's stratified sampler (:mod:`~draaw_mi.integrators.stratify`): the same glass scene
  measured 0.53x ``path``'s time to its error stratified against 0.40x independent
  (``benchmarks/results/speed_suite.md``).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

from .features import scene_shapes

GLINT_ROUGHNESS = 0.1       # below this roughness a delta light's highlight is a rare event


def min_roughness(bsdf: mi.BSDF) -> float:
    """Smallest roughness (draaw) or alpha (Mitsuba's rough BSDFs) of ``bsdf``; 1 when it has
    none (delta or diffuse lobes cannot make a delta light's glint)."""
    p = mi.traverse(bsdf)
    vals = []
    for key in p.keys():
        leaf = key.split(".")[-2] if key.endswith((".value", ".data")) else key.split(".")[-1]
        if leaf in ("roughness", "alpha", "alpha_u", "alpha_v"):
            v = np.array(p[key], dtype=np.float64).ravel()
            if v.size:
                vals.append(float(v.min()))
    return min(vals) if vals else 1.0


def has_glints(scene: mi.Scene) -> bool:
    """Whether the scene has delta lights (point, spot, sun) and near-mirror surfaces
    (roughness or alpha below :data:`GLINT_ROUGHNESS`), whose glints are events too rare
    for a pilot of a few samples: see the module docstring."""
    delta = any(mi.has_flag(e.flags(), mi.EmitterFlags.Delta) for e in scene.emitters())
    if not delta:
        return False
    seen = set()
    for shape in scene_shapes(scene):
        b = shape.bsdf()
        if b is None or id(b) in seen:
            continue
        seen.add(id(b))
        if min_roughness(b) < GLINT_ROUGHNESS:
            return True
    return False
