"""The bias of a rendering method, told apart from its noise: the error the highest sample
counts studied keep once the variance is taken out (with its standard error), and the Pareto
front of time against error."""
from __future__ import annotations

import numpy as np

BIAS_LEVELS = 3          # the highest spp levels pooled per method
BIAS_SIGMAS = 3.0        # a bias below this many standard errors is reported as a bound


def _bias_term_se(row: dict, n: int | None) -> float:
    """Standard error of one row's ``mse - variance``: the spread of its repeats' errors
    (``mse_se``; a firefly in one repeat shows there), but at least what Gaussian pixel noise
    of that variance gives over ``n`` values and the repeats (three repeats' spread alone
    can be 10x too small), plus the error of the variance estimate itself."""
    se, var, r = row.get("mse_se", np.nan), row["variance"], row.get("repeats")
    if not np.isfinite(se):
        return np.nan
    if not (n and r and r > 1):
        return se
    return float(np.sqrt(max(se ** 2, 2.0 * var ** 2 / (n * r)) + 2.0 * var ** 2 / (n * (r - 1))))


def _noise_per_sample(rows: list[dict]) -> float | None:
    """A method's pixel variance per sample (``variance * spp``), pooled over its
    :data:`BIAS_LEVELS` highest spp levels with the weights of :func:`estimate_bias`."""
    top = sorted((r for r in rows if np.isfinite(r.get("variance", np.nan))), key=lambda r: r["spp"])[-BIAS_LEVELS:]
    if not top:
        return None
    w = np.array([1.0 / max(r["variance"], 1e-30) ** 2 for r in top])
    return float(np.sum(w * [r["variance"] * r["spp"] for r in top]) / w.sum())


def estimate_bias(rows: list[dict], gt_spp: int | None = None, reference: dict | None = None) -> dict:
    """``{(scene, label, max_depth): (bias, resolved)}``: the RMSE that does not fall with spp.

    Per setting, ``bias^2 + floor = MSE - variance`` (the variance of one render estimated from
    the independent repeats). The :data:`BIAS_LEVELS` highest spp levels of a method are pooled,
    weighted by ``1 / variance^2`` (the estimate's noise grows with the variance term).
    ``floor`` is the ground truth's own noise, ``variance * spp / gt_spp`` of the ground
    truth's integrator (``reference``: ``{scene: label}``, its rows in the study at the same
    depth; without them the method's own variance stands in): left in, it shows as a bias of
    every method, ``path`` included. ``resolved``
    is False where the estimate is within :data:`BIAS_SIGMAS` standard errors of zero (from the
    spread of the repeats' errors, ``mse_se``); ``bias`` is then an upper bound. (Taken at the
    highest spp alone, from 2-3 repeats, V4 shows the ground truth's noise as a bias of
    0.0145 on the Cornell box while V1, biased by -10 % in its mean, shows 0.)
    """
    out = {}
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["scene"], r["label"], r["max_depth"]), []).append(r)
    for key, rs in groups.items():
        top = sorted((r for r in rs if np.isfinite(r.get("variance", np.nan))),
                     key=lambda r: r["spp"])[-BIAS_LEVELS:]
        if not top:
            continue
        w = np.array([1.0 / max(r["variance"], 1e-30) ** 2 for r in top])
        w /= w.sum()
        b2 = float(sum(wi * (r["mse"] - r["variance"]) for wi, r in zip(w, top)))
        res = top[-1].get("resolution")
        n = 3 * int(np.prod(res)) if res else None            # pixel values per image
        se = [_bias_term_se(r, n) for r in top]
        se2 = float(sum((wi * s) ** 2 for wi, s in zip(w, se))) if all(np.isfinite(se)) else np.nan
        if gt_spp:
            ref = (reference or {}).get(key[0])
            per_sample = _noise_per_sample(groups.get((key[0], ref, key[2]), [])) if ref else None
            if per_sample is None:
                per_sample = _noise_per_sample(rs)
            floor = per_sample / gt_spp
            b2 -= floor
            # the ground truth's noise is one realisation, common to every repeat: its mean
            # square over the n pixel values is off its expectation by about floor * sqrt(2 / n)
            if n and np.isfinite(se2):
                se2 += 2.0 * floor ** 2 / n
        noise = BIAS_SIGMAS * np.sqrt(se2) if np.isfinite(se2) else 0.0
        resolved = bool(b2 > noise)
        out[key] = (float(np.sqrt(max(b2, 0.0) if resolved else max(b2, 0.0) + noise)), resolved)
    return out


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of (time, error) points not dominated by another (lower time and error).

    >>> pareto_front([(1, 5), (2, 3), (3, 4), (4, 1)])
    [0, 1, 3]
    """
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], np.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return sorted(front)
