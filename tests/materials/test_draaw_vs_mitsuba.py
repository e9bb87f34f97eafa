"""Cross-check of the draaw BSDF against Mitsuba's own BSDFs, through Mitsuba's `path`
integrator on the Cornell box, within Monte Carlo noise.

* metallic = specular = 0 must render as `diffuse` with the same reflectance;
* metallic = 1, base_color = 1, roughness r must render as `roughconductor`
  (ggx, alpha = r^2, material 'none');
* a tangent-space normal map must render as Mitsuba's `normalmap` adapter around draaw
  (with its 3.9 extras, flip_invalid_normals and the shadow-terminator factor, switched off:
  draaw does neither; the tangent is the same, x - n n.x).

Statistic: K independent renders of each side (different seeds), per-pixel Welch z-score of
the difference of the means. Equal images: |z| > 4 almost never happens and the mean z is ~0
(measured over 6 seed sets at these settings: |mean z| <= 0.05, spread 0.01-0.02). The control
tests show that a 3% change of reflectance moves the mean z beyond the acceptance threshold
(measured at 32 spp: +0.64 for the diffuse walls, -0.15..-0.19 for the roughness-0.3 metal;
at 64 spp -0.21..-0.24).
"""
from __future__ import annotations

import numpy as np
import pytest

import mitsuba as mi

from _draaw_helpers import CORNELL_WHITE, cornell, render_stack, zstats

RES, K, SPP, DEPTH = 48, 16, 64, 4          # default suite: ~1 s per comparison
MAX_FRAC4 = 0.005                           # fraction of pixel channels with |z| > 4
MAX_MEAN_Z = 0.08                           # |mean z| allowed for equal images

_cache: dict = {}


def _stack(name, builder, seeds, spp=SPP, res=RES):
    key = (name, tuple(seeds), spp, res)
    if key not in _cache:
        _cache[key] = render_stack(builder(res), seeds, spp)
    return _cache[key]


def _diffuse_ref(res, scale=1.0):
    return cornell(res, DEPTH, white={"type": "diffuse",
                                      "reflectance": {"type": "rgb", "value": [c * scale for c in CORNELL_WHITE]}})


def _draaw_diffuse(res, scale=1.0):
    return cornell(res, DEPTH, white={"type": "draaw", "base_color": [c * scale for c in CORNELL_WHITE],
                                      "metallic": 0.0, "specular": 0.0, "roughness": 0.5})


def _conductor_ref(res, r):
    return cornell(res, DEPTH, override={"type": "roughconductor", "distribution": "ggx",
                                         "alpha": r * r, "material": "none"})


def _draaw_metal(res, r, tint=1.0):
    return cornell(res, DEPTH, override={"type": "draaw", "base_color": [tint] * 3,
                                         "metallic": 1.0, "roughness": r})


A_SEEDS = range(0, K)
B_SEEDS = range(1000, 1000 + K)


def _assert_detected(st, sign):
    """The difference fails the acceptance test above (sign = expected sign of mean z)."""
    assert sign * st["mean_z"] > MAX_MEAN_Z, st


def _assert_same(st, what):
    msg = f"{what}: {st}"
    assert st["dead_mismatch"] == 0, msg
    assert st["frac4"] <= MAX_FRAC4, msg
    assert abs(st["mean_z"]) <= MAX_MEAN_Z, msg


def test_draaw_lambert_matches_mitsuba_diffuse():
    a = _stack("draaw_diffuse", _draaw_diffuse, A_SEEDS)
    b = _stack("diffuse", _diffuse_ref, B_SEEDS)
    assert np.all(np.isfinite(a))
    st = zstats(a, b)
    print("diffuse", st)
    _assert_same(st, "draaw(metallic=0, specular=0) vs diffuse")


