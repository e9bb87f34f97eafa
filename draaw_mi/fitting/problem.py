"""What :func:`~draaw_mi.fitting.fitter.fit` works on once set up (:class:`FitProblem`),
and the helpers its iterations and its report share."""
from __future__ import annotations

from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from .. import post as post_mod
from ..rendering.session import Session
from ..scene import DraawScene
from .captures import CaptureOverrides
from .maps import MapSet
from .views import view_loss


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
    # key -> (sum of a texture's iterates over the averaged last part of the run, their count):
    # the history keeps a texture's channel means only (texture_summary)
    texture_sums: dict = field(default_factory=dict)


class PassLoss:
    """The loss of one capture's render within a fit iteration, as
    :meth:`~draaw_mi.rendering.session.Session.gradient_pass` evaluates it:
    ``loss(image, ref, mask, mean, w) -> (weight * loss, (exposure scale, new mean))``.

    The render's colour (its first three channels) goes through the running mean of recent
    renders where ``smooth`` (``mean`` and its weight ``w``: see
    :func:`~draaw_mi.fitting.fitter._mean_weight`; ``None`` otherwise), the post ``chain``, then
    :func:`~draaw_mi.fitting.views.view_loss` against ``ref`` (``mask``: its pixels that
    count, or ``None``). ``weight``: 1 / the captures an iteration renders. Equal losses (same
    settings) hash alike, so fits of one scene share their recordings; one with a post chain
    is traced, not recorded (a chain may close over JIT values).

    >>> import mitsuba as mi
    >>> ref, image = mi.TensorXf(np.full((2, 2, 3), 0.5)), mi.TensorXf(np.ones((2, 2, 3)))
    >>> value, (scale, mean) = PassLoss("l2", "fixed", 0.5)(image, ref, None, None, None)
    >>> round(float(value[0]), 4), mean
    (0.125, None)
    """
    __slots__ = ("kind", "exposure", "weight", "chain", "smooth")

    def __init__(self, kind: str, exposure: str, weight: float, chain=None, smooth: bool = False):
        self.kind, self.exposure, self.weight = kind, exposure, float(weight)
        self.chain, self.smooth = chain, bool(smooth)

    def _key(self) -> tuple:
        return self.kind, self.exposure, self.weight, id(self.chain), self.smooth

    def __eq__(self, other) -> bool:
        return isinstance(other, PassLoss) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __call__(self, image, ref, mask, mean, w):
        img = image[:, :, :3] if image.shape[2] > 3 else image
        if self.smooth:
            flat = dr.detach(img)
            # a non-finite pixel leaves the mean as it was (it had stayed NaN for the rest
            # of the run: every later loss NaN, the fit never settled)
            flat = dr.select(dr.isfinite(flat), flat, mean)
            mean = mean + w * (flat - mean)
            img = mean + (img - flat)      # the mean's value, the current render's derivative
        if self.chain is not None:
            img = apply_chain(img, self.chain)
        value, scale = view_loss(img, ref, self.kind, self.exposure, mask)
        return value * self.weight, (scale, mean if self.smooth else None)


def apply_chain(img, chain):
    return chain(img) if callable(chain) else post_mod.apply(img, chain)


def scalar(v):
    a = np.array(v).ravel()
    return float(a[0]) if a.size == 1 else a.tolist()


def texture_summary(v) -> list:
    """What the history keeps of a texture's iterate ``v`` (H x W x C, values or the optimiser's
    latents): per channel, the mean over the texels and the mean distance from it (a uniform
    drift moves the first, texels parting ways the second). A full copy per iteration held
    iterations x texels (3 MB every 4 iterations of a 256x256 RGB map, 10 GB over 800 of a
    1024x1024 one).

    >>> texture_summary(np.array([[[0.0, 1.0]], [[2.0, 1.0]]]))
    [1.0, 1.0, 1.0, 0.0]
    """
    a = np.asarray(v, dtype=np.float64)
    a = a.reshape(-1, a.shape[-1])
    mean = a.mean(axis=0)
    return [float(x) for x in np.concatenate([mean, np.abs(a - mean).mean(axis=0)])]


def record(v, shape):
    """A parameter's value as the history keeps it: a float, a list (a colour) or, for a
    texture (``shape``), a float32 array of its shape (a list of Python floats per texel and
    iteration would take 32 bytes a texel: 1.3 GB over 200 iterations of a 256x256 RGB texture)."""
    if shape is None:
        return scalar(v)
    return np.array(v, dtype=np.float32).reshape(shape)
