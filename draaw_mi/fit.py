"""Inverse fitting: recover material parameters (roughness, metallic, colour, ...) from images.

``fit(scene, references, params=["mat.roughness", "mat.metallic"])`` renders the scene with a
differentiable (path-replay) integrator, compares it with one reference image per view, and
runs Adam on the named parameters.

How it stays robust (see design.md §8 and the guide §1b, §9):

* **Valid ranges by projection.** After every Adam step each parameter is clipped to its
  range (roughness, metallic, specular, reflection, direct_to_scatter in [0, 1]; colours >= 0,
  or [0, 1] for ``base_color``). Projection rather than a sigmoid reparameterisation keeps the
  exact bounds reachable (metallic exactly 0 or 1) with no vanishing gradients near them.
* **Sanitised gradients.** NaN/Inf gradient entries are zeroed before each step, so one bad
  sample cannot poison Adam's moments for the rest of the run.
* **One kernel per run.** Resolution, spp and the integrator stay fixed; only the seed (not
  baked into the kernel) and the parameter values (arrays) change, so the render kernels are
  compiled on the first iteration and then reused (``result.kernel_compiles`` tells).
* **Noise-robust estimate.** The reported values are the average of the iterates over the last
  ``average_last`` fraction of the run (Polyak averaging), which removes most of the Monte Carlo
  jitter of the final iterate.
* **Exposure.** ``exposure="fit"`` compares ``s * image`` with the reference, where ``s`` is the
  least-squares scale ``<image, ref> / <image, image>`` (detached) recomputed every iteration:
  the fit becomes insensitive to a global exposure difference (the scale is reported in stops).

Example::

    >>> import draaw_mi
    >>> scene = draaw_mi.load_scene("scenes/material_spheres.toml", resolution=(32, 32))
    >>> ref = draaw_mi.render(scene, version="path", spp=64)
    >>> res = draaw_mi.fit(scene, ref, params=["r1m1.roughness"], iterations=3, spp=4,
    ...                    progress=False)                                  # doctest: +SKIP
    >>> sorted(res.values)                                                  # doctest: +SKIP
    ['r1m1.roughness']
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from .errors import DraawError, ParameterError
from .scene import DraawScene, load_scene

LOSSES = ("l2", "l1", "relative_l2")
# parameter name suffix -> (low, high) projection range
RANGES = {
    "roughness": (0.0, 1.0), "metallic": (0.0, 1.0), "specular": (0.0, 1.0),
    "reflection": (0.0, 1.0), "direct_to_scatter": (0.0, 1.0), "base_color": (0.0, 1.0),
    "reflectance": (0.0, 1.0), "alpha": (1e-3, 1.0), "radiance": (0.0, None), "intensity": (0.0, None),
}


@dataclass
class FitResult:
    """What :func:`fit` returns.

    ``values``: fitted value per parameter (float, or list for colours); ``history``: one dict
    per iteration (``loss`` and every parameter's value); ``image``: the final render of the
    first view (numpy, post chain applied); ``converged``: whether the loss stopped improving
    (relative change of the smoothed loss below ``tol``); ``exposure_stops``: the fitted
    exposure (0 unless ``exposure="fit"``).
    """

    values: dict
    history: list = field(default_factory=list)
    image: np.ndarray | None = None
    converged: bool = False
    iterations: int = 0
    seconds: float = 0.0
    kernel_compiles: int = 0          # JIT kernels compiled after the first iteration (0 = none)
    exposure_stops: float = 0.0

    @property
    def losses(self) -> np.ndarray:
        return np.array([h["loss"] for h in self.history])

    def plot(self, path: str | None = None):
        """Loss (log scale) and parameter values over iterations; saved to ``path`` if given."""
        import matplotlib
        if path is not None:
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
        a.semilogy(self.losses)
        a.set_xlabel("iteration")
        a.set_ylabel("loss")
        a.set_title("loss")
        for name in self.values:
            v = np.array([h["values"][name] for h in self.history], dtype=float)
            if v.ndim == 1:
                b.plot(v, label=name)
            else:
                for c in range(v.shape[1]):
                    b.plot(v[:, c], label=f"{name}[{c}]")
        b.set_xlabel("iteration")
        b.set_title("parameters")
        b.legend(fontsize=8)
        fig.tight_layout()
        if path is not None:
            from .io import atomic_path
            with atomic_path(path, ".png") as tmp:
                fig.savefig(tmp, dpi=100, format="png")
            plt.close(fig)
        return fig


def _range_for(key: str):
    parts = key.split(".")
    for p in reversed(parts):
        if p in RANGES:
            return RANGES[p]
    return (None, None)


def load_reference(ref) -> np.ndarray:
    """An (H, W, 3) linear float32 reference from an EXR/PNG path or an array/tensor."""
    from .io import read_exr, to_numpy
    if isinstance(ref, str):
        if ref.lower().endswith(".exr"):
            arr = read_exr(ref)
        elif ref.lower().endswith((".png", ".jpg", ".jpeg")):
            import matplotlib.image
            try:
                arr = matplotlib.image.imread(ref).astype(np.float32)
            except Exception as e:  # noqa: BLE001
                raise DraawError(f"fit: cannot read reference {ref!r}: {e}") from None
            if arr.dtype != np.float32 or arr.max() > 1.0:
                arr = arr / 255.0
            arr = np.where(arr <= 0.04045, arr / 12.92, ((arr + 0.055) / 1.055) ** 2.4)  # sRGB -> linear
        else:
            raise DraawError(f"fit: reference {ref!r} must be an .exr or .png file")
    else:
        arr = to_numpy(ref)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.shape[2] == 1:
        arr = np.repeat(arr, 3, axis=2)
    arr = arr[..., :3].astype(np.float32)
    if not np.all(np.isfinite(arr)):
        raise DraawError("fit: a reference image contains NaN or Inf")
    return arr


def _views(scene: DraawScene, views):
    """Sensors for each view: the scene's own camera, or camera tables as in [camera]."""
    if views is None:
        return [scene.mi_scene.sensors()[0]]
    from .scene.camera import camera_to_look_at, sensor_dict
    from .scene.schema import Where
    if not isinstance(views, (list, tuple)) or not views:
        raise DraawError("fit: views must be a non-empty list of camera tables or mi.Sensor objects")
    w, h = scene.resolution
    out = []
    for i, v in enumerate(views):
        if isinstance(v, mi.Sensor):
            out.append(v)
            continue
        look = camera_to_look_at(v, Where("fit") / "views" / i)
        out.append(mi.load_dict(sensor_dict(look, w, h, scene.settings["spp"], scene.settings["filter"])))
    return out


def _loss(img, ref, kind: str, exposure: str):
    scale = mi.Float(1.0)
    if exposure == "fit":
        num = dr.sum(dr.detach(img.array) * ref.array)
        den = dr.sum(dr.square(dr.detach(img.array)))
        scale = dr.detach(dr.select(den > 0, num / dr.select(den > 0, den, 1.0), 1.0))
    d = img.array * scale - ref.array
    if kind == "l2":
        return dr.mean(dr.square(d)), scale
    if kind == "l1":
        return dr.mean(dr.abs(d)), scale
    return dr.mean(dr.square(d) / (dr.square(ref.array) + 1e-2)), scale


def fit(scene, references, params, version: str = "v4", spp: int = 16, iterations: int = 100,
        lr: float = 0.03, loss: str = "l2", views=None, post=None, progress: bool = True,
        seed: int = 0, exposure: str = "fixed", init: dict | None = None, max_depth: int | None = None,
        average_last: float = 0.25, tol: float = 5e-3, resolution=None, lr_final: float = 0.1) -> FitResult:
    """Fit ``params`` of ``scene`` so that its renders match ``references``.

    Parameters
    ----------
    scene: a DraawScene, scene file or description dict.
    references: one reference per view: an EXR/PNG path, an (H, W, 3) array or tensor (linear).
    params: names as ``material.parameter`` (``"gold.roughness"``) or full ``mi.traverse`` keys.
    version: integrator (``v1``..``v4``, ``prb``); must be differentiable.
    spp, iterations, lr: samples per pixel per iteration (a power of two avoids recompiles),
        Adam iterations and learning rate.
    loss: ``"l2"``, ``"l1"`` or ``"relative_l2"``.
    views: None (the scene's camera) or a list of camera tables / mi.Sensor, one per reference.
    post: a post-processing chain (list of dicts) applied to each render inside the loss.
    exposure: ``"fixed"`` or ``"fit"`` (see the module docstring).
    init: starting values by parameter name (e.g. ``{"gold.roughness": 0.5}``).
    lr_final: the learning rate decays along a cosine from ``lr`` to ``lr * lr_final``.
    """
    from .render import make_integrator

    t0 = time.perf_counter()
    if loss not in LOSSES:
        raise ParameterError(f"fit: loss={loss!r}; expected one of {', '.join(LOSSES)}")
    if exposure not in ("fixed", "fit"):
        raise ParameterError(f"fit: exposure={exposure!r}; expected 'fixed' or 'fit'")
    for name, value, lo in (("spp", spp, 1), ("iterations", iterations, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < lo:
            raise ParameterError(f"fit: {name}={value!r}; expected an integer >= {lo}")
    if not (isinstance(lr, (int, float)) and lr > 0):
        raise ParameterError(f"fit: lr={lr!r}; expected a positive number")
    if isinstance(params, str):
        params = [params]
    if not params:
        raise ParameterError("fit: params is empty; name at least one parameter, e.g. 'mat.roughness'")
    if not isinstance(scene, DraawScene):
        scene = load_scene(scene)
    refs = [load_reference(r) for r in (references if isinstance(references, (list, tuple)) else [references])]
    h, w = refs[0].shape[:2]
    if any(r.shape != refs[0].shape for r in refs):
        raise DraawError(f"fit: references differ in shape: {[r.shape for r in refs]}")
    if resolution is not None or scene.resolution != (w, h):
        if resolution is not None and tuple(resolution) != (w, h):
            raise DraawError(f"fit: resolution {tuple(resolution)} differs from the references' {w}x{h}")
        scene = scene.with_resolution(w, h)
    sensors = _views(scene, views)
    if len(sensors) != len(refs):
        raise DraawError(f"fit: {len(refs)} reference(s) for {len(sensors)} view(s); give one per view")
    integrator = make_integrator(version, scene.settings["max_depth"] if max_depth is None else max_depth)
    if not isinstance(integrator, mi.ad.integrators.common.ADIntegrator):
        raise DraawError(f"fit: version {version!r} is not differentiable; use v1..v4 or 'prb'")

    p = scene.params
    keys = [scene.key(name) for name in params]
    names = dict(zip(keys, params))
    ref_t = [mi.TensorXf(r) for r in refs]
    opt = mi.ad.Adam(lr=lr)
    for k in keys:
        if not dr.is_diff_v(p[k]) or not dr.is_float_v(p[k]):
            raise DraawError(f"fit: parameter {names[k]!r} ({k}) is not differentiable")
        value = p[k]
        if init and names[k] in init:
            value = type(p[k])(init[names[k]])
        lo, hi = _range_for(k)
        opt[k] = dr.clip(value, lo if lo is not None else -np.inf, hi if hi is not None else np.inf)
    p.update(opt)

    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=iterations, desc="fit", unit="it")
    history: list = []
    scale = mi.Float(1.0)
    compiles = 0
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    img = None
    try:
        for it in range(iterations):
            frac = it / max(iterations - 1, 1)
            opt.set_learning_rate(lr * (lr_final + (1.0 - lr_final) * 0.5 * (1.0 + np.cos(np.pi * frac))))
            total = mi.Float(0.0)
            for v, (sensor, ref) in enumerate(zip(sensors, ref_t)):
                img = mi.render(scene.mi_scene, p, sensor=sensor, integrator=integrator,
                                seed=(seed * 7919 + it * len(sensors) + v) & 0xFFFFFFFF, spp=spp)
                img = img[:, :, :3] if img.shape[2] > 3 else img
                if post:
                    from . import post as post_mod
                    img = post_mod.apply(img, post)
                lv, sv = _loss(img, ref, loss, exposure)
                if v == 0:
                    scale = sv
                lv = lv / len(sensors)
                dr.backward(lv)
                total += dr.detach(lv)
            for k in keys:
                g = dr.grad(opt[k])
                dr.set_grad(opt[k], dr.select(dr.isfinite(g), g, 0.0))
            opt.step()
            for k in keys:
                lo, hi = _range_for(k)
                opt[k] = dr.clip(opt[k], lo if lo is not None else -np.inf, hi if hi is not None else np.inf)
            p.update(opt)
            loss_value = float(total[0])
            values = {names[k]: _scalar(opt[k]) for k in keys}
            new = sum(1 for kk in dr.kernel_history() if kk["type"] == dr.KernelType.JIT and not kk["cache_hit"])
            history.append({"iteration": it, "loss": loss_value, "values": values, "kernel_compiles": new})
            if it > 0:
                compiles += new
            if bar is not None:
                bar.update(1)
                bar.set_postfix(loss=f"{loss_value:.3g}", **{n.split(".")[-1][:5]: _short(v) for n, v in values.items()})
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        if bar is not None:
            bar.close()

    n_avg = max(1, int(round(iterations * average_last)))
    fitted = {}
    for k in keys:
        vals = np.array([h["values"][names[k]] for h in history[-n_avg:]], dtype=float)
        lo, hi = _range_for(k)
        mean = np.clip(vals.mean(axis=0), lo if lo is not None else -np.inf, hi if hi is not None else np.inf)
        fitted[names[k]] = mean.tolist() if mean.ndim else float(mean)
        p[k] = type(p[k])(fitted[names[k]]) if mean.ndim == 0 else type(p[k])(mean.tolist())
    p.update()
    final = np.array(mi.render(scene.mi_scene, sensor=sensors[0], integrator=integrator, seed=seed + 12345, spp=spp))
    converged = _converged(history, tol)
    return FitResult(values=fitted, history=history, image=final[..., :3], converged=converged,
                     iterations=iterations, seconds=time.perf_counter() - t0, kernel_compiles=compiles,
                     exposure_stops=float(np.log2(max(float(scale[0]), 1e-30))) if exposure == "fit" else 0.0)


def _scalar(v):
    a = np.array(v).ravel()
    return float(a[0]) if a.size == 1 else a.tolist()


def _short(v):
    return f"{v:.3f}" if isinstance(v, float) else "[" + ",".join(f"{x:.2f}" for x in v) + "]"


def _converged(history: list, tol: float) -> bool:
    """True when every parameter's mean over the last eighth of the run differs from its mean
    over the eighth before by less than ``tol`` (absolute; parameters live in [0, 1]), and the
    loss is finite. Noise-robust: it looks at averaged iterates, not the last step."""
    n = len(history)
    q = max(1, n // 8)
    if n < 16:
        return False
    if not np.isfinite(history[-1]["loss"]):
        return False
    for name in history[-1]["values"]:
        v = np.array([h["values"][name] for h in history], dtype=float)
        if np.any(np.abs(v[-q:].mean(axis=0) - v[-2 * q:-q].mean(axis=0)) > tol):
            return False
    return True
