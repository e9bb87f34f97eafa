"""draaw-mi: a differentiable GO-Draaw-style renderer on Mitsuba 3 and Dr.Jit.

Importing the package

1. checks, before Dr.Jit can abort the process, that a libLLVM >= 16 is available (LLVM
   variants only) and raises :class:`DraawError` with a one-line fix otherwise;
2. selects the Mitsuba variant (``DRAAW_MI_VARIANT``, default ``llvm_ad_rgb``);
3. registers the plugins (BSDF ``draaw``, integrators ``draaw_v1`` .. ``draaw_v4``), idempotently.

Example::

    import draaw_mi
    scene = draaw_mi.load_scene("scenes/cornell.toml")
    img = draaw_mi.render(scene, spp=64, seed=0)       # (H, W, 3) mi.TensorXf
    draaw_mi.write_exr("cornell.exr", img)
"""
from __future__ import annotations

import os as _os

from .errors import DraawError, IOFailure, ParameterError, RenderError, SceneError

__version__ = "0.1.0"
DEFAULT_VARIANT = "llvm_ad_rgb"
VARIANT = _os.environ.get("DRAAW_MI_VARIANT", DEFAULT_VARIANT)


def _select_variant(variant: str) -> None:
    if variant.startswith("scalar"):
        raise DraawError(f"DRAAW_MI_VARIANT={variant!r} is not supported: draaw-mi needs a JIT "
                         "variant such as 'llvm_ad_rgb' (CPU) or 'cuda_ad_rgb' (GPU)")
    if variant.startswith("llvm"):
        from ._llvm import check_llvm
        problem = check_llvm()
        if problem:
            raise DraawError(problem)
    import mitsuba as mi
    if variant not in mi.variants():
        raise DraawError(f"DRAAW_MI_VARIANT={variant!r} is not a Mitsuba variant; available: "
                         + ", ".join(mi.variants()))
    if mi.variant() != variant:
        mi.set_variant(variant)


_select_variant(VARIANT)

from . import materials as _materials  # noqa: E402  (needs the variant)
from . import integrators as _integrators  # noqa: E402


def register_plugins() -> None:
    """Register every draaw-mi Mitsuba plugin; safe to call any number of times."""
    _materials.register()
    _integrators.register()


register_plugins()

from .io import read_exr, write_exr, write_png  # noqa: E402
from .render import render  # noqa: E402
from .scene import load_scene  # noqa: E402
from .fit import FitResult, fit  # noqa: E402
from . import post  # noqa: E402
from .denoise import denoise  # noqa: E402  (pyoidn is imported only when called)

__all__ = [
    "DraawError", "SceneError", "ParameterError", "RenderError", "IOFailure", "VARIANT",
    "register_plugins", "load_scene", "render", "write_exr", "read_exr", "write_png", "fit", "FitResult", "post",
    "denoise",
]

# Subpackages that ``import draaw_mi`` does not load (each costs import time or pulls optional
# dependencies), reachable as attributes all the same: ``draaw_mi.sdf.smooth_union(...)``,
# ``draaw_mi.batch.run(...)`` work after a plain ``import draaw_mi``, as the README writes them.
from ._lazy import on_first_use as _on_first_use  # noqa: E402

__getattr__ = _on_first_use(__name__, ("batch", "bench", "camera_path", "media", "orbit_canvas", "preview",
                                       "sdf", "tuning", "widgets"))
