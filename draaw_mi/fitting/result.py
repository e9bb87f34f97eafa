"""What :func:`draaw_mi.fit` returns (:class:`FitResult`), and when a run counts as
converged (:func:`settled`)."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from ..errors import ParameterError
from ..io import write_exr, write_text
from ..plotting import save, subplots
from ..scene import load_scene
from .map_outputs import plot_maps, save_maps


@dataclass
class FitResult:
    """What :func:`draaw_mi.fit` returns.

    ``values``: fitted value per parameter (float, list for colours, float32 array of the
    texture's shape for textures); ``history``: one dict
    per iteration: ``"loss"``, ``"values"`` (``{name: value}``; of a texture, its channel means
    and mean deviations from them, :func:`~draaw_mi.fitting.problem.texture_summary`),
    ``"lr"`` (the learning rate) and ``"latent"`` (``{name: the optimiser's coordinates}``),
    e.g. ``[h["values"]["gold.roughness"] for h in res.history]``; ``image``: the final render of the
    first view (numpy, post chain applied); ``converged``: whether the parameters settled
    (their averaged iterates moved less than ``tol``, and not steadily in one direction: see
    :func:`settled`); ``exposure_stops``: the fitted exposure (0 unless ``exposure="fit"``);
    ``version``: the integrator it rendered with; ``observed``: per fitted map, which texels
    any capture saw (the others were filled from their neighbours); ``captures``: per view or
    capture, its residual and whether the fit explained it (:func:`explained`).
    ``stages``: per stage of :func:`~draaw_mi.fitting.two_starts.fit_two_starts`, its captures
    error and seconds; of a fit with ``polish``, each run's iterations, spp and seconds (empty
    otherwise).
    """
    values: dict
    history: list = field(default_factory=list, repr=False)      # (repr: no array dumps)
    image: np.ndarray | None = field(default=None, repr=False)
    converged: bool = False
    iterations: int = 0
    seconds: float = 0.0
    kernel_compiles: int = 0          # JIT kernels compiled after each view's first two passes (0 = none)
    exposure_stops: float = 0.0
    version: str = ""                 # the integrator the fit used (the scene's, or v4)
    observed: dict = field(default_factory=dict, repr=False)   # map name -> texels seen (H, W) bool
    captures: list = field(default_factory=list, repr=False)   # per view: explained(...)'s dicts
    stages: list = field(default_factory=list, repr=False)     # fit_two_starts' or a polished fit's

    @property
    def losses(self) -> np.ndarray:
        return np.array([h["loss"] for h in self.history])

    def plot(self, path: str | None = None):
        """Loss (log scale) and parameter values over iterations; saved to ``path`` if given."""
        if path is None:                  # shown where pyplot shows (a notebook's inline backend)
            import matplotlib.pyplot as plt
            fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
        else:                             # a file: no pyplot, no backend switch
            fig, (a, b) = subplots(1, 2, figsize=(10, 3.6))
        a.semilogy(self.losses)
        a.set_xlabel("iteration")
        a.set_ylabel("loss")
        a.set_title("loss")
        for name in self.values:
            v = np.array([h["values"][name] for h in self.history], dtype=float)
            if v.ndim == 1:
                b.plot(v, label=name)
            elif np.ndim(self.values[name]) >= 2:     # a texture: its summary's channel means
                for c in range(v.shape[1] // 2):
                    b.plot(v[:, c], label=f"mean {name}[{c}]")
            else:
                for c in range(v.shape[1]):
                    b.plot(v[:, c], label=f"{name}[{c}]")
        b.set_xlabel("iteration")
        b.set_ylabel("value")
        b.set_title("parameters")
        b.legend(fontsize=8, loc="best")
        fig.tight_layout()
        if path is not None:
            save(fig, path, dpi=100)
        return fig

    def save_maps(self, folder: str, formats=("exr", "png", "png16")) -> list[str]:
        """Write every fitted texture into ``folder``: ``<material>.<parameter>.exr`` (linear
        float32), ``.png`` (8-bit) and ``.16bit.png``, colour maps sRGB-encoded in the PNGs
        (:func:`~draaw_mi.fitting.map_outputs.save_maps`). Returns the files written."""
        return save_maps(self.values, folder, formats)

    def plot_maps(self, truth: dict | None = None, path: str | None = None):
        """The fitted maps beside ``truth`` (name -> array) where known, their error maps
        (unobserved texels blank) and the loss (:func:`~draaw_mi.fitting.map_outputs.plot_maps`)."""
        return plot_maps(self.values, truth, self.losses, self.observed, path)

    def save(self, path: str, scene=None) -> list[str]:
        """Write the fit to ``path``: for a scene described in TOML/JSON (``scene``, a
        :class:`~draaw_mi.scene.DraawScene` or the scene file's path) the description with the fitted values (``.toml``
        or ``.json``), otherwise ``{"fitted": values}`` (``.json``). A fitted texture goes to
        an EXR beside ``path`` (``<stem>.<material>.<parameter>.exr``, linear float32) that the
        written scene names. Atomic writes; returns the files written.

        >>> import os, tempfile
        >>> out = os.path.join(tempfile.mkdtemp(), "fit.json")
        >>> FitResult(values={"gold.roughness": 0.25}).save(out) == [out]
        True
        >>> open(out).read().split()
        ['{', '"fitted":', '{', '"gold.roughness":', '0.25', '}', '}']
        """
        if isinstance(scene, (str, os.PathLike)):        # a scene file: the scene it describes
            scene = load_scene(os.fspath(scene))
        lower = path.lower()
        described = scene is not None and getattr(scene, "description", None) is not None
        if not lower.endswith((".toml", ".json") if described else (".json",)):
            raise ParameterError(f"FitResult.save: {path!r}; expected a .toml or .json file"
                                 if described else f"FitResult.save: {path!r}; without a TOML/JSON "
                                 "scene only the values can be written, to a .json file")
        if described:                  # every value can be written back, before any file is
            scene.updated_description({name: 0.0 for name in self.values})
        written, values = [], {}
        stem = os.path.splitext(path)[0]
        for name, value in self.values.items():
            if isinstance(value, np.ndarray):          # a texture: an image file of its own
                base = name.removesuffix(".data")
                file = f"{stem}.{base}.exr"
                channels = {1: ["Y"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}.get(value.shape[-1])
                write_exr(file, value.reshape(value.shape[0], value.shape[1], -1), channels=channels)
                written.append(file)
                value = os.path.relpath(file, os.path.dirname(os.path.abspath(path)))
                name = base
            values[name] = _shortest(value)
        # (a TOML scene keeps its comments and layout: only the fitted values' lines change)
        text = scene.updated_text(values, dest=path) if described else json.dumps({"fitted": values}, indent=2)
        write_text(path, text)
        return written + [path]


def _shortest(value):
    """A fitted number (or list of them) as the shortest decimal that is the same float32, the
    precision the scene holds it in: 0.3808233, not 0.3808232992887497.

    >>> _shortest(0.3808232992887497), _shortest([0.1, 0.5]), _shortest("a.exr")
    (0.3808233, [0.1, 0.5], 'a.exr')
    """
    if isinstance(value, (list, tuple)):
        return [_shortest(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(np.format_float_positional(np.float32(value), unique=True, trim="0"))
    return value


def settled(history: list, tol: float, drift_ratio: float = 0.35) -> bool:
    """True when, for every parameter, the mean over the last eighth of the run differs from
    the mean over the eighth before by less than ``tol`` (absolute, RMS over a colour's
    entries; parameters live in [0, 1]) *and* the optimiser's own coordinate (``latent``: the value, or its log for
    roughness; each entry of a colour or of a map's summary) drifted by less than ``drift_ratio`` of what
    steps of those iterations' learning rates in one direction would make (Adam moves about
    ``lr`` a step while its
    gradient keeps its sign); and the loss is finite. Noise-robust: it looks at averaged
    iterates, not the last step. The drift test is what tells a decayed learning rate from
    an optimum: the cosine decay stops every parameter, and without it a 20-iteration run still
    descending (metallic at 1.0 for a truth of 0.8) counts as converged. Measured on the
    fit-sphere scene (16 spp): drift ratios 0.01-0.2 after 100 iterations, 0.55 after 40,
    0.76 after 20.

    >>> still = [{"loss": 1.0, "lr": 0.01, "values": {"m": 0.5}, "latent": {"m": 0.5}}] * 32
    >>> settled(still, 5e-3)
    True
    >>> slow = [{"loss": 1.0, "lr": 0.001, "values": {"m": 0.5 + 0.001 * i},
    ...          "latent": {"m": 0.5 + 0.001 * i}} for i in range(32)]
    >>> settled(slow, 5e-3)                       # moves 0.004 per eighth: under tol, yet steadily
    False
    >>> one_noisy = [{"loss": 1.0, "lr": 0.01, "values": {"c": [0.5] * 99 + [0.5 + 0.02 * (i % 2)]},
    ...               "latent": {"c": [0.5] * 99 + [0.5 + 0.02 * (i % 2)]}} for i in range(31)]
    >>> settled(one_noisy, 5e-3)                  # one entry of 100 jitters (0.01 between means)
    True
    """
    n = len(history)
    q = max(1, n // 8)
    if n < 16:
        return False
    if not np.isfinite(history[-1]["loss"]):
        return False
    path = q * float(np.mean([h.get("lr", 0.0) for h in history[-2 * q:]]))
    for name in history[-1]["values"]:
        v = np.array([h["values"][name] for h in history], dtype=float)
        # (RMS over a colour's or texture's entries: one noisy texel must not decide)
        if np.sqrt(np.mean(np.square(v[-q:].mean(axis=0) - v[-2 * q:-q].mean(axis=0)))) > tol:
            return False
        if "latent" in history[-1] and path > 0:
            # (the largest entry's: one channel of a map still descending, its blue mean at
            # 0.28 of 0.20, drifted 0.86 of a path where the RMS over its six summary
            # entries read 0.30, "settled")
            u = np.array([h["latent"][name] for h in history], dtype=float)
            drift = float(np.max(np.abs(u[-q:].mean(axis=0) - u[-2 * q:-q].mean(axis=0))))
            if drift > drift_ratio * path:
                return False
    return True


#: a capture is unexplained when its relative residual exceeds this many times the median
#: capture's, and UNEXPLAINED_FLOOR
UNEXPLAINED_RATIO = 3.0
UNEXPLAINED_FLOOR = 0.05


def explained(misfits: list, refs: list, masks: list) -> list:
    """Per view: ``{"misfit": the squared error of the fitted render's expectation, "relative":
    misfit / mean(ref^2) (1 = as far off as a black render), "explained": bool, "why": why
    not ("" when explained)}``. ``misfits[v] = mean((I1 - ref)(I2 - ref))`` over two renders
    with independent seeds: its expectation is ``(E[I] - ref)^2``, the Monte Carlo noise of
    the renders left out (a capture with a bright highlight is noisier, not worse explained).
    A view is unexplained when its relative misfit is above ``UNEXPLAINED_RATIO`` times the
    median view's and above ``UNEXPLAINED_FLOOR``: a black or wrongly lit photo, a camera that
    is off; or has no usable pixels (black, or saturated all over).

    >>> refs = [np.full((2, 2, 3), 0.5)] * 3
    >>> [c["explained"] for c in explained([0.001, 0.001, 0.5], refs, [None] * 3)]
    [True, True, False]
    """
    out = []
    for v, misfit in enumerate(misfits):
        ref = np.asarray(refs[v], dtype=np.float64)
        if masks[v] is not None:
            ref = ref * np.asarray(masks[v])
        energy = float(np.mean(ref * ref))
        misfit = max(float(misfit), 0.0) if np.isfinite(misfit) else float("inf")
        out.append({"misfit": misfit, "relative": misfit / energy if energy > 0 else float("inf")})
    rel = np.array([c["relative"] for c in out])
    finite = rel[np.isfinite(rel)]
    median = float(np.median(finite)) if finite.size else 0.0
    limit = max(UNEXPLAINED_RATIO * median, UNEXPLAINED_FLOOR)
    for c in out:
        c["explained"] = bool(np.isfinite(c["relative"]) and c["relative"] <= limit)
        c["why"] = ("" if c["explained"] else "no usable pixels (a black or saturated photo)"
                    if not np.isfinite(c["relative"]) else
                    f"misfit {c['relative']:.3g} of its energy, over {limit:.3g} (a wrong light, camera or photo?)")
    return out
