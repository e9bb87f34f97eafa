"""A preview of a Mitsuba user's own XML scene: values refused at update() whatever their type
or where their object's name comes from, a failed frame that does not outlive close(), and a
depth that version 'scene' does not apply said so."""
from __future__ import annotations

import gc
import warnings
import weakref

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import ParameterError
from draaw_mi.rendering.preview import Preview

XML = """<scene version="3.0.0">
  <integrator type="path"/>
  <sensor type="perspective" id="cam"><transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
  <shape type="rectangle"><transform name="to_world"><translate z="-1"/></transform>
    <emitter type="area" id="lamp"><rgb name="radiance" value="2"/></emitter></shape>
  <shape type="sphere" id="ball"><bsdf type="roughconductor" id="metal"><float name="alpha" value="0.2"/></bsdf></shape>
  <medium type="homogeneous" id="fog"><rgb name="albedo" value="0.8"/>
    <float name="sigma_t" value="0.05"/><phase type="hg"><float name="g" value="0.3"/></phase></medium>
  <shape type="cube"><transform name="to_world"><scale value="3"/></transform><bsdf type="null"/>
    <ref name="interior" id="fog"/></shape>
  <emitter type="envmap" id="sky"><string name="filename" value="{sky}"/></emitter>
</scene>"""


@pytest.fixture
def xml_scene(tmp_path):
    sky = tmp_path / "sky.exr"
    mi.Bitmap(np.full((4, 8, 3), 0.5, np.float32)).write(str(sky))
    path = tmp_path / "s.xml"
    path.write_text(XML.format(sky=sky))
    return str(path)


@pytest.mark.parametrize("name, value, match", [
    ("fog.phase_function.g", 1.5, r"expected a Henyey-Greenstein g"),        # (rendered pixels of -0.41)
    ("fog.sigma_t", -1.0, r"expected an extinction >= 0"),
    ("fog.albedo", 1.5, r"expected values in \[0, 1\]"),
    ("fog.scale", -1.0, r"expected a density scale >= 0"),
    ("sky.scale", -1.0, r"expected values >= 0"),                           # (the whole frame negative)
    ("sky.data", "nan", r"value\(s\) outside"),                               # (a TensorXf of NaN)
    ("ball.bsdf.alpha", [0.1, 0.2, 0.3], r"holds one number \(a uniform value.*\); expected one"),  # (Mitsuba's words at the frame)
    ("cam.near_clip", -1.0, r"expected a near clip distance > 0"),          # (every frame blank)
    ("sky.sampling_weight", -1.0, r"expected values >= 0"),
    ("sky.data", "nan list", r"texel value\(s\) outside"),                 # (a 1154-character "expected numbers")
    ("lamp.radiance", "nan colour", r"expected finite numbers"),          # (had said "a transform or matrix")
    ("cam.film.size", [8, 8], r"the film's size is the scene's resolution"),   # (had said "an RGB colour")
])
def test_bad_values_of_an_xml_scene_are_refused_at_the_update(xml_scene, name, value, match):
    """Each was taken and rendered wrong frames (negative, NaN, blank) or failed at the next
    frame in Mitsuba's words: a medium declared at the top of an XML file has keys of its own id
    (``fog.*``: no 'medium' in them), Dr.Jit texels went unchecked, negative texels of a light
    were let through. The preview goes on after each refusal."""
    pv = Preview(draaw_mi.load_scene(xml_scene), version="v4", max_depth=3, freeze=False)
    try:
        key = pv.key(name)
        if value == "nan colour":
            value = mi.Color3f(float("nan"), 0.0, 0.0)
        elif isinstance(value, str):          # texels of the envmap's shape
            shape = np.array(pv.scene.params[key]).shape
            value = (np.full(shape, np.nan).tolist() if value == "nan list"
                     else mi.TensorXf(np.full(shape, np.nan, np.float32)))
        with pytest.raises(ParameterError, match=match):
            pv.update({name: value})
        assert pv.step() is not None and pv.error is None
    finally:
        pv.close()


