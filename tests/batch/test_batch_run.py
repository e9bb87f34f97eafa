"""In-process batch runs: frames equal independent renders, resume, stale frames, failures,
EXR layers and metadata, and no kernel compiles after a job's first frame."""
from __future__ import annotations

import json
import math
import os

import mitsuba as mi
import numpy as np
import OpenEXR
import pytest
import tomli_w
from batch_helpers import assert_bit_identical, frames_of, manifest, tiny_description, write_manifest, write_scene

import draaw_mi
from draaw_mi.batch import runner as batch
from draaw_mi.batch.planner import frame_seed, param_value


def test_frame_equals_an_independent_render(tmp_path):
    """Frame 2 of an orbit + roughness ramp equals a fresh scene built with that camera and that
    roughness in its description, rendered with the frame's seed (box filter: bit-identical)."""
    doc = manifest(tmp_path, frames=4)
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 4 and not res.failed
    m, specs, _ = batch.load(doc)
    s = specs[2]
    # a fresh scene with that camera and roughness; V4 learns its light selection with the
    # scene as loaded (light_pilot.py), as the batch does, so learn before moving anything
    scene = draaw_mi.load_scene(tiny_description())
    draaw_mi.render(scene, seed=99, spp=1)
    p = scene.params
    p["sensor.to_world"] = mi.ScalarTransform4f().look_at(
        origin=s["camera"]["origin"], target=s["camera"]["target"], up=s["camera"]["up"])
    p[scene.key("ball.roughness")] = param_value("linear", (0.1, 0.9), 2, 4)
    p.update()
    ref = np.array(draaw_mi.render(scene, seed=frame_seed(0, 2), spp=4))
    got = draaw_mi.read_exr(s["output"])
    assert np.array_equal(got, ref)
    # the override and the camera matter: neighbouring frames differ from this reference
    assert not np.array_equal(draaw_mi.read_exr(specs[1]["output"]), ref)


def test_a_frame_without_an_override_gets_the_scene_value_back(tmp_path):
    """Scene parameters are the scene's own arrays, changed in place by an update: the values
    a frame restores must be copies taken before the first override, or a frame that does
    not override a key (another job on the same scene, a resumed run's first frame) inherits
    the previous frame's value."""
    from draaw_mi.batch.frame import SceneCache
    scene_file = write_scene(tmp_path)
    cache = SceneCache()
    m, specs, _ = batch.load(manifest(tmp_path, frames=2), cache=cache)
    entry = cache.get(scene_file)
    p = entry.scene.params
    key = entry.scene.key("ball.roughness")
    loaded = float(p[key][0])
    cam0 = np.array(p["sensor.to_world"].matrix).copy()
    entry.apply(specs[1])                                     # roughness 0.9 and an orbit camera
    assert float(p[key][0]) == pytest.approx(0.9)
    entry.apply(dict(specs[1], params={}, camera=None))       # no override, no camera
    assert float(p[key][0]) == pytest.approx(loaded)
    np.testing.assert_allclose(np.array(p["sensor.to_world"].matrix), cam0, atol=1e-6)


def test_plan_cameras_params_and_seeds(tmp_path):
    doc = manifest(tmp_path, frames=8)
    _, specs, _ = batch.load(doc)
    target = np.array([0.0, 0.5, 0.0])
    angles = []
    for s in specs:
        o = np.array(s["camera"]["origin"])
        assert math.isclose(o[1] - target[1], 0.8, abs_tol=1e-12)
        assert math.isclose(np.hypot(o[0], o[2]), 5.0, rel_tol=1e-12)
        angles.append(math.atan2(o[0], o[2]))
    steps = np.diff(np.unwrap(angles))
    assert np.allclose(steps, 2 * math.pi / 8)             # a full turn, frame 0 not repeated
    r = [s["params"]["ball.roughness.value"] for s in specs]
    assert np.allclose(r, np.linspace(0.1, 0.9, 8))
    seeds = [s["seed"] for s in specs]
    assert len(set(seeds)) == 8 and seeds == [frame_seed(0, i) for i in range(8)]
    assert len({s["hash"] for s in specs}) == 8