@pytest.mark.parametrize("r", [0.3, 0.7])
def test_draaw_metal_matches_mitsuba_roughconductor(r):
    a = _stack(f"draaw_metal{r}", lambda res: _draaw_metal(res, r), A_SEEDS)
    b = _stack(f"conductor{r}", lambda res: _conductor_ref(res, r), B_SEEDS)
    assert np.all(np.isfinite(a))
    st = zstats(a, b)
    print("metal", r, st)
    _assert_same(st, f"draaw(metallic=1, roughness={r}) vs roughconductor(alpha={r * r})")


def test_statistic_detects_3_percent_reflectance_change():
    """Control: draaw with a 3% brighter base_color is told apart from `diffuse`."""
    a = _stack("draaw_diffuse_x1.03", lambda res: _draaw_diffuse(res, 1.03), A_SEEDS)
    b = _stack("diffuse", _diffuse_ref, B_SEEDS)
    st = zstats(a, b)
    print("diffuse +3%", st)
    _assert_detected(st, +1)
    assert st["mean_z"] > 0.3, st                 # far beyond the threshold


@pytest.mark.parametrize("r", [0.3, 0.7])
def test_statistic_detects_3_percent_metal_tint(r):
    """Control: a metal with base_color 0.97 is told apart from the white roughconductor."""
    a = _stack(f"draaw_metal{r}_x0.97", lambda res: _draaw_metal(res, r, 0.97), A_SEEDS)
    b = _stack(f"conductor{r}", lambda res: _conductor_ref(res, r), B_SEEDS)
    st = zstats(a, b)
    print("metal -3%", r, st)
    _assert_detected(st, -1)


# ---------------------------------------------------------------------------- normal map
def _nm_bitmap(rgb):
    return {"type": "bitmap", "raw": True,
            "data": mi.TensorXf(np.tile(np.asarray(rgb, dtype=np.float32), (4, 4, 1)))}


NM_TILT = [0.68, 0.55, 0.94]          # unsigned encoding: n ~ (0.36, 0.1, 0.88) before normalising


def _nm_scenes(res, which):
    base = {"type": "draaw", "base_color": [0.8, 0.7, 0.6], "roughness": 0.4, "metallic": 0.2}
    if which == "draaw":
        bsdf = dict(base, normalmap=_nm_bitmap(NM_TILT))
    else:
        bsdf = {"type": "normalmap", "normalmap": _nm_bitmap(NM_TILT), "bsdf": base,
                "flip_invalid_normals": False, "use_shadowing_function": False}
    # rectangles only: their local x axis is dp_du, the tangent both implementations use
    return cornell(res, DEPTH, mats={"floor": bsdf, "back": bsdf})


def test_normalmap_matches_mitsuba_normalmap_adapter():
    a = _stack("nm_draaw", lambda res: _nm_scenes(res, "draaw"), A_SEEDS)
    b = _stack("nm_mitsuba", lambda res: _nm_scenes(res, "mitsuba"), B_SEEDS)
    assert np.all(np.isfinite(a))
    st = zstats(a, b)
    print("normalmap", st)
    _assert_same(st, "draaw normalmap vs Mitsuba normalmap{draaw}")


# ---------------------------------------------------------------------------- heavy version
@pytest.mark.slow
@pytest.mark.parametrize("case", ["diffuse", "metal0.1", "metal0.3", "metal0.7", "metal1.0", "normalmap"])
def test_cross_check_high_spp(case):
    """64x64, 16 x 256 spp per side, max_depth 4."""
    res, spp = 64, 256
    if case == "diffuse":
        a_b, b_b = _draaw_diffuse, _diffuse_ref
    elif case == "normalmap":
        a_b, b_b = (lambda res: _nm_scenes(res, "draaw")), (lambda res: _nm_scenes(res, "mitsuba"))
    else:
        r = float(case[5:])
        a_b, b_b = (lambda res: _draaw_metal(res, r)), (lambda res: _conductor_ref(res, r))
    a = render_stack(a_b(res), A_SEEDS, spp)
    b = render_stack(b_b(res), B_SEEDS, spp)
    st = zstats(a, b)
    print(case, st)
    _assert_same(st, case)
    assert abs(st["z_image"]) < 4.0, st
