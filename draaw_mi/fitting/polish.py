"""A fit's last steps at more samples per pixel: the *polish* of :func:`draaw_mi.fit`.

Near its optimum a fit's gradient is the product of two independent noisy estimates, the
render's residual ``I - ref`` and the adjoint ``dI``, whose expectations both shrink there:
its variance falls like ``1 / (spp * spp_grad)`` while the cost of an iteration grows like
``spp + spp_grad``. Adam's step is about ``lr`` times the gradient's signal-to-noise ratio, so
at a fit's 16 spp the parameters stop where that ratio drops below about 0.2, short of the
optimum on the side they came from. A near-mirror (roughness 0.05) under an environment map,
measured (``benchmarks/fit_accuracy.md``'s set-up, 128², the log-roughness gradient at
roughness 0.067): signal-to-noise 0.17 per iteration at 16 spp, 0.61 at 64, 2.1 at 256. The
fit stops at 0.064-0.070 after 150 iterations at 16 spp (300 iterations: 0.060; 150 at
64 spp: 0.064); 100 iterations at 16 spp and a polish of 30 at 128 spp reach 0.055-0.059.

The polish is a second fit from the first's averaged values: ``polish`` iterations at
``polish_spp``, a fresh Adam at :data:`POLISH_LR` times ``lr``, held constant (the higher
signal-to-noise ratio, not a smaller step, is what settles it); its averaged iterates are the
result.
"""
from __future__ import annotations

import time

from .result import settled

#: the polish's learning rate, as a multiple of the fit's (constant over the polish)
POLISH_LR = 0.4
#: the polish's spp, as a multiple of the fit's, when ``polish_spp`` is not given
POLISH_SPP_FACTOR = 8


def polish_samples(spp: int, given: int | None) -> int:
    """The polish's samples per pixel: ``given``, or :data:`POLISH_SPP_FACTOR` times the fit's.

    >>> polish_samples(16, None), polish_samples(16, 64)
    (128, 64)
    """
    return POLISH_SPP_FACTOR * spp if given is None else given


def polish_maps(given, options):
    """The polish's ``maps`` argument: the fit's (``given``, parsed as ``options``), with the
    maps' own learning rate, where one is set, at :data:`POLISH_LR` times it.

    >>> from draaw_mi.fitting.maps import MapOptions
    >>> polish_maps({"lr": 0.5, "tv": 0}, MapOptions.parse({"lr": 0.5, "tv": 0})), polish_maps(None, MapOptions())
    ({'lr': 0.2, 'tv': 0}, None)
    """
    if options.lr is None:
        return given
    return dict(given if isinstance(given, dict) else {"parametrisation": given}, lr=POLISH_LR * options.lr)


def joined(first, second, fit_spp: tuple, polish_spp: tuple, t0: float, tol: float):
    """``second`` (the polish's :class:`~draaw_mi.fitting.result.FitResult`, whose values the
    scene holds) with ``first``'s history before its own, the iterations, kernel compilations
    and seconds (since ``t0``) of both, ``converged`` judged on the joined history
    (:func:`~draaw_mi.fitting.result.settled`, ``tol``), and ``stages``: each run's
    iterations, spp and seconds (``fit_spp``, ``polish_spp``: each run's ``(spp, spp_grad)``,
    ``spp_grad`` None where it is the spp)."""
    second.stages = []
    for name, run, (spp, grad) in (("fit", first, fit_spp), ("polish", second, polish_spp)):
        second.stages.append({"stage": name, "iterations": run.iterations, "spp": spp, "seconds": run.seconds,
                              **({} if grad is None else {"spp_grad": grad})})
    second.history = first.history + second.history
    second.iterations += first.iterations
    second.kernel_compiles += first.kernel_compiles
    second.seconds = time.perf_counter() - t0
    second.converged = settled(second.history, tol)
    return second