def test_go_draaw_keyframes_follow_camera_path(tmp_path, go_draaw_dir):
    from draaw_mi.scene.camera_path import interpolate
    from draaw_mi.scene.camera import go_draaw_look_at

    doc = manifest(tmp_path, frames=6, camera={"file": os.path.join(go_draaw_dir, "camera_positions.json"),
                                               "fov": 50})
    del doc["jobs"][0]["params"]
    _, specs, _ = batch.load(doc)
    with open(os.path.join(go_draaw_dir, "camera_positions.json")) as fh:
        keys = json.load(fh)
    path = interpolate(keys, duration=1.0, fps=6)
    for s, p in zip(specs, path):
        o, t, u, mirror = go_draaw_look_at(p[:3], p[3], p[4], 50.0)
        assert np.allclose(s["camera"]["origin"], o) and np.allclose(s["camera"]["target"], t)
        assert s["camera"].get("mirror", False) == mirror


def test_go_draaw_keyframe_frames_show_go_draaws_view(tmp_path):
    """A GO-Draaw keyframe path through sin φ > 0 and sin φ < 0: each frame shows a glowing
    ball where GO-Draaw's image patch (numpy, from the spec) has it, a fifth of the way
    across (the φ > 0 frame was the left-right mirror image, the ball at column ~25 of 32);
    the frame's camera says ``mirror`` only there, and its hash is the same at every load."""
    from conftest import bright_column, glowing_ball, go_draaw_patch_point, go_draaw_patch_uv
    ball, fov = np.array([0.0, 0.5, 0.0]), 45.0
    keys = []
    for theta, phi in ((0.3, 1.2), (0.3, -2.08)):
        # the camera 3 units back from the ball along the patch's ray at (u, v) = (0.2, 0.5)
        position = ball - (go_draaw_patch_point([0, 0, 0], theta, phi, fov, 0.2, 0.5, 3.0))
        keys.append([*position.tolist(), theta, phi])
    scene = os.path.join(str(tmp_path), "ball.toml")
    with open(scene, "wb") as fh:
        tomli_w.dump(glowing_ball({"origin": [0, 0, 5], "target": [0, 0, 0]}, ball), fh)
    doc = manifest(tmp_path, frames=2, scene=scene, version="path",
                   camera={"keyframes": keys, "fov": fov})
    del doc["jobs"][0]["params"]
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 2 and not res.failed
    _, specs, _ = batch.load(doc)
    for s, k in zip(specs, keys):
        u, _ = go_draaw_patch_uv(k[:3], k[3], k[4], fov, ball)
        col = bright_column(draaw_mi.read_exr(s["output"]))
        assert col == pytest.approx(u * 32, abs=3.0), (k, col, u * 32)
        assert s["camera"].get("mirror", False) == (math.sin(k[4]) > 0)
    assert [s["hash"] for s in specs] == [s["hash"] for s in batch.load(doc)[1]]


@pytest.mark.parametrize("phi, mirrored", [(1.2, True), (-2.08, False)])
def test_frames_of_a_scenes_own_mirrored_go_draaw_camera_are_rehashed(tmp_path, phi, mirrored):
    """A job without a camera renders the scene's own; a GO-Draaw [camera] with sin φ > 0
    renders mirrored since the fix, and its frames made before stayed "done" (same hash).
    They are re-hashed; every other frame keeps its hash (the key is absent there)."""
    from draaw_mi.batch.planner import frame_hash
    desc = tiny_description()
    desc["camera"] = {"position": [0.0, 0.5, 5.0], "angles": [-1.3, phi], "fov": 40.0}
    scene = os.path.join(str(tmp_path), "s.toml")
    with open(scene, "wb") as fh:
        tomli_w.dump(desc, fh)
    doc = manifest(tmp_path, frames=1, scene=scene)
    del doc["jobs"][0]["camera"]
    spec = batch.load(doc)[1][0]
    assert spec["scene_camera_mirror"] is mirrored
    before = frame_hash({k: v for k, v in spec.items() if k != "scene_camera_mirror"})
    assert (spec["hash"] != before) is mirrored


