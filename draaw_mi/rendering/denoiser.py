"""``draaw_mi.denoise``: Intel Open Image Denoise (CPU) on rendered images.

Wraps the ``pyoidn`` binding (optional dependency: ``pip install 'draaw-mi[denoise]'``) with
draaw-mi's conventions: (H, W, 3|4) images as ``mi.TensorXf`` or numpy arrays, linear HDR
radiance, shape checks that name the argument, and the albedo / normal AOVs of the draaw
integrators as auxiliary images.

A denoised image is **biased** (a learned filter, not an estimator of the radiance); it is not
differentiable. It trades a little bias for a large drop in variance, which is what a preview
(:mod:`draaw_mi.rendering.preview`) or a low-spp point of the accuracy-time study wants.

=================  ===========================================================================
Parameter          Meaning
=================  ===========================================================================
``image``          (H, W, 3) or (H, W, 4) linear radiance; alpha passes through unchanged
``albedo``         optional (H, W, 3) first-hit albedo in [0, 1] (the ``albedo`` AOV)
``normal``         optional (H, W, 3) shading normal in [-1, 1] (the ``normal`` AOV); needs
                   ``albedo`` too (OIDN's rule)
``hdr``            True (default): radiance may exceed 1; False for display-referred input
``quality``        ``"high"`` (default), ``"balanced"`` or ``"fast"``
``clean_aux``      True when ``albedo`` / ``normal`` are noise-free (many-spp AOVs)
=================  ===========================================================================

The result has the input's shape, and its type where it is a numpy array (numpy in, numpy
out); any other input (a tensor, nested lists) gives an ``mi.TensorXf``. Non-finite input values are replaced by 0 before denoising (OIDN would spread them).

Example (skipped when ``pyoidn`` is missing)::

    >>> import numpy as np, draaw_mi
    >>> noisy = np.random.default_rng(0).random((32, 32, 3), dtype=np.float32)
    >>> draaw_mi.denoise(noisy).shape               # doctest: +SKIP
    (32, 32, 3)

From a render with AOVs::

    from draaw_mi.rendering.denoiser import denoise_aovs
    img, info = draaw_mi.render(scene, spp=4, aovs=["albedo", "normal"], return_info=True)
    clean = denoise_aovs(img, info["channels"])                 # colour denoised, AOVs kept
"""
from __future__ import annotations

import warnings

import mitsuba as mi
import numpy as np

from ..errors import DraawError, ParameterError

INSTALL_HINT = "pip install 'draaw-mi[denoise]' (or: pip install pyoidn)"
QUALITIES = ("high", "balanced", "fast")
AUX_AOVS = ("albedo", "normal")


class DenoiserMissing(DraawError, ImportError):
    """The optional ``pyoidn`` package is not installed."""


def available() -> bool:
    """Whether ``pyoidn`` can be imported (the denoiser is usable)."""
    try:
        load_pyoidn()
    except DenoiserMissing:
        return False
    return True


def load_pyoidn():
    try:
        import pyoidn
    except Exception as e:  # noqa: BLE001 - ImportError, or a broken native library (OSError)
        raise DenoiserMissing(f"draaw_mi.rendering.denoiser needs the optional package pyoidn ({type(e).__name__}: "
                              f"{e}); install it with: {INSTALL_HINT}") from None
    return pyoidn


#: the smallest side OIDN sees: a smaller image is padded out to it (see :func:`denoise`)
MIN_SIDE = 16


def _as_array(x, name: str, shape=None, channels=(3,)) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=np.float32)
    except (TypeError, ValueError) as e:
        raise ParameterError(f"denoise: {name} is not an image ({type(x).__name__}: {e})") from None
    if arr.ndim != 3 or arr.shape[2] not in channels or min(arr.shape[:2]) < 1:
        want = " or ".join(f"(H, W, {c})" for c in channels)
        raise ParameterError(f"denoise: {name} has shape {arr.shape}; expected {want}")
    if shape is not None and arr.shape[:2] != shape:
        raise ParameterError(f"denoise: {name} has shape {arr.shape}; expected the image's size "
                             f"{shape[0]}x{shape[1]} (H x W) with 3 channels")
    return np.ascontiguousarray(np.nan_to_num(arr, nan=0.0, posinf=0.0, neginf=0.0))


