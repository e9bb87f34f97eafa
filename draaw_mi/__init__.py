"""draaw-mi: a differentiable GO-Draaw-style renderer on Mitsuba 3 and Dr.Jit.

Importing the package

1. checks, before Dr.Jit can abort the process, that a libLLVM >= 16 is available (LLVM
   variants only) and raises :class:`DraawError` with a one-line fix otherwise;
2. selects the Mitsuba variant (``DRAAW_MI_VARIANT``, default ``llvm_ad_rgb``);
3. registers the plugins (BSDF ``draaw``, integrators ``draaw_v1`` .. ``draaw_v4``), idempotently;
4. serves the module paths of the flat layout of earlier releases (``draaw_mi.preview``,
   ``draaw_mi.fit_result``, ...: :data:`MOVED`) as their new modules, with a
   ``DeprecationWarning``.

The package is a stack of wings, each importing only the ones below it: ``cli``, ``bench``,
``batch``, ``widgets``, ``fitting``, ``rendering``, ``scene``, ``integrators``, ``media`` /
``post``, ``sdf`` / ``materials``, and the ground floor (``io``, ``progress``, ``plotting``,
``guard``, ``limits``, ``errors``). Heavy or optional wings (``batch``, ``bench``, ``cli``,
``media``, ``widgets``) are imported when first named; ``sdf`` comes with the integrators (they
find a scene's SDF objects).

Example::

    import draaw_mi
    scene = draaw_mi.load_scene("scenes/cornell.toml")
    img = draaw_mi.render(scene, spp=64, seed=0)       # (H, W, 3) mi.TensorXf
    draaw_mi.write_exr("cornell.exr", img)
"""
from __future__ import annotations

import importlib as _importlib
import os as _os
import sys as _sys

from ._llvm import check_llvm
from .errors import DraawError, IOFailure, NonFiniteWarning, ParameterError, RenderError, SceneError

__version__ = "0.1.0"
DEFAULT_VARIANT = "llvm_ad_rgb"
VARIANT = _os.environ.get("DRAAW_MI_VARIANT", DEFAULT_VARIANT)


#: the Mitsuba variants draaw-mi runs on: JIT (a kernel per render), differentiable, RGB (its
#: BSDF and integrators compute in Color3f: a spectral, monochrome or polarised variant fails
#: in the first render)
SUPPORTED_VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")


def _select_variant(variant: str) -> None:
    supported = "supported: 'llvm_ad_rgb' (CPU, the default) or 'cuda_ad_rgb' (GPU)"
    if variant.startswith("scalar"):
        raise DraawError(f"DRAAW_MI_VARIANT={variant!r} is not supported: draaw-mi needs a JIT "
                         f"variant; {supported}")
    if variant.startswith("llvm"):
        problem = check_llvm()
        if problem:
            raise DraawError(problem)
    import mitsuba as mi  # only now: with libLLVM < 16, importing Dr.Jit aborts the process
    if variant not in mi.variants():
        raise DraawError(f"DRAAW_MI_VARIANT={variant!r} is not a Mitsuba variant; available: "
                         + ", ".join(mi.variants()) + f"; {supported}")
    if variant not in SUPPORTED_VARIANTS:       # (before set_variant: nothing is made in it)
        why = ("renders in RGB only" if variant.endswith(("_spectral", "_mono", "_polarized")) else
               "needs a differentiable (_ad_) variant")
        raise DraawError(f"DRAAW_MI_VARIANT={variant!r} is not supported: draaw-mi {why}; {supported}")
    if mi.variant() != variant:
        try:
            mi.set_variant(variant)
        except (ImportError, RuntimeError) as e:          # (cuda_ad_rgb without a GPU or driver)
            first = (str(e).strip().splitlines() or [type(e).__name__])[0]
            raise DraawError(f"DRAAW_MI_VARIANT={variant!r}: Mitsuba cannot start it here ({first}); "
                             f"use {DEFAULT_VARIANT!r}") from None


_select_variant(VARIANT)

from . import integrators as _integrators  # noqa: E402
from . import materials as _materials  # noqa: E402  (needs the variant)


def register_plugins() -> None:
    """Register every draaw-mi Mitsuba plugin; safe to call any number of times."""
    _materials.register()
    _integrators.register()


register_plugins()

from . import post  # noqa: E402
from .fitting import FitResult, fit  # noqa: E402
from .io import read_exr, write_exr, write_png  # noqa: E402
from .rendering import denoise, render  # noqa: E402  (denoise imports pyoidn when called)
from .scene import load_scene  # noqa: E402

__all__ = [
    "DraawError", "SceneError", "ParameterError", "RenderError", "IOFailure", "NonFiniteWarning", "VARIANT",
    "register_plugins", "load_scene", "render", "write_exr", "read_exr", "write_png", "fit", "FitResult", "post",
    "denoise",
]

