"""Post-processing on Dr.Jit tensors: GO-Draaw's shader chain, differentiable and HDR-safe.

Every filter is a plain function on an (H, W, 3) or (H, W, 4) ``mi.TensorXf`` (float numpy
arrays are converted) that returns an ``mi.TensorXf`` of the same shape, plus a callable class
for chains (kornia style)::

    import draaw_mi.post as post
    out = post.bloom(img, threshold=0.1, amount=0.5)          # function
    out = post.Bloom(threshold=0.1, amount=0.5)(img)          # same, as an object
    out = post.apply(img, [{"type": "contrast", "contrast": 1.2},
                           {"type": "bloomV2", "BloomSpread": 1.5, "amount": 0.5},
                           {"type": "srgb"}])                  # chain (GO-Draaw names accepted)
    chain = post.load_chain("chain.json")                     # validated, callable

Filters (GO-Draaw type name in brackets): :func:`contrast`, :func:`tint`, :func:`bloom`,
:func:`bloom_v2` (``bloomV2``), :func:`sharpen`, :func:`color_mapping` (``colorMapping``),
:func:`chromatic_aberration` (``chromaticAberration``), :func:`edge_detection`
(``edgeDetection``), :func:`lighten` (``Lighten``), :func:`crt` (``CRT``, the README's
"Vignette"), and the tone curves :func:`linear` and :func:`log` (GO-Draaw's Lin/Log grades) and
:func:`srgb`.

Conventions shared by all filters (differences from GO-Draaw are listed in each docstring):

* ``amount`` ∈ [0, 1] (default 1.0, GO-Draaw's frontend uses 0.1) blends the effect with the
  input, ``out = c + amount · (f(c) - c)``; ``amount = 0`` returns the input exactly.
  ``multipass`` (default 1; 3 for the blooms) repeats the whole pass.
* Float, HDR images: GO-Draaw clamps and re-quantises to 8 bits after every pass; that is not
  done here. Only clamps written into an effect's formula remain (bloom's ``min(·, 1)``,
  CRT's ``clamp``, the Lin/Log grades' saturation at 1), each switchable with ``clamp=False``;
  negative values are allowed (contrast, sharpen can produce them).
* Distances (shift, Sobel distance, bloom spread, CRT radius) are in pixels. GO-Draaw's shaders
  use texel units, which makes ``Strength`` and ``Radius`` tiny or huge; its parameter names are
  accepted but read in pixels.
* Non-finite colour values (NaN, ±inf, from a user's image: draaw-mi's renders have none)
  are read as 0 before the first filter, as :func:`draaw_mi.denoise` does (a blur would spread
  one NaN pixel over a 13 × 13 square). ``amount = 0`` returns finite inputs exactly.
* Alpha (4th channel) passes through untouched.
* Differentiable end to end (fused ``dr.gather`` kernels; the quantiser uses a
  straight-through gradient). Parameters are Python numbers and are baked into the kernels:
  changing one recompiles the affected kernel (about 10 ms; a few hundred ms for CRT).
* Bad names and values raise :class:`~draaw_mi.errors.ParameterError` (a ``DraawError``)
  naming the filter, the parameter, the value and the valid range or names.
"""
from __future__ import annotations

from ._spec import BOUNDARIES, Filter, FilterSpec, Param
from .aberration import ChromaticAberration, chromatic_aberration
from .blur import Bloom, BloomV2, Sharpen, bloom, bloom_v2, sharpen
from .chain import FILTERS, Chain, apply, display_encoded, filter_class, load_chain
from .color import ColorMapping, Contrast, Lighten, Tint, color_mapping, contrast, lighten, tint
from .crt_look import CRT, crt
from .edges import EdgeDetection, edge_detection
from .tone import SRGB, Linear, Log, linear, log, srgb

__all__ = sorted([
    "BOUNDARIES", "Bloom", "BloomV2", "CRT", "Chain", "ChromaticAberration", "ColorMapping",
    "Contrast", "EdgeDetection", "FILTERS", "Filter", "FilterSpec", "Lighten", "Linear", "Log",
    "Param", "SRGB", "Sharpen", "Tint", "apply", "bloom", "bloom_v2", "chromatic_aberration",
    "color_mapping", "contrast", "crt", "display_encoded", "edge_detection", "filter_class",
    "lighten", "linear",
    "load_chain", "log", "sharpen", "srgb", "tint",
])