def denoise(image, albedo=None, normal=None, *, hdr: bool = True, quality: str = "high",
            clean_aux: bool = False):
    """Denoise ``image`` with Intel OIDN (see the module docstring for the parameter table)."""
    if quality not in QUALITIES:
        raise ParameterError(f"denoise: quality={quality!r}; expected one of {', '.join(QUALITIES)}")
    for flag, value in (("hdr", hdr), ("clean_aux", clean_aux)):
        if not isinstance(value, (bool, np.bool_)):
            raise ParameterError(f"denoise: {flag}={value!r}; expected True or False")
    if normal is not None and albedo is None:
        raise ParameterError("denoise: normal given without albedo; OIDN uses the normal only "
                             "together with the albedo (pass both, or neither)")
    is_tensor = not isinstance(image, np.ndarray)
    arr = _as_array(image, "image", channels=(3, 4))
    hw = arr.shape[:2]
    aux = {}
    if albedo is not None:
        aux["albedo"] = np.clip(_as_array(albedo, "albedo", hw), 0.0, 1.0)
    if normal is not None:
        aux["normal"] = np.clip(_as_array(normal, "normal", hw), -1.0, 1.0)
    oidn = load_pyoidn()
    color = np.ascontiguousarray(np.maximum(arr[..., :3], 0.0) if hdr else arr[..., :3])
    # OIDN darkens images a few pixels across (a constant 1.0: 0.19 at 1x1, 0.74 at 2x2, 0.95
    # at 3x3): such an image goes in with its edge pixels repeated out to MIN_SIDE, and comes
    # back cut to its own size (0.99-1.02 then)
    pad = [((MIN_SIDE - n) // 2, MIN_SIDE - n - (MIN_SIDE - n) // 2) if n < MIN_SIDE else (0, 0) for n in hw]
    if any(sum(p) for p in pad):
        grow = lambda a: None if a is None else np.pad(a, pad + [(0, 0)], mode="edge")   # noqa: E731
        color, aux = grow(color), {k: grow(v) for k, v in aux.items()}
    out = oidn.denoise(color, aux.get("albedo"), aux.get("normal"), hdr=hdr, clean_aux=clean_aux,
                       quality=quality)
    out = np.asarray(out, dtype=np.float32)[pad[0][0]:pad[0][0] + hw[0], pad[1][0]:pad[1][0] + hw[1]]
    out = np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)
    if arr.shape[2] == 4:
        out = np.concatenate([out, arr[..., 3:]], axis=2)
    if is_tensor:
        return mi.TensorXf(out)
    return out


def aux_channels(channels) -> dict:
    """Indices of the albedo and normal AOV channels in a render's channel list.

    Channels are found by name, in R, G, B (X, Y, Z) order whatever order the list has
    (``read_exr`` lists an EXR's other channels sorted: ``albedo.B`` before ``albedo.R``).

    >>> aux_channels(["R", "G", "B", "N.X", "N.Y", "N.Z", "albedo.R", "albedo.G", "albedo.B"])
    {'albedo': [6, 7, 8], 'normal': [3, 4, 5]}
    >>> aux_channels(["R", "G", "B", "albedo.B", "albedo.G", "albedo.R"])
    {'albedo': [5, 4, 3]}
    """
    names = list(channels)
    out = {}
    for key, wanted in (("albedo", ("albedo.R", "albedo.G", "albedo.B")), ("normal", ("N.X", "N.Y", "N.Z"))):
        if all(n in names for n in wanted):
            out[key] = [names.index(n) for n in wanted]
    return out


def denoise_aovs(image, channels, **kwargs):
    """Denoise the colour of an (H, W, C) render whose ``channels`` may include the albedo and
    normal AOVs (used as auxiliary images); every AOV channel is returned unchanged."""
    is_tensor = not isinstance(image, np.ndarray)
    arr = np.asarray(image, dtype=np.float32)
    names = list(channels)
    if arr.ndim != 3 or arr.shape[2] != len(names):
        raise ParameterError(f"denoise_aovs: image of shape {arr.shape} with {len(names)} channel names")
    n_color = 4 if names[3:4] == ["A"] else 3
    idx = aux_channels(names)
    albedo = arr[..., idx["albedo"]] if "albedo" in idx else None
    normal = arr[..., idx["normal"]] if ("normal" in idx and albedo is not None) else None
    if "normal" in idx and albedo is None:
        warnings.warn("denoise_aovs: the normal AOV guides OIDN only with an albedo AOV (render "
                      "with aovs=['albedo', 'normal']); denoising without guides", stacklevel=2)
    color = denoise(arr[..., :n_color], albedo, normal, **kwargs)
    out = np.concatenate([color, arr[..., n_color:]], axis=2)
    if is_tensor:
        return mi.TensorXf(out)
    return out


class Denoiser:
    """Callable form of :func:`denoise` with fixed options (kornia style).

    >>> Denoiser(quality="fast").quality
    'fast'
    """
    def __init__(self, hdr: bool = True, quality: str = "high", clean_aux: bool = False):
        if quality not in QUALITIES:
            raise ParameterError(f"Denoiser: quality={quality!r}; expected one of {', '.join(QUALITIES)}")
        for flag, value in (("hdr", hdr), ("clean_aux", clean_aux)):
            if not isinstance(value, (bool, np.bool_)):
                raise ParameterError(f"Denoiser: {flag}={value!r}; expected True or False")
        self.hdr, self.quality, self.clean_aux = hdr, quality, clean_aux

    def __call__(self, image, albedo=None, normal=None):
        return denoise(image, albedo, normal, hdr=self.hdr, quality=self.quality, clean_aux=self.clean_aux)

    def __repr__(self):
        return f"Denoiser(hdr={self.hdr}, quality={self.quality!r}, clean_aux={self.clean_aux})"
