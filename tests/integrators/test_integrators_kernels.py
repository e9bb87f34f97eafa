"""Lean kernels: draaw_v4's render kernel is as small as Mitsuba's ``path`` kernel and every
scene feature it does not need is absent from it (guide §7: ``dr.kernel_history()``)."""
from __future__ import annotations

import gc
import json
import os
import subprocess
import sys

import pytest
from integrators_helpers import dr, mi, official_scene, rs

from draaw_mi.scene.loading import release_wrapped

ALL_FEATURES = dict(area=True, point=True, spot=True, envmap=True, texture=True,
                    normalmap=True, glass=True, conductor=True, two_sided=True)


def render_ops(scene, integ, spp: int = 4) -> int:
    """operation_count of the largest JIT kernel launched by one primal render."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()                          # clears the history
        img = mi.render(scene, integrator=integ, spp=spp, seed=0)
        dr.eval(img)
        dr.sync_thread()
        ks = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    return max(k["operation_count"] for k in ks)


def ops_of(scene_dict: dict, kind: str = "draaw_v4", **props) -> int:
    release_wrapped()                  # vcalls cover every live instance: drop old scenes
    gc.collect()
    scene = mi.load_dict(scene_dict)
    n = render_ops(scene, mi.load_dict({"type": kind, "max_depth": 5, **props}))
    del scene
    gc.collect()
    return n


@pytest.mark.parametrize("name", ["cornell", "mitsuba_cornell"])
def test_v4_kernel_no_larger_than_path(name):
    gc.collect()
    if name == "cornell":
        scene = official_scene("cornell", 16)
    else:
        d = mi.cornell_box()
        d["sensor"]["film"].update(width=16, height=16, rfilter={"type": "box"})
        scene = mi.load_dict(d)
    n_path = render_ops(scene, mi.load_dict({"type": "path", "max_depth": 6}))
    # the path tracing kernel alone: these boxes show their light, so V4 adds the emission
    # splitting rays for its edge pixels (test_emission_split.py checks that code's gating);
    # the sampler alike (V4's stratified pattern is Mitsuba's orthogonal sampler's code, not the integrator's)
    n_v4 = render_ops(scene, mi.load_dict({"type": "draaw_v4", "max_depth": 6, "emission_split": 1,
                                           "stratify": False}))
    assert n_v4 <= 1.10 * n_path, (n_v4, n_path)


def removed_feature_ops() -> dict:
    """The V4 kernel's size on the scene with every feature, and with each one removed."""
    counts = {"full": ops_of(rs.feature_scene(res=8, spp=4, **ALL_FEATURES), aovs="all")}
    for feature in ALL_FEATURES:
        opts = dict(ALL_FEATURES, **{feature: False})
        counts[feature] = ops_of(rs.feature_scene(res=8, spp=4, **opts), aovs="all")
    counts["aovs"] = ops_of(rs.feature_scene(res=8, spp=4, **ALL_FEATURES))
    return counts


def _counts_in_a_process(function: str) -> dict:
    """``function()`` of this module, run in a process of its own (no other scene alive: a
    vcall traces every live instance of its class), its JSON result."""
    from conftest import ROOT          # (here, not at the top: the child imports this module alone)
    here = os.path.dirname(os.path.abspath(__file__))
    script = (f"import json, sys; sys.path.insert(0, {here!r}); "
              f"import test_integrators_kernels as t; print(json.dumps(t.{function}()))")
    try:
        out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=600)
    except subprocess.TimeoutExpired as e:
        pytest.fail(f"the counting process ran past 600 s; its stderr: {str(e.stderr)[-2000:]}")
    tail = f"stdout {out.stdout[-1000:]!r}, stderr {out.stderr[-2000:]!r}"
    assert out.returncode == 0, tail
    try:
        return json.loads(out.stdout.strip().splitlines()[-1])
    except (IndexError, ValueError):
        pytest.fail(f"the counting process printed no counts: {tail}")


def test_each_removed_feature_lowers_v4_kernel():
    """In a process of its own: a vcall traces every live instance of its class, so a two-sided
    BSDF that an earlier test leaves alive (a cached scene) puts its code into the kernel of
    the scene without one (measured: 6857 operations, the full scene's, against 6278 with no
    such scene alive; the in-process form failed under another test order)."""
    counts = _counts_in_a_process("removed_feature_ops")
    full = counts.pop("full")
    for feature, n in counts.items():
        assert n < full, (feature, n, full)