CBOX_PATH = """<scene version="3.0.0"><integrator type="path"><integer name="max_depth" value="6"/>
<integer name="rr_depth" value="2"/></integrator><sensor type="perspective"><film type="hdrfilm">
<integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
<shape type="sphere"><bsdf type="diffuse"/></shape><emitter type="constant"/></scene>"""


@pytest.mark.parametrize("job, key", [
    ({"version": "path", "max_depth": 6}, "declared_integrator"),
    ({"version": "v4", "max_depth": 6, "aovs": ["depth"], "post": [{"type": "srgb"}]}, "post_by_channel_names"),
    ({"version": "v4", "max_depth": 6, "aovs": ["depth", "normal"], "post": [{"type": "srgb"}]}, None),
    ({"version": "path", "max_depth": 3}, None),
])
def test_frames_whose_pixels_changed_since_they_were_hashed_are_rehashed(tmp_path, job, key):
    """A declared ``path`` (rr_depth 2) now renders with its file's settings, and a post chain
    no longer takes an RGB film's single AOV for alpha: frames made before kept their hash,
    and a resumed batch kept them as done. They are re-hashed; other frames keep their hash
    (a depth of 3 is not the file's: a default path renders it, as before)."""
    from draaw_mi.batch.planner import CHANGED_KEYS, frame_hash
    scene = tmp_path / "s.xml"
    scene.write_text(CBOX_PATH)
    doc = {"output": os.path.join("out", "{job}", "{frame:04d}.exr"),
           "jobs": [{"name": "j", "scene": str(scene), "frames": 1, "spp": 1, **job}]}
    spec = batch.load(doc)[1][0]
    assert [k for k in CHANGED_KEYS if spec.get(k)] == ([key] if key else [])
    before = frame_hash({k: v for k, v in spec.items() if k not in CHANGED_KEYS})
    assert (spec["hash"] != before) is (key is not None)


def test_look_at_keyframes_take_mirror_as_a_scene_camera_does(tmp_path):
    """The README says a look-at camera takes mirror = true (the tuner saves mirrored GO-Draaw
    cameras so); a batch look_at keyframe refused it ("unknown key 'mirror'"). The mirrored
    frame is the plain frame flipped left-right; mixed keyframes are refused."""
    key = {"origin": [0.3, 1.0, 5.0], "target": [0.0, 0.5, 0.0]}
    doc = manifest(tmp_path, frames=1, version="path", spp=256, camera={"look_at": [key]})
    del doc["jobs"][0]["params"]
    doc["jobs"].append(dict(doc["jobs"][0], name="m", camera={"look_at": [dict(key, mirror=True)]}))
    res = batch.run(doc, progress=False)
    assert res.complete and not res.failed
    plain, mirrored = (draaw_mi.read_exr(s["output"]) for s in batch.load(doc)[1])
    cols = lambda img: img.mean(axis=(0, 2))                       # noqa: E731 (column means)
    flipped, same = (np.abs(cols(mirrored) - cols(p)).max() for p in (plain[:, ::-1], plain))
    assert flipped < 0.3 * same, (flipped, same)
    doc["jobs"][1]["camera"] = {"look_at": [dict(key, mirror=True), key]}
    doc["jobs"][1]["frames"] = 2
    with pytest.raises(draaw_mi.DraawError, match=r"look_at\[1\].mirror: False, keyframe 0 says True: .*all mirrored or none"):
        batch.load(doc)


