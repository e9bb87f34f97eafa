"""Shared helpers of the post tests: the reference module, test images and parameter cases.

``reference.py`` is loaded under the unique module name ``post_reference`` so that it cannot
clash with another test folder's ``reference`` module.
"""
from __future__ import annotations

import importlib.util
import pathlib
import sys

import numpy as np


def _load_reference():
    name = "post_reference"
    if name not in sys.modules:
        path = pathlib.Path(__file__).with_name("reference.py")
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


ref = _load_reference()

SHAPE = (13, 17)          # odd, non-square: catches transposed axes
LARGE = (40, 48)          # offsets smaller than the image: the cheap boundary formulas


def hdr_image(seed: int = 0, shape=SHAPE, channels: int = 3, lo: float = 0.0,
              hi: float = 4.0) -> np.ndarray:
    """Random float32 HDR image: RGB = lo + (hi - lo) · u³ (mostly below 1, up to ``hi``),
    alpha (if any) uniform in [0, 1]."""
    rng = np.random.default_rng(seed)
    img = (lo + (hi - lo) * rng.random((*shape, channels)) ** 3).astype(np.float32)
    if channels == 4:
        img[..., 3] = rng.random(shape, dtype=np.float32)
    return img


#: (filter, params) cases checked against the reference; the first of each filter is the default.
CASES = {
    "contrast": [{}, {"contrast": 1.7, "pivot": 0.3, "amount": 0.6, "multipass": 2}],
    "tint": [{}, {"color": (0.2, 0.9, 1.5), "strength": 0.6, "amount": 0.5, "multipass": 3}],
    "bloom": [{}, {"threshold": 0.8, "intensity": 1.4, "clamp": False, "boundary": "zero",
                   "amount": 0.7, "multipass": 2},
              {"boundary": "mirror"}, {"boundary": "wrap", "clamp": False},
              {"boundary": "nearest"}],
    "bloom_v2": [{}, {"spread": 1.7, "clamp": False, "boundary": "nearest", "multipass": 1},
                 {"spread": 0.0}, {"spread": 3.0, "boundary": "wrap", "amount": 0.4}],
    "sharpen": [{}, {"sharpness": 1.5, "boundary": "zero", "amount": 0.3, "multipass": 2},
                {"boundary": "mirror"}, {"boundary": "wrap", "sharpness": 0.5}],
    "color_mapping": [{}, {"levels": (4, 7, 100), "amount": 0.5, "multipass": 2}],
    "chromatic_aberration": [{}, {"shift": 3.3, "boundary": "zero"},
                             {"shift": 0.5, "boundary": "nearest", "amount": 0.5},
                             {"shift": 40.25}, {"shift": 37.5, "boundary": "wrap"},
                             {"shift": 23.0, "boundary": "mirror"}],
    "edge_detection": [{}, {"distance": 1.5, "color": (1.0, 0.5, 0.0), "boundary": "zero",
                            "amount": 0.5},
                       {"distance": 2.0, "boundary": "wrap"}, {"distance": 0.0},
                       {"boundary": "mirror", "multipass": 2, "amount": 0.3}],
    "lighten": [{}, {"strength": -0.5, "amount": 0.5, "multipass": 4}],
    "crt": [{}, {"base": 0.2, "glow": 2.0, "radius": 5.5, "seed": 7, "clamp": False,
                 "boundary": "zero"},
            {"radius": 0.0}, {"boundary": "nearest", "radius": 40.0},
            {"boundary": "mirror", "radius": 9.0}, {"boundary": "wrap", "radius": 30.0}],
    "linear": [{}, {"gamma": 0.5, "scale": 1.0, "amount": 0.5}, {"gamma": 1 / 3,
                                                                  "clamp": False}],
    "log": [{}, {"gamma": 0.8, "scale": 10.0, "amount": 0.7, "multipass": 2, "clamp": False}],
    "srgb": [{}, {"inverse": True}, {"amount": 0.5, "multipass": 2}],
}

FILTER_NAMES = list(CASES)


def case_params():
    """pytest parameters ``(name, params)`` with readable ids."""
    out = []
    for name, cases in CASES.items():
        for i, params in enumerate(cases):
            out.append((name, params, f"{name}-{i}"))
    return out