def test_gating_removes_v4_code_beyond_plugins():
    """Python-level branches, not only smaller vcalls: point-light-only scenes have no MIS or
    emitter lookups at hits; removing the only delta BSDF drops the delta bookkeeping."""
    area = ops_of(rs.feature_scene(res=8, spp=4))
    point = ops_of(rs.feature_scene(res=8, spp=4, area=False, point=True))
    assert point < area
    # the same scene content, features forced on by an extra, never-seen object: the
    # difference is the integrator's own gated code
    glass = ops_of(rs.feature_scene(res=8, spp=4, glass=True))
    assert area < glass


@pytest.mark.parametrize("kind", ["draaw_v1", "draaw_v2", "draaw_v3"])
def test_other_versions_gate_aovs_and_environment(kind):
    base = ops_of(rs.feature_scene(res=8, spp=4), kind)
    assert base < ops_of(rs.feature_scene(res=8, spp=4), kind, aovs="all")
    assert base < ops_of(rs.feature_scene(res=8, spp=4, envmap=True), kind)


def test_v3_near_specular_code_only_for_glossy_other_bsdfs():
    """V3's near-specular test of other BSDFs (``near_specular``) enters the kernel only when
    some non-draaw BSDF has a glossy lobe: with diffuse ones only, ``glossy_alpha`` changes
    nothing; with a roughconductor it adds that code."""
    def scene(metal: bool) -> dict:
        d = rs.feature_scene(res=8, spp=4, conductor=metal)
        for k in ("floor", "ball", "box"):
            d[k]["bsdf"] = {"type": "diffuse"}
        return d
    diffuse = [ops_of(scene(False), "draaw_v3", glossy_alpha=a) for a in (0.0, 0.25)]
    assert diffuse[0] == diffuse[1], diffuse
    metal = [ops_of(scene(True), "draaw_v3", glossy_alpha=a) for a in (0.0, 0.25)]
    assert metal[0] < metal[1], metal


def _checker(a, b, n=4) -> list:
    return [[list(a) if (i + j) % 2 else list(b) for j in range(n)] for i in range(n)]


def _description(extra_material=None, normalmap=False) -> dict:
    """A draaw scene (16x16: floor, ball, area light); ``extra_material``: a material no
    shape uses; ``normalmap``: the ball's material normal-mapped."""
    ball = {"base_color": [0.7, 0.5, 0.3], "roughness": 0.5}
    if normalmap:
        ball["normalmap"] = _checker((0.6, 0.5, 0.9), (0.4, 0.5, 0.9))
    d = {"render": {"resolution": [16, 16], "spp": 4, "max_depth": 5, "filter": "box"},
         "camera": {"origin": [0, 1.5, 4], "target": [0, 0.4, 0], "fov": 45},
         "materials": {"m": ball, "fl": {"base_color": [0.5, 0.5, 0.5], "roughness": 0.8}},
         "shapes": [{"name": "floor", "type": "rectangle", "material": "fl", "scale": 3,
                     "rotate": {"axis": [1, 0, 0], "angle": -90}},
                    {"name": "ball", "type": "sphere", "material": "m", "translate": [0, 0.5, 0],
                     "scale": 0.5}],
         "lights": [{"type": "area", "shape": "rectangle", "position": [0, 3.5, 0.5],
                     "target": [0, 0, 0.5], "size": [0.6, 0.6], "intensity": 8}]}
    if extra_material is not None:
        d["materials"]["extra"] = extra_material
    return d