def test_exr_layers_metadata_and_half(tmp_path):
    doc = manifest(tmp_path, frames=2, aovs=["depth", "normal"], half=True)
    batch.run(doc, progress=False)
    _, specs, _ = batch.load(doc)
    with OpenEXR.File(specs[1]["output"], separate_channels=True) as f:
        h = dict(f.header())
        chans = {n: c.pixels for n, c in f.channels().items()}
    assert set(chans) == {"R", "G", "B", "depth.Z", "N.X", "N.Y", "N.Z"}
    assert all(c.dtype == np.float16 and c.shape == (24, 32) for c in chans.values())
    assert h["draaw:frame_hash"] == specs[1]["hash"] and h["draaw:spp"] == 4
    assert h["draaw:seed"] == specs[1]["seed"] and h["draaw:version"] == "v4"\
        and h["draaw:integrator"] == "draaw_v4"
    assert h["draaw:mitsuba"] == "3.9.1" and h["draaw:draaw_mi"] == draaw_mi.__version__
    from draaw_mi.batch.planner import file_hash
    assert h["draaw:scene_sha256"] == file_hash(specs[1]["scene"])
    # depth is the distance to the first hit: about |camera - sphere| - radius at the centre
    o = np.array(specs[1]["camera"]["origin"])
    centre_depth = float(chans["depth.Z"][12, 16])
    assert abs(centre_depth - (np.linalg.norm(o - [0, 0.8, 0]) - 0.8)) < 0.1


@pytest.mark.parametrize("sampler", ["independent", "multijitter"])
def test_no_kernel_compiles_after_the_first_frame(tmp_path, sampler):
    """Also with a stratifying sampler, whose state in the scene changes after the first
    render (recorded with literals, it re-recorded and compiled anew at the third frame)."""
    doc = manifest(tmp_path, frames=4)
    doc["jobs"][0]["scene"] = write_scene(tmp_path, "strat.toml", sampler=sampler)
    res = batch.run(doc, progress=False)
    assert all(r["kernels"] for r in res.results)          # kernels were recorded
    assert [r.get("new_kernels") for r in res.results] == [None, 0, 0, 0]
    assert res.new_kernels == {"orbit": 0}


def test_kernel_check_sees_a_recompile(tmp_path):
    """The detector is not blind: a frame with another max_depth (a literal in the kernel)
    shows up as new kernels."""
    from draaw_mi.batch.executors import run_inprocess
    from draaw_mi.batch.planner import frame_hash

    m, specs, cache = batch.load(manifest(tmp_path, frames=3))
    specs[2]["max_depth"] = 2
    specs[2]["hash"] = frame_hash(specs[2])
    got = []
    run_inprocess(specs, cache, got.append)
    first = set(got[0]["kernels"])
    assert set(got[1]["kernels"]) <= first
    assert set(got[2]["kernels"]) - first


def test_kernel_signatures_ignore_alignment_not_code():
    """Kernels are told apart by their code without load alignments (which Dr.Jit takes from
    the buffers it is handed: a batch with previews warned of 2 recompiles that computed the
    same thing); another operation or literal is another kernel. Real history entries carry
    their code, so the signature is not the plain hash."""
    import io

    import drjit as dr
    from draaw_mi.batch.frame import kernel_signature

    name = "drjit_" + "0" * 32
    code = "define void @{}() {{ %f = load <8 x float>, ptr %p, align {} ; fmul %f, 2.0 }}"
    a = {"hash": 1, "ir": io.StringIO(code.format(name, 32))}
    b = {"hash": 2, "ir": io.StringIO(code.format("drjit_" + "f" * 32, 1))}
    c = {"hash": 3, "ir": io.StringIO(code.format(name, 32).replace("2.0", "3.0"))}
    assert kernel_signature(a) == kernel_signature(b) != kernel_signature(c)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        x = dr.arange(mi.Float, 64) * 3.0
        dr.eval(x)
        entry = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT][0]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert kernel_signature(entry) != str(entry["hash"])


def test_previews_and_contact_sheet(tmp_path):
    doc = manifest(tmp_path, frames=3, previews=True)
    doc["contact_sheet"] = True
    batch.run(doc, progress=False)
    out = tmp_path / "out" / "orbit"
    assert sorted(p.name for p in out.iterdir()) == ["0000.exr", "0000.png", "0001.exr", "0001.png",
                                                    "0002.exr", "0002.png", "orbit_contact.png"]
    assert sorted(p.name for p in out.parent.iterdir()) == ["batch.jsonl", "orbit"]


