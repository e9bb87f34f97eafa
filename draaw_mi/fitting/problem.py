"""What :func:`~draaw_mi.fitting.fitter.fit` works on once set up (:class:`FitProblem`),
and the helpers its iterations and its report share."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import post as post_mod
from ..rendering.session import Session
from ..scene import DraawScene
from .captures import CaptureOverrides
from .maps import MapSet


@dataclass
class FitProblem:
    """What :func:`_set_up` makes of the scene, references and parameters."""
    scene: DraawScene                  # the scene rendered (a copy at the references' size)
    callers_scene: DraawScene          # the scene given, which receives the fitted values
    session: Session
    integrator: object
    sensors: list
    refs: list                         # mi.TensorXf per view
    masks: list                        # a display reference's unclipped pixels, or None
    chain: object                      # the loaded post chain, or None
    keys: list                         # mi.traverse keys (of scene.all_params)
    names: dict                        # key -> the name as given
    prm: dict                          # key -> FitParam
    start: dict                        # key -> the scene's value (a diverged fit puts it back)
    initial: dict                      # key -> the value the optimiser starts from
    version: str
    spp: int
    spp_grad: int | None
    smooth: bool
    overrides: CaptureOverrides        # per capture: the light and parameter values it sets
    maps: MapSet                       # the textures fitted as maps (empty: none, or "texels")


def apply_chain(img, chain):
    return chain(img) if callable(chain) else post_mod.apply(img, chain)


def scalar(v):
    a = np.array(v).ravel()
    return float(a[0]) if a.size == 1 else a.tolist()


def record(v, shape):
    """A parameter's value as the history keeps it: a float, a list (a colour) or, for a
    texture (``shape``), a float32 array of its shape (a list of Python floats per texel and
    iteration would take 32 bytes a texel: 1.3 GB over 200 iterations of a 256x256 RGB texture)."""
    if shape is None:
        return scalar(v)
    return np.array(v, dtype=np.float32).reshape(shape)