# Subpackages that ``import draaw_mi`` does not load (each costs import time or pulls optional
# dependencies), reachable as attributes all the same: ``draaw_mi.sdf.smooth_union(...)``,
# ``draaw_mi.batch.run(...)`` work after a plain ``import draaw_mi``, as the README writes them.
from ._lazy import MovedModules as _MovedModules  # noqa: E402
from ._lazy import ShadowedModule as _ShadowedModule
from ._lazy import on_first_use as _on_first_use

_LAZY = ("batch", "bench", "cli", "media", "widgets")

# Module paths of the flat layout, served as the modules' new homes with a DeprecationWarning
# until the next release. (Not draaw_mi.render, .fit, .denoise: those names are the functions.)
MOVED = {
    **{f"draaw_mi.{old}": f"draaw_mi.rendering.{new}" for old, new in (
        ("preview", "preview"), ("preview_worker", "preview_worker"), ("passes", "passes"),
        ("frozen", "frozen"), ("film_colour", "film_colour"), ("adaptive", "subsample"))},
    **{f"draaw_mi.fit_{name}": f"draaw_mi.fitting.{name}" for name in ("params", "reference", "result", "views")},
    **{f"draaw_mi.{old}": f"draaw_mi.widgets.{new}" for old, new in (
        ("tuning", "tuning"), ("orbit_canvas", "orbit_canvas"), ("tuner_camera", "camera_panel"),
        ("tuner_lights", "lights_panel"), ("tuner_post", "post_panel"), ("tuner_document", "save_panel"))},
    **{f"draaw_mi.{old}": f"draaw_mi.bench.{new}" for old, new in (
        ("bench_bias", "bias"), ("bench_report", "report"), ("speed_bench", "speed"), ("speed_suite", "suite"),
        ("image_metrics", "metrics"), ("code_digest", "code_digest"))},
    "draaw_mi.cli_bench": "draaw_mi.cli.bench", "draaw_mi.cli_common": "draaw_mi.cli.common",
    "draaw_mi.camera_path": "draaw_mi.scene.camera_path",
    "draaw_mi.adaptive_sampling": "draaw_mi.integrators.adaptive_sampling",
    "draaw_mi.integrators.reference_scenes": "draaw_mi.bench.reference_scenes",
    "draaw_mi.sdf.study": "draaw_mi.bench.sdf_study",
    "draaw_mi.sdf.go_draaw": "draaw_mi.scene.go_draaw_spheres",
    "draaw_mi.media.scene_volumes": "draaw_mi.scene.volume_dicts",
}
if not any(isinstance(hook, _MovedModules) for hook in _sys.meta_path):
    _sys.meta_path.insert(0, _MovedModules(MOVED))     # ahead of stale files of the old layout

# draaw_mi/render.py, fit.py and denoise.py moved too, but draaw_mi.render, .fit and .denoise
# are the functions: ``from draaw_mi.render import X`` reads X from the new module, with a warning
_SESSION = "session_of(scene) (draaw_mi.rendering.session)"
for _old, _new, _elsewhere, _gone in (
        ("render", "draaw_mi.rendering.renderer", {
            **dict.fromkeys(("FREEZE", "FREEZE_MAX_PIXELS", "FREEZE_MAX_SPP"), "draaw_mi.rendering.session"),
            **dict.fromkeys(("freeze_render", "freeze_supported", "other_live_bsdfs", "scene_scalars"),
                            "draaw_mi.rendering.frozen"),
            **dict.fromkeys(("pass_seed", "sample_passes"), "draaw_mi.rendering.passes"),
            "film_colour_names": "draaw_mi.rendering.film_colour", "suggest": "draaw_mi.errors"}, {
            "make_integrator": f"{_SESSION}.integrator(version, max_depth, ...)",
            "scene_holds": f"{_SESSION}.holds()",
            "check_version_sees": f"{_SESSION}.check_version_sees(version)",
            "freeze_eligible": f"{_SESSION}.freezes(spp)",
            "frozen_render": f"{_SESSION}.recording(integrator, spp)",
            "scene_state": f"{_SESSION} holds what the renderer kept per scene",
            "scene_changed": f"{_SESSION}.scene_changed() (with the DraawScene, not the mi.Scene)"}),
        ("fit", "draaw_mi.fitting.fitter", {}, {}),
        ("denoise", "draaw_mi.rendering.denoiser", {}, {})):
    _sys.modules.setdefault(f"{__name__}.{_old}", _ShadowedModule(f"{__name__}.{_old}", _new, _elsewhere, _gone))


def __getattr__(name: str):
    if f"{__name__}.{name}" in MOVED:        # draaw_mi.preview without importing it first
        return _importlib.import_module(f"{__name__}.{name}")
    return _on_first_use(__name__, _LAZY)(name)