def test_a_failed_frame_does_not_keep_the_scene_after_close(xml_scene):
    """The error a failed frame left in ``Preview.error`` held, through its traceback, the
    list of scenes the worker was updating: the scene outlived close() and was freed later,
    outside the render guard."""
    scene = draaw_mi.load_scene(xml_scene)
    pv = Preview(scene, version="v4", max_depth=3, freeze=False)
    pv.step()
    key = scene.key("ball.bsdf.alpha")
    pv._pending[key] = mi.TensorXf(np.zeros(3, np.float32))   # (past the checks: fails at the frame)
    try:
        pv._apply_pending()                    # (what the worker runs; it keeps the error)
    except Exception as e:  # noqa: BLE001
        pv.error = e
    assert pv.error is not None and pv.error.__traceback__ is not None
    pv.close()
    alive = weakref.ref(scene)
    del scene
    gc.collect()
    assert alive() is None
    assert pv.error is not None and pv.error.__traceback__ is None


def test_a_depth_for_version_scene_is_said_not_to_apply(xml_scene):
    """The frames stayed as they were (the scene's integrator keeps its own depth), and the
    tuner's depth slider moved without effect: said, as render() says it."""
    with pytest.warns(RuntimeWarning, match=r"Preview: version 'scene' renders with the integrator the scene "
                                            r"declares.*max_depth=1 not applied"):
        pv = Preview(draaw_mi.load_scene(xml_scene), version="scene", max_depth=1, freeze=False)
    try:
        with pytest.warns(RuntimeWarning, match=r"Preview.configure: .*max_depth=2 not applied"):
            pv.configure(max_depth=2)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            pv.configure(version="v4", max_depth=2)                   # (a version that takes it)
    finally:
        pv.close()


def test_a_meshs_vertex_array_passes_as_it_is():
    """Dr.Jit values are read as numbers where they are one number, one colour or texels; a
    mesh's vertex array (an override of a batch or a preview) is not a colour of 12 numbers."""
    from draaw_mi.materials.checks import check_value
    check_value("demo", "m.vertex_positions", "m.vertex_positions", mi.Float(np.arange(12.0)))
    with pytest.raises(ParameterError, match=r"demo: l.radiance=.*expected finite numbers"):
        check_value("demo", "l.radiance", "l.emitter.radiance.value", mi.Color3f(float("nan"), 0.0, 0.0))


def test_what_the_checks_must_let_through(xml_scene):
    """What a review of these checks found them refusing, or no longer checking: an envmap's
    negative texels (a resampled EXR's overshoot, which the loader takes; the tuner's light
    colour sends them); a light's to_world as a numpy matrix (its negative entries read as
    texels); a material named like a nested medium's or emitter's dict key (``interior``:
    checked as a medium's, so its roughness went unchecked)."""
    import tomllib
    pv = Preview(draaw_mi.load_scene(xml_scene), version="v4", max_depth=2, freeze=False)
    try:
        texels = np.array(pv.scene.params[pv.key("sky.data")])
        texels[0, 0, 0] = -0.001
        pv.update({"sky.data": texels})
        pv.update({"sky.to_world": np.array(mi.ScalarTransform4f().rotate([0, 1, 0], 30).matrix)})
        assert pv.step() is not None and pv.error is None
    finally:
        pv.close()
    with open("scenes/smoke.toml", "rb") as fh:
        desc = tomllib.load(fh)
    desc["materials"]["interior"] = desc["materials"].pop("floor")
    for shape in desc.get("shapes", []):
        if shape.get("material") == "floor":
            shape["material"] = "interior"
    desc["render"] = {**desc.get("render", {}), "resolution": [8, 8]}
    pv = Preview(draaw_mi.load_scene(desc), version="v4", max_depth=2, freeze=False)
    try:
        with pytest.raises(ParameterError, match=r"interior.roughness=5.0; expected a number in \[0.0, 1.0\]"):
            pv.update({"interior.roughness": 5.0})
    finally:
        pv.close()


def test_close_keeps_the_errors_causes():
    """close() dropped the stored error's cause with its traceback: the tuner, which shows the
    innermost error, showed only Dr.Jit's "error (see above)"."""
    pv = Preview(draaw_mi.load_scene({"render": {"resolution": [4, 4]}, "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]},
                                      "shapes": [{"type": "sphere"}], "lights": [{"type": "constant"}]}), freeze=False)
    try:
        raise RuntimeError("drjit.custom(): error (see above)") from ValueError("NaN in roughness")
    except RuntimeError as e:
        pv.error = e
    pv.close()
    assert isinstance(pv.error.__cause__, ValueError) and pv.error.__traceback__ is None
    assert pv.error.__cause__.__traceback__ is None
