"""fit() with files: textures fitted and written back in their shape, an SDF object's
parameters, PNG references, where a fit is saved, plots written to files (split from
test_fit.py, whose helpers these share)."""
from __future__ import annotations

import os

import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main
from draaw_mi.errors import DraawError

from conftest import SCENES
from test_fit import _version


TEXTURE = np.full((8, 8, 3), 0.5, np.float32)
TEXTURE[:4] = [0.8, 0.2, 0.1]                    # two tones: top half red, bottom half grey


def _textured(folder, extra: str = ""):
    """A textured quad under a point light; the scene names its texture relatively."""
    folder.mkdir(exist_ok=True)
    draaw_mi.write_exr(str(folder / "tex.exr"), TEXTURE)
    (folder / "quad.toml").write_text(
        '[render]\nresolution = [24, 24]\nspp = 4\nmax_depth = 3\nfilter = "box"\n'
        '[camera]\norigin = [0, 0, 3]\ntarget = [0, 0, 0]\nfov = 40\n'
        f'[materials.m]\nbase_color = "tex.exr"\nroughness = 0.6\n{extra}'
        '[[shapes]]\ntype = "rectangle"\nmaterial = "m"\nname = "q"\nscale = 0.9\n'
        '[[lights]]\ntype = "point"\nposition = [0, 0, 2]\nintensity = 10.0\n')
    return folder / "quad.toml"


def test_a_texture_is_fitted_and_given_back_in_its_shape(tmp_path):
    """A base-colour texture fitted from a flat 0.3 to a path-traced reference of the two-tone
    truth. The fitted texels are returned and set in the texture's (8, 8, 3) shape (a flat list
    made the final ``params.update()`` raise, after every iteration had run); the history keeps
    a texture's summary per iteration (its channel means, also the latent's in linear space).
    Measured over 4 fit seeds (120 iterations): mean |error| 0.0033-0.0048, each half's mean
    colour within 0.0021 of the truth, against 0.233 at the start (40 iterations stop short:
    the red half at 0.835)."""
    path = _textured(tmp_path)
    ref = np.array(draaw_mi.render(str(path), version="path", spp=256, seed=99))
    scene = draaw_mi.load_scene(str(path))
    res = draaw_mi.fit(scene, ref, ["m.base_color"], version=_version(), spp=4, iterations=120,
                       progress=False, init={"m.base_color": np.full((8, 8, 3), 0.3, np.float32)})
    fitted = res.values["m.base_color"]
    assert isinstance(fitted, np.ndarray) and fitted.shape == (8, 8, 3)
    assert np.abs(fitted - TEXTURE).mean() < 0.01
    np.testing.assert_allclose(fitted[:4].mean(axis=(0, 1)), [0.8, 0.2, 0.1], atol=0.006)
    np.testing.assert_allclose(fitted[4:].mean(axis=(0, 1)), [0.5, 0.5, 0.5], atol=0.006)
    np.testing.assert_array_equal(np.array(scene.params["m.base_color.data"]), fitted)
    # the history keeps each iterate's summary (channel means, mean deviations), not a copy
    last = res.history[-1]["values"]["m.base_color"]
    assert len(last) == 6 and np.allclose(last[:3], fitted.reshape(-1, 3).mean(0), atol=0.01)
    # a map's latent is its logits, the optimiser's own units (settled compares their drift
    # with its steps): red's mean texel 0.65 is logit 0.62 to 0.71, not the value
    latent = res.history[-1]["latent"]["m.base_color"]
    assert len(latent) == 6 and 0.5 < latent[0] < 0.9 and latent[1] < 0 and latent[2] < 0
    assert res.plot() is not None                  # per-channel means of the texels
    assert res.converged


def test_a_map_fit_still_moving_is_not_converged(tmp_path):
    """The fit above stopped at 40 iterations: the red half at 0.725 of 0.8, still climbing.
    ``converged`` had read True (the map's drift, in value units, was compared with steps in
    logit units); its logits' drift now says it moves. The reported values are the same as
    before the history kept summaries (its texels averaged over the run's last quarter)."""
    path = _textured(tmp_path)
    ref = np.array(draaw_mi.render(str(path), version="path", spp=256, seed=99))
    res = draaw_mi.fit(draaw_mi.load_scene(str(path)), ref, ["m.base_color"], version=_version(), spp=4,
                       iterations=40, progress=False,
                       init={"m.base_color": np.full((8, 8, 3), 0.3, np.float32)})
    assert res.values["m.base_color"][:4, :, 0].mean() < 0.76
    assert not res.converged


