"""What a fit records of each iteration: its history entry (values, loss, latents, the
kernels compiled) and the progress bar's short line."""
from __future__ import annotations

import drjit as dr
import numpy as np

from .problem import FitProblem, record, texture_summary
from .report import averaged_count
from .settings import FitSettings


def _iterates(problem: FitProblem, opt) -> dict:
    """The current value of every fitted texture (a map's, or a texture fitted texel by
    texel), as a float32 array of its shape."""
    maps = problem.maps.values()
    return {k: maps[k] if k in maps else record(problem.prm[k].from_latent(dr.detach(opt[k])), problem.prm[k].shape)
            for k in problem.keys if k in maps or problem.prm[k].shape is not None}


def history_entry(problem: FitProblem, s: FitSettings, opt, it: int, loss_value: float, scale):
    """``(one iteration's history entry, kernels compiled in it)``."""
    keys, names, prm = problem.keys, problem.names, problem.prm
    full = _iterates(problem, opt)
    # a texture's summary, not a copy per iteration; its iterates are summed for the average
    # over the run's last part (report) while they fall in it
    values = {names[k]: texture_summary(full[k]) if k in full else
              record(prm[k].from_latent(dr.detach(opt[k])), prm[k].shape) for k in keys}
    if it >= s.iterations - averaged_count(s):
        for k, v in full.items():
            total, count = problem.texture_sums.get(k, (0.0, 0))
            problem.texture_sums[k] = (total + v.astype(np.float64), count + 1)
    new = sum(1 for kk in dr.kernel_history() if kk["type"] == dr.KernelType.JIT and not kk["cache_hit"])
    # the optimiser's coordinate: a map's logits, a texture's latent, or (linear) the value
    latent = {}
    for k in keys:
        if k in problem.maps.latents:
            latent[names[k]] = texture_summary(problem.maps.latents[k].latent())
        elif prm[k].space == "linear":
            latent[names[k]] = values[names[k]]
        elif k in full:
            latent[names[k]] = texture_summary(record(dr.detach(opt[k]), prm[k].shape))
        else:
            latent[names[k]] = record(dr.detach(opt[k]), prm[k].shape)
    entry = {"iteration": it, "loss": loss_value, "values": values, "kernel_compiles": new,
             "lr": float(opt.lr) if isinstance(opt.lr, (int, float)) else s.lr, "latent": latent}
    if s.exposure == "fit":
        entry["exposure_stops"] = float(np.log2(max(float(scale[0]), 1e-30)))
    return entry, new


def progress_values(values: dict, textures: set) -> dict:
    """The progress bar's ``{short name: value}``: each parameter by the first 5 letters of
    its last part, or of its last two parts where two would share one (two materials'
    ``roughness``); a texture (named in ``textures``) by its channel means.

    >>> progress_values({"a.roughness": 0.5, "b.roughness": 0.25, "a.base_color": [0.5, 0.2, 0.1, 0, 0, 0]},
    ...                  {"a.base_color"})
    {'a.roug': '0.500', 'b.roug': '0.250', 'base_': '[0.50,0.20,0.10]'}
    """
    base = {n: n.split(".")[-1][:5] for n in values}
    taken = list(base.values())
    short = {n: ".".join(p[:4] for p in n.split(".")[-2:]) if taken.count(base[n]) > 1 else base[n]
             for n in values}
    return {short[n]: _short(v[:len(v) // 2] if n in textures else v) for n, v in values.items()}


def _short(v):
    """A parameter's value for the progress report: a number, a colour, or a texture's mean.

    >>> _short(0.25), _short([0.5, 0.25, 1.0]), _short(np.full((4, 4, 3), 0.5))
    ('0.250', '[0.50,0.25,1.00]', 'mean 0.500')
    """
    arr = np.asarray(v, dtype=np.float64)
    if arr.size == 1:
        return f"{float(arr.ravel()[0]):.3f}"
    if arr.size <= 4:
        return "[" + ",".join(f"{x:.2f}" for x in arr.ravel()) + "]"
    return f"mean {arr.mean():.3f}"