def description_ops(desc: dict, kind: str) -> tuple[int, list]:
    """(largest kernel's operation count, image as a list) of one render of a draaw scene
    description, no other scene alive."""
    import numpy as np

    import draaw_mi
    release_wrapped()
    gc.collect()
    scene = draaw_mi.load_scene(desc)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        img = mi.render(scene.mi_scene, integrator=mi.load_dict({"type": kind, "max_depth": 5}), spp=4, seed=0)
        dr.eval(img)
        dr.sync_thread()
        n = max(k["operation_count"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    out = np.array(img).tolist()
    del scene, img
    gc.collect()
    return n, out


def scene_content_ops() -> dict:
    """Kernel sizes (and V1 / V2 images) of the base scene, with an unused textured and
    normal-mapped material, with an unused roughconductor, and normal-mapped."""
    unused_tex = {"base_color": _checker((0.9, 0.2, 0.1), (0.1, 0.2, 0.9)),
                  "normalmap": _checker((0.6, 0.5, 0.9), (0.4, 0.5, 0.9))}
    out = {}
    for kind in ("draaw_v3", "draaw_v4"):
        out[f"base {kind}"] = description_ops(_description(), kind)[0]
        out[f"unused_tex {kind}"] = description_ops(_description(unused_tex), kind)[0]
    out["unused_metal draaw_v4"] = description_ops(
        _description({"type": "roughconductor", "alpha": 0.1}), "draaw_v4")[0]
    for kind in ("draaw_v1", "draaw_v2"):
        out[f"base {kind}"] = description_ops(_description(), kind)
        out[f"nmap {kind}"] = description_ops(_description(normalmap=True), kind)
    return out


def test_kernels_hold_only_what_the_scene_renders():
    """In a process of its own (as :func:`test_each_removed_feature_lowers_v4_kernel`): a
    material no shape uses adds nothing to V3's or V4's kernel (it is left out of the scene; a
    live BSDF enters every vcall: an unused textured, normal-mapped one took V4 from 2144 to
    3055 operations, V3 from 2648 to 5027, an unused roughconductor V4 to 3256), and V1 / V2,
    which ignore normal maps, trace a normal-mapped scene as the scene without its map: the
    same kernel and the same image (they had traced uv and dp/du for it: 4019 / 2684
    operations for 3936 / 2601)."""
    c = _counts_in_a_process("scene_content_ops")
    for kind in ("draaw_v3", "draaw_v4"):
        assert c[f"unused_tex {kind}"] == c[f"base {kind}"], (kind, c)
    assert c["unused_metal draaw_v4"] == c["base draaw_v4"], c
    for kind in ("draaw_v1", "draaw_v2"):
        (n_base, img_base), (n_nmap, img_nmap) = c[f"base {kind}"], c[f"nmap {kind}"]
        assert n_nmap == n_base, (kind, n_nmap, n_base)
        assert img_nmap == img_base, kind


#: the integrators of black_light_ops (V3's Beckmann lobe reads the draaw parameters: a
#: black surface taken for a draaw one reflected at grazing angles, its Fresnel term)
_BLACK_CASES = {"draaw_v1": {}, "draaw_v2": {}, "draaw_v3": {}, "draaw_v3:beckmann": {"distribution": "beckmann"}}


def black_light_ops() -> dict:
    """Kernel sizes and images of the base scene, whose area light has the black surface
    draaw-mi gives it, and of the same Mitsuba scene with that surface a ``diffuse`` of
    reflectance 1e-12 (another BSDF, reflecting next to nothing), for V1..V3 (_BLACK_CASES)."""
    import numpy as np

    import draaw_mi
    from draaw_mi.integrators.features import BLACK_SURFACE_PREFIX, detect_features
    out = {}
    scene = draaw_mi.load_scene(_description())
    d = dict(scene.mi_dict)
    del scene
    lights = [k for k, v in d.items() if isinstance(v, dict) and "emitter" in v and "bsdf" in v]
    assert lights and all(d[k]["bsdf"]["id"].startswith(BLACK_SURFACE_PREFIX) for k in lights)
    dim = dict(d, **{k: dict(d[k], bsdf={"type": "diffuse", "reflectance": {"type": "rgb", "value": [1e-12] * 3}})
                     for k in lights})
    for name, dd in (("black", d), ("dim", dim)):
        release_wrapped()
        gc.collect()
        mi_scene = mi.load_dict(dd)
        f = detect_features(mi_scene)
        out[f"{name} flags"] = [f["black_surfaces"], f["other_materials"]]
        for kind, props in _BLACK_CASES.items():
            integ = mi.load_dict({"type": kind.split(":")[0], "max_depth": 5, **props})
            n = render_ops(mi_scene, integ)
            img = mi.render(mi_scene, integrator=integ, spp=4, seed=0)
            out[f"{name} {kind}"] = [n, np.array(img).tolist()]
        del mi_scene
        gc.collect()
    return out


def test_a_toml_lights_black_surface_adds_no_other_bsdf_code():
    """A TOML scene's area light has a black ``diffuse`` surface; counted as "another BSDF" it
    put every other-BSDF branch into V3's kernel (2623 operations against 1717 without; 3-5 %
    of its time at 128^2). It is known as black (``black_surfaces``), absorbing: V1..V3's
    kernels are smaller than with a diffuse that reflects 1e-12, and the images the same."""
    import numpy as np
    c = _counts_in_a_process("black_light_ops")
    assert c["black flags"] == [True, False] and c["dim flags"] == [False, True], c
    for kind in _BLACK_CASES:
        (n_black, img_black), (n_dim, img_dim) = c[f"black {kind}"], c[f"dim {kind}"]
        img_black, img_dim = np.array(img_black), np.array(img_dim)
        assert n_black < n_dim, (kind, n_black, n_dim)
        assert img_black.mean() > 0.01 and np.allclose(img_black, img_dim, rtol=1e-5, atol=1e-7), kind
