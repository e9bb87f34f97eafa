"""What load_scene takes beyond scene files: Mitsuba dicts (crop windows, declared
integrators), a loaded scene again (overrides), and a dict scene written back."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi import SceneError


def test_a_mitsuba_dicts_crop_window_is_its_resolution_and_resizes_with_it():
    """A dict's film cropped to 16x16 said its film's 32x32; resized, its window stayed 16x16."""
    film = {"type": "hdrfilm", "width": 32, "height": 32, "crop_width": 16, "crop_height": 16,
            "crop_offset_x": 8, "crop_offset_y": 8, "rfilter": {"type": "box"}}
    d = {"type": "scene", "sensor": {"type": "perspective", "film": film,
                                     "sampler": {"type": "independent", "sample_count": 1}},
         "ball": {"type": "sphere"}, "sky": {"type": "constant"}}
    scene = draaw_mi.load_scene(d)
    assert scene.resolution == (16, 16) and scene.settings["resolution"] == (16, 16)
    small = draaw_mi.load_scene(d, resolution=(8, 8))
    f = small.mi_scene.sensors()[0].film()
    assert small.resolution == (8, 8) and list(f.size()) == [16, 16] and list(f.crop_offset()) == [4, 4]
    assert np.array(draaw_mi.render(small, seed=0)).shape == (8, 8, 3)


def test_the_integrator_a_mitsuba_dict_or_mi_scene_declares_is_its_version():
    """A dict's integrator under another key than "integrator", or an mi.Scene's, rendered
    with v4 without a word."""
    from draaw_mi.scene.description import DEFAULT_SETTINGS

    def scene_dict(**integrator):
        return {"type": "scene", **integrator, "ball": {"type": "sphere"}, "sky": {"type": "constant"},
                "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8}}}

    own = draaw_mi.load_scene(scene_dict(my_integrator={"type": "direct"}))
    assert own.settings["version"] == "scene" and own.summary()["integrator"] == "direct"
    wrapped = draaw_mi.load_scene(mi.load_dict(scene_dict(integrator={"type": "path", "max_depth": 3})))
    assert (wrapped.settings["version"], wrapped.settings["max_depth"]) == ("path", 3)
    # (Mitsuba gives a scene that declares none no integrator: draaw-mi's default renders it)
    assert mi.load_dict(scene_dict()).integrator() is None
    assert draaw_mi.load_scene(mi.load_dict(scene_dict())).settings["version"] == DEFAULT_SETTINGS["version"]


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_a_dict_scene_holding_numpy_values_is_written_back(tmp_path, suffix):
    """A fit's save of such a scene raised TypeError ("Object of type ndarray is not JSON /
    TOML serializable")."""
    from draaw_mi.scene.draaw_scene import plain
    from draaw_mi.scene.schema import Where
    desc = {"render": {"resolution": [8, 8], "spp": 1},
            "materials": {"m": {"base_color": np.full((2, 2, 3), 0.5, np.float32), "metallic": np.float32(0.25)}},
            "shapes": [{"type": "sphere", "material": "m"}], "lights": [{"type": "point", "position": [0, 3, 3]}]}
    scene = draaw_mi.load_scene(desc)
    out = tmp_path / f"fit{suffix}"
    out.write_text(scene.updated_text({"m.roughness": 0.125}, dest=str(out)))
    again = draaw_mi.load_scene(str(out))
    assert np.allclose(np.array(again.params["m.base_color.data"]), 0.5)
    assert np.allclose(again.params["m.metallic.value"], 0.25) and np.allclose(again.params["m.roughness.value"], 0.125)
    with pytest.raises(SceneError, match=r"s: m\.tex: object .* cannot be written to a scene file"):
        plain({"m": {"tex": object()}}, Where("s"))


def test_a_loaded_scene_takes_a_resolution_and_refuses_other_overrides(tiny_desc):
    """load_scene(scene, resolution=..., spp=..., version=...) gave the scene back as it was,
    every override dropped without a word."""
    scene = draaw_mi.load_scene(tiny_desc)
    assert draaw_mi.load_scene(scene) is scene
    assert draaw_mi.load_scene(scene, spp=None, resolution=None) is scene     # (None: the scene's)
    assert draaw_mi.load_scene(scene, resolution=(8, 4)).resolution == (8, 4)
    with pytest.raises(SceneError, match=r"takes resolution= only, not spp, version; give them to render"):
        draaw_mi.load_scene(scene, resolution=(8, 4), spp=2, version="v1")


@pytest.mark.parametrize("override, match", [
    ({"filter": "nope"}, r"override.filter: 'nope' is not one of box, gaussian"),
    ({"hide_emitters": "no"}, r"override.hide_emitters: 'no' is not true or false"),
    ({"aovs": ["dpth"]}, r"override.aovs: 'dpth' is not an AOV; did you mean 'depth'"),
    ({"aovs": [1]}, r"override.aovs: \[1\] is not a list of AOV names"),
])
def test_load_scenes_filter_hide_emitters_and_aovs_overrides_are_checked(tiny_desc, override, match):
    """They were taken as given and failed at the render (a string of AOVs read letter by
    letter, a filter in Mitsuba's words)."""
    with pytest.raises(SceneError, match=match):
        draaw_mi.load_scene(tiny_desc, **override)


def test_one_aov_name_as_an_override_is_one_aov(tiny_desc):
    assert draaw_mi.load_scene(tiny_desc, aovs="depth").settings["aovs"] == ["depth"]
    assert draaw_mi.load_scene(tiny_desc, aovs=np.array(["depth", "normal"])).settings["aovs"] == ["depth", "normal"]