def test_cli_fit_of_a_texture_writes_it_beside_the_scene_elsewhere(tmp_path, capsys):
    """``draaw-mi fit --param m.base_color -o OTHER/fitted.toml``: the fitted texture goes to
    an EXR beside the written scene, which names it; the scene's other relative file names
    (a roughness texture) are rewritten for the new folder (written elsewhere, the scene did
    not load). A scene that cannot be written back fails before the fit."""
    draaw_mi.write_png(str(tmp_path / "rough.png"), np.full((4, 4, 3), 0.6, np.float32))
    src = _textured(tmp_path / "a")
    src.write_text(src.read_text().replace("roughness = 0.6", 'roughness = "../rough.png"'))
    ref_path = str(tmp_path / "ref.exr")
    draaw_mi.write_exr(ref_path, np.array(draaw_mi.render(str(src), version="path", spp=64, seed=5)))
    out = tmp_path / "b" / "c" / "fitted.toml"
    assert main(["fit", str(src), "--reference", ref_path, "--param", "m.base_color", "--iterations", "6",
                 "--spp", "4", "--version", _version(), "-o", str(out)]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "m.base_color = texture 8x8x3" in printed and "fitted.m.base_color.exr" in printed
    fitted = draaw_mi.load_scene(str(out))
    assert fitted.description["materials"]["m"]["base_color"] == "fitted.m.base_color.exr"
    assert fitted.description["materials"]["m"]["roughness"] == os.path.join("..", "..", "rough.png")
    written = draaw_mi.read_exr(str(tmp_path / "b" / "c" / "fitted.m.base_color.exr"))
    np.testing.assert_allclose(np.array(fitted.params["m.base_color.data"]), written[..., :3], atol=1e-6)
    assert not np.allclose(written[..., :3], TEXTURE)          # (6 steps: moved, not converged)
    # a value that cannot be written back is said before any texture file is written
    from draaw_mi.fitting.result import FitResult
    bad = FitResult(values={"nomat.base_color": np.zeros((2, 2, 3), np.float32)})
    with pytest.raises(DraawError, match="nomat"):
        bad.save(str(tmp_path / "d" / "x.toml"), fitted)
    assert not (tmp_path / "d").exists()
    # an XML scene has no description to write into: the values only, to JSON; said before fitting
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm"><integer '
                   'name="width" value="24"/><integer name="height" value="24"/></film></sensor></scene>')
    assert main(["fit", str(xml), "--reference", ref_path, "--param", "m.base_color", "-o",
                 str(tmp_path / "x.toml")]) == 2
    assert "only the values can be written" in capsys.readouterr().err


def test_an_sdf_objects_radius_and_a_material_are_fitted_and_saved(tmp_path):
    """``sdf.NODE.PARAM`` is fitted like a material parameter (the tracer's interior gradient;
    silhouettes are not differentiated, sdf/integration.py) and written back to its [[sdf]]
    table. Started 0.15 below the true radius 0.8 and at grey: over fit seeds 0-3 (30
    iterations, 8 spp, 48x36) the radius ended at 0.795-0.810 and the colour within 0.04 of
    (0.8, 0.3, 0.2); the tolerances are about 2.5 times that."""
    import copy
    from sdf_helpers import base_description
    d = base_description((48, 36))
    d["sdf"] = [{"type": "sphere", "name": "obj", "material": "ball", "center": [0.0, 0.8, 0.0],
                 "radius": 0.8}]
    truth = draaw_mi.load_scene(d)
    ref = draaw_mi.render(truth, version="v4", spp=512, seed=99, post=[])
    start = copy.deepcopy(d)
    start["sdf"][0]["radius"] = 0.65
    start["materials"]["ball"]["base_color"] = [0.5, 0.5, 0.5]
    scene = draaw_mi.load_scene(start)
    res = draaw_mi.fit(scene, ref, params=["sdf.obj.radius", "ball.base_color"], iterations=30, spp=8,
                       progress=False, seed=0, lr=0.05)
    assert abs(res.values["sdf.obj.radius"] - 0.8) < 0.025, res.values
    assert np.abs(np.array(res.values["ball.base_color"]) - [0.8, 0.3, 0.2]).max() < 0.1, res.values
    out = str(tmp_path / "fitted.toml")
    res.save(out, scene)
    again = draaw_mi.load_scene(out)
    assert float(again.sdf.nodes["obj"].radius[0]) == pytest.approx(res.values["sdf.obj.radius"], rel=1e-6)


