"""The last phase of :func:`~draaw_mi.fitting.fitter.fit`: the averaged values set in the
scene, texels no capture saw filled, a final render, how well each capture is explained, and
the :class:`~draaw_mi.fitting.result.FitResult`."""
from __future__ import annotations

import time

import drjit as dr
import numpy as np

from ..errors import RenderError
from ..rendering.frozen import owned_tensor
from ..rendering.session import holding, session_of
from .maps import fill_unobserved
from .problem import FitProblem, apply_chain
from .result import FitResult, explained, settled
from .settings import FitSettings


def averaged_count(s: FitSettings) -> int:
    """How many of the last iterates the reported values average (``average_last`` of the run)."""
    return max(1, int(round(s.iterations * s.average_last)))


def leave_in_callers_scene(problem: FitProblem, keys) -> None:
    """The fitted ``keys`` of ``problem.scene`` copied into the scene the caller gave, where the
    fit ran on a copy at the references' size (at the end of a fit, and when it is interrupted)."""
    if problem.callers_scene is problem.scene:
        return
    p = problem.scene.all_params
    with holding(problem.callers_scene):            # (no render of it sees half the values)
        q = problem.callers_scene.all_params
        for k in keys:
            q[k] = type(p[k])(p[k])
        q.update()
        session_of(problem.callers_scene).scene_changed()


def report(problem: FitProblem, s: FitSettings, opt, history: list, compiles: int, t0: float) -> FitResult:
    """The iterates averaged over the last ``average_last`` of the run, set in the scene (and
    in the caller's, when the fit rendered a copy), a final render and the result."""
    keys, names, prm, scene = problem.keys, problem.names, problem.prm, problem.scene
    p = scene.all_params
    n_avg = averaged_count(s)
    averaged = {k: prm[k].project_value(problem.texture_sums[k][0] / problem.texture_sums[k][1]
                                        if k in problem.texture_sums else
                                        np.array([h["values"][names[k]] for h in history[-n_avg:]],
                                                 dtype=float).mean(axis=0)) for k in keys}
    observed = {}
    for k in problem.maps.latents:       # texels no capture saw: continued from those seen
        observed[names[k]] = problem.maps.seen(k).copy()
        if s.maps.fill:
            averaged[k] = fill_unobserved(averaged[k].reshape(prm[k].shape), observed[names[k]])
    problem.overrides.restore(p)
    bad = [names[k] for k in keys if not np.all(np.isfinite(averaged[k]))]
    if bad:
        with holding(scene):
            for k in keys:
                p[k] = problem.start[k]
            p.update()
            problem.session.scene_changed()
        raise RenderError(f"fit: {', '.join(bad)} diverged to NaN/Inf (last loss "
                         f"{history[-1]['loss']:.3g}); the scene keeps its starting values: "
                         f"try a smaller lr (now {s.lr:g})")
    fitted = {}
    for k in keys:
        mean = averaged[k]
        if prm[k].shape is not None:         # a texture: back in its own shape
            fitted[names[k]] = mean.astype(np.float32).reshape(prm[k].shape)
            # (owned: the result's array and the scene's texture share no memory, and later
            # recordings take the texture as input)
            p[k] = owned_tensor(fitted[names[k]]) if dr.is_tensor_v(prm[k].type) else prm[k].type(fitted[names[k]])
        else:
            fitted[names[k]] = mean.tolist() if mean.ndim else float(mean)
            p[k] = prm[k].type(fitted[names[k]]) if mean.ndim == 0 else prm[k].type(mean.tolist())
    with holding(scene):                          # the values and the render they show, together
        problem.overrides.apply(p, 0)
        p.update()
        problem.session.scene_changed()
        problem.overrides.select_lights(problem.integrator, scene.mi_scene, 0)
        final = problem.session.render_pass(problem.integrator, problem.spp, (s.seed + 12345) & 0xFFFFFFFF,
                                            sensor=problem.sensors[0])
        misfit = misfits(problem, s)            # (and the scene's own lights back)
        if problem.overrides.lights_vary and hasattr(problem.integrator, "restore_selection"):
            problem.integrator.restore_selection(scene.mi_scene, None)    # relearned for them
    final = final[:, :, :3] if final.shape[2] > 3 else final
    if problem.chain is not None:
        final = apply_chain(final, problem.chain)
    final = np.array(final)
    leave_in_callers_scene(problem, keys)
    return FitResult(values=fitted, history=history, image=final[..., :3], converged=settled(history, s.tol),
                     iterations=s.iterations, seconds=time.perf_counter() - t0, kernel_compiles=compiles,
                     exposure_stops=float(np.mean([h["exposure_stops"] for h in history[-n_avg:]]))
                     if s.exposure == "fit" else 0.0, version=problem.version, observed=observed,
                     captures=explained(misfit, problem.refs, problem.masks))


def misfits(problem: FitProblem, s: FitSettings) -> list:
    """Per view, ``mean((I1 - ref)(I2 - ref))`` of two renders of the fitted scene with
    independent seeds (its expectation is the squared error of the render's expectation; see
    :func:`~draaw_mi.fitting.result.explained`). The caller holds the scene."""
    p = problem.scene.all_params
    out = []
    for v, (sensor, ref) in enumerate(zip(problem.sensors, problem.refs)):
        problem.overrides.apply(p, v)
        p.update()
        problem.session.scene_changed()
        errors = []
        for k in range(2):
            problem.overrides.select_lights(problem.integrator, problem.scene.mi_scene, v)
            img = problem.session.render_pass(problem.integrator, problem.spp,
                                              (s.seed * 7919 + 104729 * (k + 1) + v) & 0xFFFFFFFF, sensor=sensor)
            img = img[:, :, :3] if img.shape[2] > 3 else img
            if problem.chain is not None:
                img = apply_chain(img, problem.chain)
            d = np.array(img, dtype=np.float64) - np.array(ref, dtype=np.float64)
            if problem.masks[v] is not None:
                d = d * np.array(problem.masks[v])
            errors.append(d)
        out.append(float(np.mean(errors[0] * errors[1])))
    problem.overrides.restore(p)
    p.update()
    problem.session.scene_changed()
    return out