def test_out_dir_and_expansion(tmp_path):
    """A job over two versions expands to one job per version under ``--out``; each frame is
    that version's render (a version that did not reach the renderer left only the names
    right): frame 1 of each equals an independent render with its version, camera, roughness
    and seed, and the two versions' frames differ."""
    doc = manifest(tmp_path, frames=2, version=["v1", "v4"])
    doc["output"] = "{job}/{version}_{frame:02d}.exr"
    res = batch.run(doc, out=str(tmp_path / "elsewhere"), progress=False)
    assert res.complete
    names = sorted(frames_of(tmp_path / "elsewhere"))
    assert names == ["orbit-v1/v1_00.exr", "orbit-v1/v1_01.exr", "orbit-v4/v4_00.exr", "orbit-v4/v4_01.exr"]
    _, specs, _ = batch.load(doc, out=str(tmp_path / "elsewhere"))
    got = {}
    for s in (s for s in specs if s["output"].endswith("_01.exr")):
        scene = draaw_mi.load_scene(tiny_description())
        draaw_mi.render(scene, version=s["version"], seed=99, spp=1)    # (V4 learns as the batch does)
        p = scene.params
        p["sensor.to_world"] = mi.ScalarTransform4f().look_at(
            origin=s["camera"]["origin"], target=s["camera"]["target"], up=s["camera"]["up"])
        p[scene.key("ball.roughness")] = param_value("linear", (0.1, 0.9), 1, 2)
        p.update()
        ref = np.array(draaw_mi.render(scene, version=s["version"], seed=s["seed"], spp=4))
        got[s["version"]] = draaw_mi.read_exr(s["output"])
        assert np.array_equal(got[s["version"]], ref), s["version"]
    assert sorted(got) == ["v1", "v4"]
    assert not np.array_equal(got.popitem()[1], got.popitem()[1])


def test_example_manifest_plans(tmp_path):
    from conftest import SCENES
    m, specs, _ = batch.load(os.path.join(SCENES, "batch_example.toml"), out=str(tmp_path))
    assert [j.name for j in m.jobs] == ["turntable", "roughness_sweep"]
    assert len(specs) == 36 and specs[0]["resolution"] == [256, 256]
    assert all(s["output"].startswith(str(tmp_path)) for s in specs)


def test_scene_changed_after_planning_fails_the_frame(tmp_path):
    doc = manifest(tmp_path, frames=2)
    m, specs, cache = batch.load(doc)
    write_scene(tmp_path, spp=8)                           # same file, other content
    from draaw_mi.batch.frame import SceneCache, safe_render_frame
    r = safe_render_frame(specs[0], SceneCache())
    assert "changed since the batch was planned" in r["error"]


def test_frozen_frames_equal_retraced_frames(tmp_path):
    """Replaying the dr.freeze recording gives the same bits as tracing every frame anew,
    with the camera and an override changing every frame (and AOVs)."""
    doc = manifest(tmp_path, frames=4, aovs=["depth", "albedo"])
    doc["output"] = "{job}/{frame:04d}.exr"
    batch.run(doc, out=str(tmp_path / "frozen"), progress=False)
    doc["jobs"][0]["freeze"] = False
    _, specs, _ = batch.load(doc, out=str(tmp_path / "traced"))
    assert specs[0]["freeze"] is False
    batch.run(doc, out=str(tmp_path / "traced"), progress=False)
    a, b = frames_of(tmp_path / "frozen"), frames_of(tmp_path / "traced")
    assert_bit_identical(a, b)
    assert len({float(v[..., 0].mean()) for v in a.values()}) == 4        # the frames do differ


def test_post_chain_applies_to_colour_only(tmp_path):
    """A job's post chain equals draaw_mi.post.apply on the plain frame's colour; AOVs untouched."""
    chain = [{"type": "tint", "color": [1.0, 0.5, 0.25], "strength": 0.6}]
    doc = manifest(tmp_path, frames=2, aovs=["depth"])
    doc["output"] = "{job}/{frame:04d}.exr"
    batch.run(doc, out=str(tmp_path / "plain"), progress=False)
    doc["jobs"][0]["post"] = chain
    batch.run(doc, out=str(tmp_path / "post"), progress=False)
    plain, post = frames_of(tmp_path / "plain"), frames_of(tmp_path / "post")
    for k in plain:
        ref = np.array(draaw_mi.post.apply(plain[k][..., :3], chain))
        assert np.allclose(post[k][..., :3], ref, atol=1e-6) and not np.allclose(ref, plain[k][..., :3])
        assert np.array_equal(post[k][..., 3], plain[k][..., 3])


