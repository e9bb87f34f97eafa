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


TAIL_FRACTION = 0.005    # the largest squared errors whose share of the MSE tail_share gives
FIREFLY_SHARE = 0.5      # a single render whose error is mostly fireflies holds more
FIREFLY_SPREAD = 2.0     # a setting is firefly-dominated when its repeats' RMSEs differ this much


def tail_share(img: np.ndarray, gt: np.ndarray, fraction: float = TAIL_FRACTION) -> float:
    """The share of the squared error held by the largest ``fraction`` of the squared errors
    (pixel values). Gaussian noise gives about 0.05 at 0.5 %; a render whose error is a few
    fireflies (single samples worth thousands of times the pixel) gives close to 1, and its
    RMSE over a few repeats then depends on whether they happened to fall: it jumps and may
    even rise with spp, while the expected MSE still falls as 1 / spp.

    >>> rng = np.random.default_rng(0)
    >>> gt = np.zeros((64, 64, 3))
    >>> round(tail_share(rng.normal(size=gt.shape), gt), 2)
    0.05
    >>> img = rng.normal(0, 0.01, gt.shape); img[3, 4, 0] = 50.0
    >>> tail_share(img, gt) > 0.9
    True
    """
    with np.errstate(over="ignore", invalid="ignore"):
        sq = np.sort(((np.asarray(img, dtype=np.float64) - gt) ** 2).ravel())
    total = float(sq.sum())
    if not np.isfinite(total):      # a NaN/inf pixel: the render is reported as non-finite
        return float("nan")
    if total <= 0:
        return 0.0
    k = max(1, int(round(fraction * sq.size)))
    return float(sq[-k:].sum() / total)


def converged_bias(halves: tuple[np.ndarray, np.ndarray], gt: np.ndarray,
                   gt_halves: tuple[np.ndarray, np.ndarray] | None = None,
                   sigmas: float = BIAS_SIGMAS) -> tuple[float, bool]:
    """``(bias, resolved)``: the RMSE between a method's expectation and the ground truth's,
    from two independent high-spp renders of the method (``halves``, the same spp each) and
    the ground truth ``gt`` (a render of the reference integrator, independent of them).

    ``mean((a + b) / 2 - gt)^2`` holds the bias^2, the noise of the halves' mean
    (``mean((a - b)^2) / 4``) and the ground truth's noise; the last is read from
    ``gt_halves``, two renders of the reference integrator at half the ground truth's spp
    each (``mean((c - d)^2) / 4``); without them it is left in. Both noise terms are unbiased
    for any finite variance, fireflies included. ``resolved`` is False where the estimate is
    within ``sigmas`` standard errors (over the pixel values) of zero; ``bias`` is then an
    upper bound (estimate + ``sigmas`` standard errors).

    >>> rng = np.random.default_rng(1)
    >>> truth = np.full((32, 32, 3), 0.5)
    >>> noisy = lambda b, s=0.2: truth + b + rng.normal(0, s, truth.shape)    # s: at N spp
    >>> gt = noisy(0, 0.2 / np.sqrt(2))                                      # at 2N spp
    >>> b, ok = converged_bias((noisy(0.1), noisy(0.1)), gt, (noisy(0), noisy(0)))
    >>> round(b, 1), ok
    (0.1, True)
    >>> b, ok = converged_bias((noisy(0), noisy(0)), gt, (noisy(0), noisy(0)))
    >>> ok, b < 0.1
    (False, True)
    """
    a, b = (np.asarray(h, dtype=np.float64) for h in halves)
    gt = np.asarray(gt, dtype=np.float64)
    d = ((a + b) / 2 - gt) ** 2 - (a - b) ** 2 / 4
    if gt_halves is not None:
        c, e = (np.asarray(h, dtype=np.float64) for h in gt_halves)
        d = d - (c - e) ** 2 / 4
    d = d.ravel()
    b2 = float(d.mean())
    se = float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else 0.0
    resolved = bool(b2 > sigmas * se)
    return float(np.sqrt(max(b2, 0.0) if resolved else max(b2, 0.0) + sigmas * se)), resolved
