"""Emitter selection learned by a pilot: each emitter's share of next-event estimation's
second moment, not its power.

Power says how much light an emitter sends, not how much of the image's *noise* comes through
it. On the thesis scene (a sky, an area light and a point light over a near-mirror floor) the
point light's glints carry almost all of the variance, yet uniform selection (power selection
is off where an environment lights the scene: a sky's power says little) gives it a third of
the light samples. Picking emitter ``i`` with probability ``p_i``, next-event estimation's
variance is ``sum_i M_i / p_i`` minus a constant, where ``M_i = E[f_i^2]`` is the second
moment of emitter ``i``'s contribution; it is smallest for ``p_i`` proportional to
``sqrt(M_i)``.

:func:`learn_selection` measures the ``M_i`` with a pilot of camera paths traced by the
integrator itself (uniform selection, a fixed seed, :data:`PILOT_PATHS` = 2^18 paths in scenes
with glints, 4 per pixel at 256x256, and 2^16 elsewhere: 0.03-0.1 s and 0.01-0.03 s on two
cores after compilation, whatever the render's size) and returns a
:class:`~.sampling.PowerSelection` with
``p_i = (1 - UNIFORM_SHARE) * sqrt(M_i) / sum_j sqrt(M_j) + UNIFORM_SHARE / n``. The
probabilities are fixed before the render, so the render stays unbiased; an emitter whose
contribution the pilot misses keeps the uniform share, which bounds what a poor pilot costs.
On the thesis glass scene the learned table takes V4 from 0.93x to 0.60x ``path``'s variance
x time at 256x256; rare contributions are what a pilot can miss (there, 2^16 paths give the
point light 0.34 with one seed and 0.86 with another), hence 2^18 where the scene has glints
(``benchmarks/results/speed_suite.md``).

``draaw_v4`` (``light_selection = "auto"`` or ``"learned"``) learns the table before its first
primal render of a scene and keeps it for the scene's lifetime: a change of lights or
materials leaves it (still unbiased, perhaps less apt) rather than paying a pilot per change
(a fit's iteration, a preview's slider step); ``integrator.forget_scene(scene, learned=True)``
relearns. The pilot's paths start at the sensor as it is then, so the batch executor learns
before it moves the camera (:class:`draaw_mi.batch.frame.CachedScene`), and a resumed batch
renders the same bits as an uninterrupted one.
"""
from __future__ import annotations

import contextlib

import drjit as dr
import mitsuba as mi
import numpy as np

from .glints import has_glints
from .sampling import PowerSelection

PILOT_PATHS = 1 << 18       # camera paths of the pilot where the scene has glints (uniform over the film)
PILOT_PATHS_PLAIN = 1 << 16     # ... and elsewhere, where no rare path carries the variance
PILOT_SEED = 0x5EED1        # fixed: the same scene learns the same table in every process
UNIFORM_SHARE = 0.2         # part of the probability spread uniformly (a floor per emitter)


def selection_probabilities(moments) -> np.ndarray | None:
    """Selection probabilities for second moments ``moments`` (one per emitter), or ``None``
    (uniform) when the pilot saw nothing to go by.

    >>> [round(float(x), 3) for x in selection_probabilities([9.0, 1.0, 0.0])]
    [0.667, 0.267, 0.067]
    >>> selection_probabilities([0.0, 0.0]) is None, selection_probabilities([float("nan"), 1.0]) is None
    (True, True)
    """
    m = np.asarray(moments, dtype=np.float64)
    if m.size < 2 or not np.all(np.isfinite(m)) or m.sum() <= 0:
        return None
    root = np.sqrt(np.maximum(m, 0.0))
    return (1.0 - UNIFORM_SHARE) * root / root.sum() + UNIFORM_SHARE / m.size


def selection_from_moments(scene: mi.Scene, moments) -> PowerSelection | None:
    """The table of :func:`selection_probabilities` (moments in ``scene.emitters()`` order)."""
    p = selection_probabilities(moments)
    return None if p is None else PowerSelection.from_power(scene, p)


def light_moments(integrator, scene: mi.Scene, paths: int = PILOT_PATHS,
                  seed: int = PILOT_SEED) -> np.ndarray:
    """Per-emitter second moments ``M_i`` of next-event estimation's contribution (luminance),
    from ``paths`` camera paths of ``integrator`` with uniform selection; in ``scene.emitters()``
    order. ``integrator``: ``draaw_v4`` (it adds to ``_light_sums`` while :func:`collecting`)."""
    n = len(scene.emitters())
    uniform = PowerSelection.from_power(scene, np.ones(n))
    sensor = scene.sensors()[0]
    with dr.suspend_grad():
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, paths)
        pos = sampler.next_2d()
        ray, _ = sensor.sample_ray_differential(time=sensor.shutter_open(), sample1=0.5,
                                                sample2=pos, sample3=mi.Point2f(0.5))
        # float64 sums: the atomic additions' order varies from run to run, and the table
        # must not (the same scene must render the same bits in every process)
        sums = dr.zeros(mi.Float64, n)
        with collecting(integrator, uniform, sums):
            integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=sampler, ray=ray,
                              depth=mi.UInt32(0), δL=None, δaovs=None, state_in=None,
                              active=mi.Bool(True))
        dr.eval(sums)
    m = np.array(sums, dtype=np.float64) / paths
    # 6 significant digits: differences in the last bits of the sums vanish here
    return np.array([float(f"{x:.6g}") for x in m])


def learn_selection(integrator, scene: mi.Scene) -> PowerSelection | None:
    """:func:`selection_from_moments` of :func:`light_moments`; ``None`` below two emitters.
    The pilot traces :data:`PILOT_PATHS` paths where the scene has glints (delta lights on
    near-mirrors, :func:`~.glints.has_glints`: rare paths that a smaller pilot misses), else
    :data:`PILOT_PATHS_PLAIN`: a quarter of the time for the same table (the material spheres
    and the speed suite's spot and area light: 2^16 and 2^18 paths give tables within 0.002
    over four seeds each)."""
    if len(scene.emitters()) < 2:
        return None
    return selection_from_moments(scene, light_moments(integrator, scene, paths=pilot_paths(scene)))


def pilot_paths(scene: mi.Scene) -> int:
    """The pilot's camera paths for ``scene``: :data:`PILOT_PATHS` where it has glints, else
    :data:`PILOT_PATHS_PLAIN` (see :func:`learn_selection`)."""
    return PILOT_PATHS if has_glints(scene) else PILOT_PATHS_PLAIN


@contextlib.contextmanager
def collecting(integrator, table: PowerSelection, sums: mi.Float):
    """Within this block ``integrator`` selects emitters with ``table`` and adds, for every
    light sample, ``contribution^2 * pmf`` to ``sums[emitter index]`` (see module doc)."""
    integrator._frozen_selection, integrator._light_sums = (table,), sums
    try:
        yield
    finally:
        integrator._frozen_selection, integrator._light_sums = None, None
