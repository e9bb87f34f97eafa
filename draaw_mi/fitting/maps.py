"""How :func:`draaw_mi.fit` moves a texture (a map of base colour, roughness, metallic, ...):
a multi-scale latent that keeps every texel in range, a smoothness prior, and which texels
the captures observed.

A texture ``T`` of ``H x W`` texels and ``C`` channels in the range ``[lo, hi]`` is

    T = lo + (hi - lo) * sigmoid(z),    z = sum_l  U_l(z_l)

where ``z_0`` is a coarse grid (4 texels on its short side), each further level doubles the
resolution up to ``H x W``, and ``U_l`` upsamples level ``l`` bilinearly to ``H x W``
(a Laplacian-pyramid parametrisation). Why each part:

* **The sigmoid** keeps texels inside ``[lo, hi]`` without a projection: a projected texel
  that noise pushes onto a bound stops there (its gradient is cut), which is how texel-by-texel
  fits end with maps of 0s and 1s.
* **The pyramid**: a coarse latent sums the gradients of every texel it covers, so the broad
  shape of a map is fitted first and with little noise, and texels seen by few pixels take
  their neighbours' values until their own evidence says otherwise (coarse-to-fine, without
  restarts).
* **Adam per latent, on every level**: the coarse levels' steps come from gradients summed
  over many texels (little noise), the finest level's from one texel's. (A second moment
  pooled per level let the few texels under a highlight take steps many times ``lr``:
  measured on the benchmark's sphere it left spots of 0 and 1.)
* **A learning rate per map** (``lr_scale``): a metallic map's latents take steps
  :data:`LR_SCALES` times the others'. Metallic is near 0 or 1 in real materials (its texels
  end at logits of +-3 to +-9, colour and roughness mostly inside +-2), so its latents travel
  farther; at the maps' common rate the metal patches were still at 0.3-0.8 after 1,200
  steps.
* **Total variation** (``tv``, in value units per texel, Huber-smoothed): a prior that keeps
  flat regions flat and sharp edges sharp (metallic patches), weighed against the image loss.
  On by default for the principled material's ``roughness`` maps only (:data:`TV_WEIGHTS`;
  ``alpha`` maps of Mitsuba's rough BSDFs have none): a texel's roughness shows only
  while a highlight covers it, so between highlights the images leave it to noise, and that
  noise, through the texel's colour and metallic, also opens the way to false metal.
* **Visibility**: a texel is *observed* when any capture's gradient reached it. Unobserved
  texels are reported and, at the end, filled from observed neighbours (:func:`fill_unobserved`)
  rather than left at whatever the coarse levels made of them.

>>> import numpy as np
>>> m = MapLatent(np.full((8, 8, 1), 0.25), lo=0.0, hi=1.0)
>>> bool(np.allclose(m.value(), 0.25))
True
>>> [lv.shape[:2] for lv in m.levels]
[(4, 4), (8, 8)]
"""
from __future__ import annotations

import numbers
from dataclasses import dataclass

import drjit as dr
import numpy as np

from ..errors import ParameterError
from ..rendering.frozen import owned_tensor

#: short side of the coarsest level
COARSEST = 4
#: Huber width of the total-variation prior (value units): below it the prior is quadratic
TV_DELTA = 0.02
#: latents are clamped to +-LOGIT_MAX (sigmoid 1e-4 from the bounds): a gradient that keeps
#: pushing a texel at its bound does not grow the latent without limit; one that pulls it
#: back inside passes
LOGIT_MAX = 9.0


def upsample_matrix(n_out: int, n_in: int) -> np.ndarray:
    """``(n_out, n_in)`` bilinear interpolation on texel centres, edges clamped.

    >>> upsample_matrix(4, 2).round(3).tolist()
    [[1.0, 0.0], [0.75, 0.25], [0.25, 0.75], [0.0, 1.0]]
    """
    a = np.zeros((n_out, n_in))
    x = (np.arange(n_out) + 0.5) * n_in / n_out - 0.5
    j0 = np.floor(x).astype(int)
    t = x - j0
    for j, w in ((j0, 1.0 - t), (j0 + 1, t)):
        np.add.at(a, (np.arange(n_out), np.clip(j, 0, n_in - 1)), w)
    return a