def test_doctests():
    import doctest

    import sys
    plan_mod = sys.modules["draaw_mi.batch.planner"]        # draaw_mi.batch.planner is also the function
    result = doctest.testmod(plan_mod)
    assert result.attempted >= 1 and result.failed == 0
    from draaw_mi.batch import lock
    result = doctest.testmod(lock)
    assert result.attempted >= 1 and result.failed == 0


def test_a_job_after_one_that_moved_a_light_renders_as_if_alone(tmp_path):
    """V4 keeps a light-selection table from the lights' powers. A job that dims a light and a
    job without overrides after it on the same scene: the second job's frames must be the bits
    it renders alone (the restored light must refresh the table; it kept the dimmed light's
    table, 1.4 off)."""
    desc = tiny_description()
    desc["lights"] = [{"type": "point", "position": [2.0, 4.0, 3.0], "intensity": 40.0},
                      {"type": "point", "position": [-2.0, 3.0, 1.0], "intensity": 5.0}]
    scene = os.path.join(str(tmp_path), "two_lights.toml")
    with open(scene, "wb") as fh:
        tomli_w.dump(desc, fh)
    dim = {"name": "dim", "scene": scene, "frames": 2, "spp": 4, "version": "v4",
           "params": {"point_light0.intensity.value": {"from": 1.0, "to": 2.0}}}
    plain = {"name": "plain", "scene": scene, "frames": 2, "spp": 4, "version": "v4"}

    def run(jobs, folder):
        doc = {"output": os.path.join(folder, "{job}", "{frame:04d}.exr"), "jobs": jobs}
        assert batch.run(doc, progress=False).complete
        return {k: v for k, v in frames_of(os.path.join(str(tmp_path), folder)).items()
                if k.startswith("plain")}
    after = run([dim, plain], "after")
    alone = run([plain], "alone")
    assert len(alone) == 2
    assert_bit_identical(after, alone)


def test_a_scene_is_loaded_once_per_run(tmp_path, monkeypatch):
    """Planning asks the cache for the scene at its own resolution (no override), frames ask
    with the spec's resolution: one load serves both (it loaded twice, and held both)."""
    from draaw_mi.batch import frame          # the module of the scene cache
    loads = []
    real = frame.load_scene

    def counting(*args, **kwargs):
        loads.append(kwargs.get("resolution"))
        return real(*args, **kwargs)
    monkeypatch.setattr(frame, "load_scene", counting)
    assert batch.run(manifest(tmp_path, frames=2), progress=False).complete
    assert loads == [None]
    # a job at another resolution is another scene
    loads.clear()
    (tmp_path / "b").mkdir()
    assert batch.run(manifest(tmp_path / "b", frames=1, resolution=[16, 12]), progress=False).complete
    assert loads == [(16, 12)]