def test_a_png_reference_fits_as_its_exr_does(tmp_path):
    """A PNG is clipped to [0, 1] when written; its saturated pixels (6 % here, the light and
    its highlight) counted as if the render should be 1 there: roughness 0.37 / metallic 0.54
    for a truth of 0.25 / 0.8. They are left out of the loss now. Over fit seeds 0-3 (64x64,
    60 iterations, 8 spp) the fit ended at roughness 0.257-0.258, metallic 0.778-0.793; the
    tolerances are about three times the distance to the truth."""
    scene = draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=(64, 64))
    p = scene.params
    p[scene.key("target.roughness")] = 0.25
    p[scene.key("target.metallic")] = 0.8
    p.update()
    img = draaw_mi.render(scene, version="path", spp=256, seed=5)
    assert (np.array(img) > 1).mean() > 0.03                      # the case: clipped pixels
    png = str(tmp_path / "ref.png")
    draaw_mi.write_png(png, img)
    fresh = draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=(64, 64))
    res = draaw_mi.fit(fresh, png, params=["target.roughness", "target.metallic"], iterations=60,
                       spp=8, progress=False, seed=0)
    assert abs(res.values["target.roughness"] - 0.25) < 0.025, res.values
    assert abs(res.values["target.metallic"] - 0.8) < 0.06, res.values


def test_a_fit_is_saved_beside_a_scene_given_by_its_path(tmp_path):
    """``res.save("fitted.toml", "scenes/fit_sphere.toml")`` said that without a TOML/JSON
    scene only the values could be written, though the path named one."""
    from draaw_mi.fitting.result import FitResult
    out = str(tmp_path / "fitted.toml")
    FitResult(values={"target.roughness": 0.31}).save(out, os.path.join(SCENES, "fit_sphere.toml"))
    again = draaw_mi.load_scene(out)
    assert float(again.params[again.key("target.roughness")][0]) == pytest.approx(0.31)


def test_plots_written_to_files_leave_the_session_backend_alone(tmp_path):
    """``FitResult.plot(path)`` (and the study's and the SDF study's plots) called
    ``matplotlib.use("Agg")``: a notebook's inline backend was gone for the rest of the session."""
    import matplotlib
    from draaw_mi.fitting.result import FitResult
    before = matplotlib.get_backend()
    matplotlib.use("pdf")            # a backend none of them would pick
    try:
        res = FitResult(values={"a.roughness": 0.3},
                        history=[{"loss": 1.0 / (i + 1), "values": {"a.roughness": 0.3 + 0.01 * i}}
                                 for i in range(5)])
        fig = res.plot(str(tmp_path / "fit.png"))
        assert matplotlib.get_backend() == "pdf"
        assert (tmp_path / "fit.png").stat().st_size > 1000 and fig.axes[1].get_ylabel() == "value"
    finally:
        matplotlib.use(before)


def test_fitted_values_are_written_as_the_float32_the_scene_holds(tmp_path):
    """The saved TOML said ``roughness = 0.3808232992887497`` (a fit's value as a Python float)
    where the scene holds the float32 0.3808233: the shortest decimal of the same float32 is
    written, and loads back to the same float32."""
    import tomllib
    from draaw_mi.fitting.result import FitResult
    fitted = {"target.roughness": 0.3808232992887497, "target.base_color": [float(np.float32(0.1))] * 3}
    out = str(tmp_path / "fitted.toml")
    FitResult(values=fitted).save(out, os.path.join(SCENES, "fit_sphere.toml"))
    text = open(out).read()
    assert "roughness = 0.3808233\n" in text and "0.3808232992887497" not in text
    mat = tomllib.loads(text)["materials"]["target"]
    assert mat["base_color"] == [0.1, 0.1, 0.1]
    again = draaw_mi.load_scene(out)
    assert np.float32(again.params[again.key("target.roughness")][0]) == np.float32(0.3808232992887497)
    json_out = str(tmp_path / "fitted.json")
    FitResult(values={"a.roughness": 0.7718944549560547}).save(json_out)
    assert open(json_out).read().split() == ['{', '"fitted":', '{', '"a.roughness":', '0.77189445', '}', '}']


def test_a_start_value_out_of_range_is_refused_before_the_fit(tiny_scene):
    """A roughness of NaN set through scene.params went on to "got a zero gradient", then
    "diverged to NaN/Inf ... try a smaller lr"; it is refused as an init of NaN is."""
    import mitsuba as mi
    ref = np.full((24, 32, 3), 0.2, np.float32)
    p = tiny_scene.params
    key = tiny_scene.key("ball.roughness")
    for bad, shown in ((float("nan"), "nan"), (-0.5, "-0.5")):
        p[key] = mi.Float(bad)
        p.update()
        with pytest.raises(draaw_mi.ParameterError, match=rf"fit: ball.roughness starts at {shown} \(its value "
                                                         r"in the scene\); expected values in \[0.0, 1.0\]"):
            draaw_mi.fit(tiny_scene, ref, params=["ball.roughness"], iterations=1, progress=False)
    # an init in range is the start instead: no refusal
    res = draaw_mi.fit(tiny_scene, ref, params=["ball.roughness"], iterations=1, progress=False,
                       init={"ball.roughness": 0.4})
    assert np.isfinite(res.values["ball.roughness"])