def pyramid_sizes(h: int, w: int, coarsest: int = COARSEST) -> list:
    """Level sizes from coarse to fine: each halves the next (rounded up) while the short side
    stays at least ``coarsest`` texels (a texture smaller than twice that has one level).

    >>> pyramid_sizes(64, 64)
    [(4, 4), (8, 8), (16, 16), (32, 32), (64, 64)]
    >>> pyramid_sizes(6, 12), pyramid_sizes(8, 12)
    ([(6, 12)], [(4, 6), (8, 12)])
    """
    sizes = [(h, w)]
    while min(sizes[-1]) // 2 >= coarsest:
        hh, ww = sizes[-1]
        sizes.append(((hh + 1) // 2, (ww + 1) // 2))
    return sizes[::-1]


def _separable(ay: np.ndarray, x: np.ndarray, ax: np.ndarray) -> np.ndarray:
    """``ay @ x[..., c] @ ax.T`` for every channel ``c`` of ``x`` (H, W, C): two matrix
    products through BLAS (``tensordot``; two-operand ``einsum`` calls loop in C without it:
    11-21x slower from a 4x4 to a 64x64 level of a 64x64 map; a three-operand one sums over all
    index combinations at once).

    >>> ay, ax = upsample_matrix(4, 2), upsample_matrix(6, 3)
    >>> x = np.arange(12.0).reshape(2, 3, 2)
    >>> bool(np.allclose(_separable(ay, x, ax), np.einsum("ij,jkc,lk->ilc", ay, x, ax)))
    True
    """
    if ay.shape[0] == ay.shape[1] and ax.shape[0] == ax.shape[1]:
        return x                    # the finest level: both matrices are identities (O(n^3) a product)
    return np.moveaxis(np.tensordot(np.tensordot(ay, x, axes=(1, 0)), ax, axes=(1, 1)), 2, 1)


def _logit(p):
    p = np.clip(p, 1e-4, 1 - 1e-4)
    return np.log(p / (1 - p))


def _sigmoid(z):
    return 0.5 * (1.0 + np.tanh(0.5 * z))


class MapLatent:
    """One texture as a pyramid of latents (see the module docstring), with its own Adam.

    Args:
        start: the starting texels, ``(H, W, C)`` inside ``[lo, hi]``.
        lo, hi: the range (``hi=None``: ``[lo, lo + 1]`` scaled to the start's maximum; colours).
        multiscale: False gives a single level (texel-by-texel, still in range by the sigmoid).
        tv: weight of the total-variation prior (0: none).
        beta_1, beta_2: Adam's decays.
    """

    def __init__(self, start, lo: float = 0.0, hi: float | None = 1.0, *, multiscale: bool = True,
                 tv: float = 0.0, beta_1: float = 0.9, beta_2: float = 0.99, name: str = "texture"):
        start = np.asarray(start, dtype=np.float64)
        if start.ndim != 3:
            raise ParameterError(f"MapLatent: {name} has shape {start.shape}; expected (H, W, C)")
        if not np.all(np.isfinite(start)):
            raise ParameterError(f"MapLatent: {name} has non-finite texels")
        if hi is None:                        # an unbounded colour: room up to twice its start
            hi = max(1.0, 2.0 * float(start.max()))
        if not hi > lo:
            raise ParameterError(f"MapLatent: {name}'s range [{lo}, {hi}] is empty")
        self.name, self.lo, self.hi, self.tv = name, float(lo), float(hi), float(tv)
        self.shape = start.shape
        h, w, c = start.shape
        sizes = pyramid_sizes(h, w) if multiscale else [(h, w)]
        self.ups = [(upsample_matrix(h, hh), upsample_matrix(w, ww)) for hh, ww in sizes]
        z = _logit((start - self.lo) / (self.hi - self.lo))
        # the start's mean per channel in the coarsest level, the rest in the finest
        self.levels = [np.zeros((hh, ww, c)) for hh, ww in sizes]
        mean = z.mean(axis=(0, 1))
        self.levels[0][:] = mean
        if len(self.levels) > 1:
            self.levels[-1][:] = z - mean
        else:
            self.levels[0][:] = z
        self.beta_1, self.beta_2 = beta_1, beta_2
        self.m = [np.zeros_like(lv) for lv in self.levels]
        self.v = [np.zeros_like(lv) for lv in self.levels]
        self.t = 0
        self.seen = np.zeros((h, w), dtype=bool)       # texels any gradient reached

    # ------------------------------------------------------------------ value and gradient
    def latent(self) -> np.ndarray:
        """The summed levels ``z`` (H, W, C), clamped to +-LOGIT_MAX."""
        z = np.zeros(self.shape)
        for (ay, ax), lv in zip(self.ups, self.levels):
            z += _separable(ay, lv, ax)
        return np.clip(z, -LOGIT_MAX, LOGIT_MAX)

    def value(self, dtype=np.float32) -> np.ndarray:
        """The texels, ``(H, W, C)`` in ``[lo, hi]`` (float32: what the scene's texture holds)."""
        return (self.lo + (self.hi - self.lo) * _sigmoid(self.latent())).astype(dtype)

    def prior(self, value: np.ndarray | None = None) -> tuple:
        """``(TV energy, its gradient in value space)``: the mean over texel pairs of a Huber
        norm of neighbour differences, times ``tv``."""
        t = self.value().astype(np.float64) if value is None else value
        grad = np.zeros_like(t)
        energy = 0.0
        for axis in (0, 1):
            d = np.diff(t, axis=axis)
            if d.size == 0:
                continue
            a = np.abs(d)
            quad = a < TV_DELTA
            energy += float(np.where(quad, 0.5 * d * d / TV_DELTA, a - 0.5 * TV_DELTA).sum())
            g = np.where(quad, d / TV_DELTA, np.sign(d))
            pad = [(0, 0)] * 3
            pad[axis] = (1, 0)
            gp = np.pad(g, pad)
            pad[axis] = (0, 1)
            gn = np.pad(g, pad)
            grad += gp - gn                        # d/dt_i of |t_i - t_{i-1}| and |t_{i+1} - t_i|
        n = t.size
        return self.tv * energy / n, self.tv * grad / n

    def gradients(self, grad_value: np.ndarray) -> list:
        """The gradient of ``loss + prior`` with respect to each level's latents, from the loss
        gradient with respect to the texels (``(H, W, C)``; NaN/Inf entries count as 0)."""
        g = np.nan_to_num(np.asarray(grad_value, dtype=np.float64).reshape(self.shape),
                          nan=0.0, posinf=0.0, neginf=0.0)
        z = self.latent()
        s = _sigmoid(z)
        if self.tv > 0:
            g = g + self.prior(self.lo + (self.hi - self.lo) * s)[1]
        # a latent clamped at +-LOGIT_MAX passes only a gradient that moves it back inside: a
        # texel that starts at a bound (metallic 0, the material's default) or reaches one can
        # leave it when the images ask
        inside = (np.abs(z) < LOGIT_MAX) | (np.sign(z) * g > 0)
        gz = g * (self.hi - self.lo) * s * (1 - s) * inside
        return [_separable(ay.T, gz, ax.T) for ay, ax in self.ups]      # U_l^T gz

    def step(self, grad_value: np.ndarray, lr: float) -> None:
        """One Adam step from the loss gradient with respect to the texels (``(H, W, C)``)."""
        finite = np.nan_to_num(np.asarray(grad_value, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
        self.seen |= np.any(finite.reshape(self.shape) != 0, axis=2)
        self.t += 1
        for i, gl in enumerate(self.gradients(finite)):
            self.m[i] = self.beta_1 * self.m[i] + (1 - self.beta_1) * gl
            self.v[i] = self.beta_2 * self.v[i] + (1 - self.beta_2) * gl * gl
            m_hat = self.m[i] / (1 - self.beta_1 ** self.t)
            v_hat = self.v[i] / (1 - self.beta_2 ** self.t)
            self.levels[i] -= lr * m_hat / (np.sqrt(v_hat) + 1e-12)
            np.clip(self.levels[i], -2 * LOGIT_MAX, 2 * LOGIT_MAX, out=self.levels[i])


def fill_unobserved(value: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """``value`` with the texels outside ``seen`` replaced by a smooth continuation of the seen
    ones (pull-push: averages of seen texels over ever coarser blocks, pushed back down). With
    nothing seen the value is returned as it is.

    >>> v = np.zeros((4, 4, 1)); v[:, :2] = 1.0
    >>> seen = np.zeros((4, 4), bool); seen[:, :2] = True
    >>> fill_unobserved(v, seen)[:, 2:, 0].tolist()
    [[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0]]
    """
    if seen.all() or not seen.any():
        return value
    w = seen.astype(np.float64)[..., None]
    levels = [(value * w, w)]
    while min(levels[-1][1].shape[:2]) > 1:
        vw, ww = levels[-1]
        h, wd = vw.shape[:2]
        hh, w2 = (h + 1) // 2, (wd + 1) // 2
        pad = ((0, 2 * hh - h), (0, 2 * w2 - wd), (0, 0))
        vw = np.pad(vw, pad).reshape(hh, 2, w2, 2, -1).sum(axis=(1, 3))
        ww = np.pad(ww, pad).reshape(hh, 2, w2, 2, -1).sum(axis=(1, 3))
        levels.append((vw, ww))
    filled = levels[-1][0] / np.maximum(levels[-1][1], 1e-12)
    for vw, ww in reversed(levels[:-1]):
        h, wd = vw.shape[:2]
        up = np.repeat(np.repeat(filled, 2, axis=0), 2, axis=1)[:h, :wd]
        own = vw / np.maximum(ww, 1e-12)
        filled = np.where(ww > 0, own, up)
    out = value.copy()
    out[~seen] = filled[~seen].astype(value.dtype)
    return out


#: each map's learning rate as a multiple of the maps' ``lr``, by its material parameter's name
#: (``fit(maps={"lr_scale": {...}})`` overrides it). Measured on the SVBRDF benchmark's tile
#: (16² maps, 64² images, 160 iterations, ``sweep`` + softboxes; albedo PSNR / roughness MAE /
#: metallic MAE): metallic x1 24.4 / 0.144 / 0.232, x3 27.7 / 0.116 / 0.129, x5 28.1 / 0.105 /
#: 0.101, x8 28.1 / 0.107 / 0.114, x12 26.6 / 0.116 / 0.153; roughness x2 (23.3 / 0.149 / 0.230)
#: and metallic x2 with colour x2 (22.8 / 0.141 / 0.191) did not help
#: (benchmarks/results/svbrdf_fit.md). The pyramid's maps only (``texels`` has one Adam).
LR_SCALES = {"metallic": 5.0}


def map_names(key: str) -> tuple:
    """The names ``lr_scale`` knows a map by, most specific first: its scene key, its fit name
    and its material parameter.

    >>> map_names("obj.metallic.data")
    ('obj.metallic.data', 'obj.metallic', 'metallic')
    """
    return key, key.removesuffix(".data"), material_parameter(key)


def material_parameter(key: str) -> str:
    """The material parameter a map's key names: ``"obj.metallic.data"`` -> ``"metallic"``.

    >>> material_parameter("obj.metallic.data"), material_parameter("floor.bsdf.roughness")
    ('metallic', 'roughness')
    """
    return key.removesuffix(".data").split(".")[-1]


#: each map's total-variation weight by its material parameter's name, where
#: ``fit(maps={"tv": ...})`` does not set it (no entry: no prior). Measured on the SVBRDF
#: benchmark's monkey (32² maps, 64² images, 240 iterations, ``sweep`` + softboxes; albedo
#: PSNR / roughness MAE / metallic MAE): no prior 25.9 / 0.076 / 0.060 (seed 1: 30.2 / 0.061 /
#: 0.032), roughness 0.001 27.1 / 0.052 / 0.056, **0.003** 30.2 / 0.035 / 0.032 (seed 1: 33.0
#: / 0.036 / 0.019), 0.01 29.8 / 0.066 / 0.032, 0.03 29.0 / 0.099 / 0.039
#: (benchmarks/results/svbrdf_fit.md). The pyramid's maps only (``texels`` has no prior).
TV_WEIGHTS = {"roughness": 0.003}


def _per_map(given: dict | None, defaults: dict, key: str) -> float | None:
    """The entry of ``given`` for the map with key ``key``, by the first of its
    :func:`map_names` that has one, else that of ``defaults``, else ``None``.

    >>> _per_map({"obj.roughness": 2.0}, {"roughness": 1.0}, "obj.roughness.data")
    2.0
    >>> _per_map(None, {"roughness": 1.0}, "obj.metallic.data") is None
    True
    """
    for table in (given or {}, defaults):
        for k in map_names(key):
            if k in table:
                return float(table[k])
    return None


#: what ``fit(maps=...)`` takes: "pyramid" (the default) or "texels" (each texel its own
#: coordinate of the fit's Adam, projected onto its range: the texel-by-texel fit)
PARAMETRISATIONS = ("pyramid", "texels")


@dataclass
class MapOptions:
    """``fit(maps=...)``: how texture parameters are fitted.

    * ``parametrisation``: ``"pyramid"`` (multi-scale, in range by a sigmoid; module docstring)
      or ``"texels"`` (every texel a coordinate of Adam, clipped to its range).
    * ``tv``: total-variation weight (value units; 0 = none): one number for every map, or
      ``{name: weight}`` per map, by the names ``lr_scale`` takes, over :data:`TV_WEIGHTS`
      (``None``, the default: :data:`TV_WEIGHTS` alone, a prior on roughness maps).
    * ``lr``: the maps' learning rate (in logit units; default the fit's ``lr``).
    * ``lr_scale``: ``{name: multiple of lr}`` per map of the pyramid, by its scene key
      (``"obj.metallic.data"``), its fit name (``"obj.metallic"``) or its material parameter
      (``"metallic"``), the first that has an entry; over :data:`LR_SCALES`
      (``{"metallic": 1.0}`` gives metallic the common rate).
    * ``fill``: texels no capture observed take their neighbours' values at the end.

    >>> o = MapOptions.parse({"lr_scale": {"obj.roughness": 2.0}})
    >>> o.scale_for("obj.metallic.data"), o.scale_for("obj.roughness.data"), o.scale_for("obj.base_color.data")
    (5.0, 2.0, 1.0)
    >>> o.tv_for("obj.roughness.data"), o.tv_for("obj.base_color.data")
    (0.003, 0.0)
    >>> MapOptions.parse({"tv": 0.0}).tv_for("obj.roughness.data")
    0.0
    """
    parametrisation: str = "pyramid"
    tv: float | dict | None = None
    lr: float | None = None
    fill: bool = True
    lr_scale: dict | None = None

    def scale_for(self, key: str) -> float:
        """The multiple of ``lr`` for the map with key ``key`` (``"obj.metallic.data"``): the
        ``lr_scale`` entry for its key, its fit name or its material parameter, else the
        :data:`LR_SCALES` entry for those, else 1."""
        scale = _per_map(self.lr_scale, LR_SCALES, key)
        return 1.0 if scale is None else scale

    def tv_for(self, key: str) -> float:
        """The total-variation weight of the map with key ``key``: ``tv`` where it is a number,
        else its entry (by the names :meth:`scale_for` uses) in ``tv`` or :data:`TV_WEIGHTS`,
        else 0; 0 for ``texels``, which has no prior."""
        if self.parametrisation != "pyramid":
            return 0.0
        if _is_number(self.tv):
            return float(self.tv)
        weight = _per_map(self.tv, TV_WEIGHTS, key)
        return 0.0 if weight is None else weight

    @classmethod
    def parse(cls, maps) -> MapOptions:
        if maps is None:
            return cls()
        if isinstance(maps, str):
            maps = {"parametrisation": maps}
        if not isinstance(maps, dict):
            raise ParameterError(f"fit: maps={maps!r}; expected a dict (parametrisation, tv, lr, lr_scale, "
                                 "fill) or one of 'pyramid', 'texels'")
        unknown = sorted(set(maps) - {"parametrisation", "tv", "lr", "lr_scale", "fill"})
        if unknown:
            raise ParameterError(f"fit: maps has the key(s) {', '.join(unknown)}; expected parametrisation, "
                                 "tv, lr, lr_scale, fill")
        o = cls(**maps)
        if o.parametrisation not in PARAMETRISATIONS:
            raise ParameterError(f"fit: maps parametrisation={o.parametrisation!r}; expected one of "
                                 f"{', '.join(PARAMETRISATIONS)}")
        if o.lr is not None and not (_is_number(o.lr) and np.isfinite(o.lr) and o.lr > 0):
            raise ParameterError(f"fit: maps lr={o.lr!r}; expected a finite number > 0")
        if _is_number(o.tv):
            if not (np.isfinite(o.tv) and o.tv >= 0):
                raise ParameterError(f"fit: maps tv={o.tv!r}; expected a finite number >= 0 or a dict "
                                     "{parameter name: weight >= 0}")
        elif o.tv is not None:
            _check_table("tv", o.tv, "{parameter name: weight} (or one finite number >= 0)",
                         lambda v: v >= 0, ">= 0")
        if o.lr_scale is not None:
            if o.parametrisation != "pyramid":
                raise ParameterError(f"fit: maps lr_scale={o.lr_scale!r} with parametrisation="
                                     f"{o.parametrisation!r}; expected it with 'pyramid' only (texels share "
                                     "the fit's Adam)")
            _check_table("lr_scale", o.lr_scale, "{parameter name: multiple of lr}", lambda v: v > 0, "> 0")
        weights = o.tv.values() if isinstance(o.tv, dict) else [o.tv or 0.0]
        if o.parametrisation != "pyramid" and any(w > 0 for w in weights):
            raise ParameterError(f"fit: maps tv={o.tv!r} with parametrisation={o.parametrisation!r}; expected "
                                 "it with 'pyramid' only (texels have no prior)")
        return o


def _is_number(v) -> bool:
    """A real number that is not a bool (NumPy's scalars included)."""
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _check_table(option: str, table, expected: str, ok, bound: str) -> None:
    """ParameterError unless ``table`` is a dict of parameter names to finite numbers ``ok``."""
    if not isinstance(table, dict):
        raise ParameterError(f"fit: maps {option}={table!r}; expected a dict {expected}")
    for k, v in table.items():
        if not isinstance(k, str) or not _is_number(v) or not (np.isfinite(v) and ok(v)):
            raise ParameterError(f"fit: maps {option}[{k!r}]={v!r}; expected a parameter name and a "
                                 f"finite number {bound}")


class MapSet:
    """The texture parameters of one fit: a :class:`MapLatent` each, the AD-attached tensor a
    render of the current capture reads, and the gradients summed over an iteration's
    captures."""

    def __init__(self, params: dict, options: MapOptions):
        """``params``: key -> ``(start (H, W, C), lo, hi)``."""
        self.options = options
        self.latents = {k: MapLatent(start, lo, hi, multiscale=True, tv=options.tv_for(k), name=k)
                        for k, (start, lo, hi) in params.items()}
        self.scales = {k: options.scale_for(k) for k in params}
        known = {n for k in params for n in map_names(k)}
        for option, table in (("lr_scale", options.lr_scale), ("tv", options.tv)):
            unknown = sorted(set(table if isinstance(table, dict) else ()) - known)
            if unknown and not params:           # (texels, or no texture among the parameters)
                raise ParameterError(f"fit: maps {option} names {', '.join(map(repr, unknown))}, but no "
                                     "texture is fitted as a map of the pyramid here")
            if unknown:
                raise ParameterError(f"fit: maps {option} names {', '.join(map(repr, unknown))}, which no "
                                     f"fitted map has; expected one of {', '.join(sorted(known))}")
        self.attached: dict = {}
        self.grads = {k: np.zeros(m.shape) for k, m in self.latents.items()}
        self._values: dict | None = None       # values() since the last step (read-only)

    def __bool__(self) -> bool:
        return bool(self.latents)

    def attach(self, p) -> None:
        """Set each texture in the scene parameters ``p`` as a tensor that tracks gradients."""
        for k, v in self.values().items():
            t = owned_tensor(v)
            dr.enable_grad(t)
            p[k] = t
            self.attached[k] = t

    def collect(self) -> None:
        """Add the gradients the last backward pass left on the attached tensors."""
        for k, t in self.attached.items():
            self.grads[k] += np.array(dr.grad(t), dtype=np.float64).reshape(self.grads[k].shape)
        self.attached = {}

    def step(self, lr: float) -> None:
        """One Adam step of every map, each at ``lr`` times its ``scale_for``."""
        for k, m in self.latents.items():
            m.step(self.grads[k], lr * self.scales[k])
            self.grads[k][:] = 0.0
        self._values = None

    def values(self) -> dict:
        """Each map's texels (float32, read-only), computed once per step: an iteration reads
        them for each capture it renders and for its history."""
        if self._values is None:
            self._values = {k: m.value() for k, m in self.latents.items()}
            for v in self._values.values():
                v.flags.writeable = False
        return self._values

    def seen(self, key: str) -> np.ndarray:
        return self.latents[key].seen