def test_a_missing_or_stale_preview_comes_from_the_finished_exr(tmp_path, monkeypatch, capsys):
    """A run killed between a frame's PNG and EXR, or previews turned on after the frames were
    rendered: the EXR is finished, so the next run writes the PNG from it, renders nothing, and
    the run is complete only once every preview exists. A PNG of another frame (its hash) is
    replaced; one without a hash (older draaw-mi) is kept. (Before: the frame counted as done
    and its PNG never came.)"""
    import matplotlib.image
    from draaw_mi.batch import frame as frame_mod
    from draaw_mi.cli import main
    doc = manifest(tmp_path, frames=2)
    assert batch.run(doc, progress=False).rendered == 2            # no previews yet
    out = tmp_path / "out" / "orbit"
    doc["jobs"][0]["previews"] = True
    path = write_manifest(tmp_path, doc)
    assert main(["batch", path, "--status"]) == 1
    assert "2 without their preview" in capsys.readouterr().out
    stale = out / "0001.png"                                     # another frame's preview
    matplotlib.image.imsave(str(stale), np.zeros((4, 4, 3), np.uint8), metadata={"draaw:frame_hash": "0" * 32})

    def no_render(*a, **k):
        raise AssertionError("a finished frame was rendered again")
    monkeypatch.setattr(frame_mod.CachedScene, "render", no_render)
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 0 and res.previews == 2 and not res.failed
    for f in ("0000", "0001"):
        png = matplotlib.image.imread(str(out / f"{f}.png"))[..., :3]
        ref = draaw_mi.io.srgb_encode(draaw_mi.read_exr(str(out / f"{f}.exr"))[..., :3])
        assert png.shape == ref.shape and np.abs(png - ref).max() <= 0.5 / 255 + 1e-6
    assert batch.run(doc, progress=False).previews == 0          # now done
    assert main(["batch", path, "--status"]) == 0
    # a preview from before previews carried a hash (written after its EXR) stays this frame's
    matplotlib.image.imsave(str(out / "0000.png"), np.zeros((4, 4, 3), np.uint8))
    assert main(["batch", path, "--status"]) == 0


def test_previews_of_a_chain_that_ends_in_srgb_are_not_encoded_twice(tmp_path):
    """A job whose post chain ends in ``srgb`` writes display-encoded EXRs; its PNG previews
    and contact sheet hold those values as they are."""
    import matplotlib.image
    doc = manifest(tmp_path, frames=2, previews=True, post=[{"type": "srgb"}])
    doc["contact_sheet"] = True
    assert batch.run(doc, progress=False).complete
    out = tmp_path / "out" / "orbit"
    exr = draaw_mi.read_exr(str(out / "0000.exr"))[..., :3]
    png = matplotlib.image.imread(str(out / "0000.png"))[..., :3]
    assert np.abs(png - np.clip(exr, 0, 1)).max() <= 0.5 / 255 + 1e-6
    sheet = matplotlib.image.imread(str(out / "orbit_contact.png"))[..., :3]
    assert np.abs(sheet[:exr.shape[0], :exr.shape[1]] - np.clip(exr, 0, 1)).max() <= 0.5 / 255 + 1e-6