def test_numpy_integers_are_counts_and_floats_are_not():
    """``fit(iterations=np.int64(2))`` was refused ("expected an integer >= 1") where render,
    load_scene and with_resolution take NumPy integers."""
    from draaw_mi.fitting.settings import check_counts
    check_counts("fit", iterations=(np.int64(2), 1), spp=(np.uint32(4), 1))
    for bad in (2.0, True, np.float64(2.0)):
        with pytest.raises(draaw_mi.ParameterError, match=r"fit: iterations=.*; expected an integer >= 1"):
            check_counts("fit", iterations=(bad, 1))


def test_bad_fit_input_raises_the_typed_errors(tiny_scene, tmp_path):
    """A reference of another aspect ratio, a NaN in it, a version that is not differentiable,
    two references for one view and an unreadable reference raised the bare DraawError, which
    ``except draaw_mi.ParameterError`` (or IOFailure) let through."""
    good = np.full((24, 32, 3), 0.2, np.float32)
    nan = good.copy()
    nan[1, 2, 0] = np.nan
    cases = [(dict(references=np.full((17, 32, 3), 0.2, np.float32)), draaw_mi.ParameterError, "another aspect"),
             (dict(references=nan), draaw_mi.ParameterError, r"NaN or Inf \(first at x=2, y=1\)"),
             (dict(references=good, version="path"), draaw_mi.ParameterError, "not differentiable"),
             (dict(references=[good, good]), draaw_mi.ParameterError, r"2 reference\(s\) for 1 view"),
             (dict(references=str(tmp_path / "nothing.exr")), draaw_mi.IOFailure, "nothing.exr.* does not exist")]
    for kwargs, error, says in cases:
        with pytest.raises(error, match=says):
            draaw_mi.fit(tiny_scene, params=["ball.roughness"], iterations=1, progress=False, **kwargs)


def test_a_roughness_started_at_the_floor_is_warned_about(tiny_scene):
    """From roughness 0 (or 0.02) a fit towards 0.26 stayed near 0.07 after 150 iterations:
    below about twice the floor (0.019) the alpha clamp leaves little gradient. Said; a start
    of 0.3 is not."""
    import warnings
    ref = np.full((24, 32, 3), 0.2, np.float32)
    for start in (0.0, 0.02):
        with pytest.warns(RuntimeWarning, match=rf"fit: ball.roughness starts at {start:g}, near 0.019.*"
                                                r"init=\{'ball.roughness': 0.3\}"):
            draaw_mi.fit(tiny_scene, ref, params=["ball.roughness"], iterations=1, progress=False,
                         init={"ball.roughness": start})
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message="fit: ball.roughness starts at")
        draaw_mi.fit(tiny_scene, ref, params=["ball.roughness"], iterations=1, progress=False,
                     init={"ball.roughness": 0.3})


@pytest.mark.parametrize("encoding", ["unsigned", "signed"])
def test_a_fitted_normal_map_stays_in_its_encodings_range_and_reloads(tmp_path, encoding):
    """A normal map had no range: it was fitted texel by texel without projection, reached
    2.1 and the saved scene was refused at its next load ("normalmap=2.12138 (texture values)
    is above 1.01"). It is fitted as a map in its encoding's range ([0, 1] unsigned, [-1, 1]
    signed): a reference of a strongly tilted truth pulls a flat start to the bound."""
    from draaw_mi.fitting.params import range_for
    lo = 0.0 if encoding == "unsigned" else -1.0
    flat = np.zeros((4, 4, 3), np.float32) + np.float32([(lo + 1) / 2, (lo + 1) / 2, 1.0])
    tilted = flat.copy()
    tilted[..., 0] = 1.0
    for name, texels in (("flat", flat), ("tilted", tilted)):
        draaw_mi.write_exr(str(tmp_path / f"{name}.exr"), texels)
    extra = f'normalmap = "{{}}.exr"\nnormalmap_encoding = "{encoding}"\n'
    ref = np.array(draaw_mi.render(str(_textured(tmp_path / "t", extra.format("../tilted"))), spp=16, seed=1))
    path = _textured(tmp_path / "s", extra.format("../flat"))
    scene = draaw_mi.load_scene(str(path))
    assert range_for("m.normalmap.data", scene) == (lo, 1.0)
    res = draaw_mi.fit(scene, ref, ["m.normalmap"], spp=4, iterations=12, lr=0.5, progress=False)
    fitted = np.asarray(res.values["m.normalmap"])
    assert fitted.shape == (4, 4, 3) and fitted.min() >= lo and fitted.max() <= 1.0, (fitted.min(), fitted.max())
    saved = res.save(str(tmp_path / "s" / "fitted.toml"), str(path))
    reloaded = draaw_mi.load_scene(str(saved if isinstance(saved, str) else tmp_path / "s" / "fitted.toml"))
    np.testing.assert_allclose(np.array(reloaded.params["m.normalmap.data"]), fitted, atol=1e-6)