def test_a_contact_sheet_that_cannot_be_written_leaves_the_run_complete(tmp_path, monkeypatch, capsys):
    """Every frame rendered, then the sheet fails: the result (and the exit status) say the
    frames are all there and the summary says why there is no sheet (it was exit 2 and no
    summary, as for a bad manifest)."""
    from draaw_mi.batch import runner        # the module that writes the sheets
    from draaw_mi.cli import main
    from draaw_mi.errors import IOFailure

    def failing(specs, damaged=None):
        raise IOFailure("write_png('x_contact.png'): disk full")
    monkeypatch.setattr(runner, "contact_sheets", failing)
    doc = manifest(tmp_path, frames=2)
    doc["contact_sheet"] = True
    path = write_manifest(tmp_path, doc)
    assert main(["batch", path, "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "all 2 frames present" in out and "contact sheets not written: write_png" in out


def test_pattern_fields_version_and_spp_are_the_frames_own(tmp_path):
    """A job without version/spp wrote into ``default_default_0000.exr`` (and ``{spp:03d}``
    failed): the fields take the scene's settings, as the frame renders them."""
    doc = manifest(tmp_path, frames=1)
    del doc["jobs"][0]["spp"]
    doc["output"] = "out/{version}_{spp:03d}_{frame:04d}.exr"
    _, specs, _ = batch.load(doc)
    scene = draaw_mi.load_scene(doc["jobs"][0]["scene"])
    want = f"{scene.settings['version']}_{scene.settings['spp']:03d}_0000.exr"
    assert os.path.basename(specs[0]["output"]) == want and specs[0]["spp"] == scene.settings["spp"]


def test_a_frames_header_says_what_it_shows(tmp_path):
    """Its overrides, camera and post chain, readable from the file (a frame's roughness could
    not be read back)."""
    chain = [{"type": "contrast", "amount": 0.5}]
    doc = manifest(tmp_path, frames=2, post=chain)
    batch.run(doc, progress=False)
    _, specs, _ = batch.load(doc)
    h = batch.read_header(specs[1]["output"])
    assert json.loads(h["draaw:params"]) == {"ball.roughness.value": 0.9}
    cam = json.loads(h["draaw:camera"])
    assert np.allclose(cam["origin"], specs[1]["camera"]["origin"]) and cam["fov"] == specs[1]["camera"]["fov"]
    assert json.loads(h["draaw:post"]) == specs[1]["post"] and specs[1]["post"][0]["type"] == "contrast"


@pytest.mark.parametrize("axis", ["y", "smaller", "diagonal"])
def test_a_camera_tables_fov_is_measured_as_the_scenes(tmp_path, axis):
    """A scene whose fov is along y (or another axis): a job whose camera table is the scene's
    own view renders the frame the scene renders without a camera table (the fov went into
    Mitsuba's x_fov as it was: 30 degrees along y on a 2:1 film is 56.4 along x)."""
    desc = tiny_description(resolution=[16, 8])
    desc["camera"]["fov_axis"] = axis
    scene = tmp_path / "fy.toml"
    scene.write_bytes(tomli_w.dumps(desc).encode())
    view = {k: desc["camera"][k] for k in ("origin", "target")}
    doc = {"output": "out/{job}/{frame:04d}.exr", "jobs": [
        {"name": "plain", "scene": str(scene), "frames": 1, "spp": 4},
        {"name": "table", "scene": str(scene), "frames": 1, "spp": 4,
         "camera": {"look_at": [dict(view, up=[0.0, 1.0, 0.0])]}}]}
    res = batch.run(doc, progress=False)
    assert res.complete and not res.failed
    frames = frames_of(tmp_path / "out")
    plain, table = frames[os.path.join("plain", "0000.exr")], frames[os.path.join("table", "0000.exr")]
    assert np.array_equal(plain, table)


def test_a_job_without_a_seed_or_chain_takes_its_scenes(tmp_path):
    """Two scenes that differ only in render.seed give different frames, each the frame's seed
    drawn from its scene's; a scene's own post chain is what the header records."""
    chain = [{"type": "contrast", "contrast": 1.5}]
    jobs = []
    for seed in (1, 99):
        desc = tiny_description(resolution=[8, 6], seed=seed)
        desc["post"] = chain
        path = tmp_path / f"s{seed}.toml"
        path.write_bytes(tomli_w.dumps(desc).encode())
        jobs.append({"name": f"s{seed}", "scene": str(path), "frames": 1, "spp": 4})
    doc = {"output": "out/{job}/{frame:04d}.exr", "jobs": jobs}
    assert batch.run(doc, progress=False).complete
    _, specs, _ = batch.load(doc)
    assert [s["seed"] for s in specs] == [frame_seed(1, 0), frame_seed(99, 0)]
    a, b = (draaw_mi.read_exr(s["output"]) for s in specs)
    assert not np.array_equal(a, b)
    ref = draaw_mi.render(draaw_mi.load_scene(jobs[1]["scene"]), spp=4, seed=frame_seed(99, 0))
    assert np.array_equal(b, np.array(ref))
    assert json.loads(batch.read_header(specs[0]["output"])["draaw:post"]) == chain


def test_a_cut_short_preview_is_written_again(tmp_path):
    """A PNG cut short (a full disk, a copy stopped) still carries its frame's hash, which comes
    ahead of the pixels: it counted as this frame's finished preview and was never mended."""
    from PIL import Image
    doc = manifest(tmp_path, frames=1, previews=True)
    assert batch.run(doc, progress=False).rendered == 1
    png = tmp_path / "out" / "orbit" / "0000.png"
    whole = png.read_bytes()
    png.write_bytes(whole[:len(whole) - 20])                     # the IEND chunk and a bit more
    res = batch.run(doc, progress=False)
    assert res.rendered == 0 and res.previews == 1 and res.complete
    assert png.read_bytes() == whole
    with Image.open(png) as im:
        im.load()                                                # reads to the end: whole
