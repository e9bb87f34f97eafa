"""API of every filter: shapes, dtypes, amount = 0, class = function, defaults, bad parameters,
docstrings (doctests) and the public names."""
from __future__ import annotations

import doctest
import importlib
import inspect

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi.post as post
from draaw_mi.errors import DraawError, ParameterError
from post_helpers import CASES, FILTER_NAMES, hdr_image

FUNCS = {name: getattr(post, name) for name in FILTER_NAMES}
#: one out-of-range value per parameter kind, per filter: (parameter, bad value)
BAD_VALUES = {
    "contrast": [("contrast", -0.1), ("contrast", 11.0), ("pivot", float("nan"))],
    "tint": [("strength", 1.5), ("color", (1.0, -1.0, 0.0)), ("color", (1.0, 2.0)),
             ("color", "#12345")],
    "bloom": [("threshold", -1.0), ("intensity", 20.0), ("boundary", "reflection"),
              ("clamp", "maybe")],
    "bloom_v2": [("spread", -0.5), ("spread", 9.0)],
    "sharpen": [("sharpness", -1.0), ("boundary", 3)],
    "color_mapping": [("levels", 0), ("levels", 2.5), ("levels", (4, 4)), ("levels", 70000)],
    "chromatic_aberration": [("shift", -1.0), ("shift", float("inf"))],
    "edge_detection": [("distance", 33.0), ("color", "red")],
    "lighten": [("strength", -2.0)],
    "crt": [("base", 1.5), ("glow", 81.0), ("radius", 101.0), ("seed", -1), ("seed", 0.5)],
    "linear": [("gamma", 0.0), ("gamma", 1.5), ("scale", 0.0), ("scale", 1e39)],
    "log": [("gamma", -0.1), ("scale", 1e-39), ("scale", 2e6)],
    "srgb": [("inverse", "sometimes")],
}


@pytest.mark.parametrize("name", FILTER_NAMES)
@pytest.mark.parametrize("channels", [3, 4])
def test_shape_type_and_numpy_input(name, channels):
    img = hdr_image(seed=11, channels=channels)
    out = FUNCS[name](img)
    assert type(out) is mi.TensorXf
    assert tuple(out.shape) == img.shape
    # float64 numpy and mi.TensorXf inputs give the same float32 result
    out64 = FUNCS[name](img.astype(np.float64)).numpy()
    out_t = FUNCS[name](mi.TensorXf(img)).numpy()
    assert out64.dtype == np.float32
    np.testing.assert_array_equal(out64, out_t)
    if channels == 4:
        np.testing.assert_array_equal(out_t[..., 3], img[..., 3])


@pytest.mark.parametrize("name", FILTER_NAMES)
@pytest.mark.parametrize("channels", [3, 4])
def test_amount_zero_returns_input_exactly(name, channels):
    img = hdr_image(seed=12, channels=channels)
    params = dict(CASES[name][-1], amount=0.0)
    np.testing.assert_array_equal(FUNCS[name](img, **params).numpy(), img)
    np.testing.assert_array_equal(post.apply(img, [{"type": name, **params}]).numpy(), img)


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_class_equals_function(name):
    img = hdr_image(seed=13, channels=4)
    params = CASES[name][-1]
    cls = post.FILTERS[name]
    f = cls(**params)
    np.testing.assert_array_equal(f(img).numpy(), FUNCS[name](img, **params).numpy())
    assert f == cls(**params)
    assert f.to_dict()["type"] == name
    assert name in repr(f) or cls.__name__ in repr(f)


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_signature_defaults_match_spec(name):
    spec = post.FILTERS[name].spec
    for obj in (FUNCS[name], post.FILTERS[name].__init__):
        sig = inspect.signature(obj)
        names = [p for p in sig.parameters if p not in ("self", "image")]
        assert names == [p.name for p in spec.params]
        for p in spec.params:
            got = p.check("test", sig.parameters[p.name].default)
            assert got == p.check("test", p.default), (name, p.name)
    doc = FUNCS[name].__doc__
    for section in ("Args:", "Returns:", "Shape:", "Example:", ">>>"):
        assert section in doc, (name, section)


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_bad_parameter_values_raise(name):
    img = hdr_image(seed=14)
    for param, value in BAD_VALUES[name]:
        with pytest.raises(ParameterError) as info:
            FUNCS[name](img, **{param: value})
        msg = str(info.value)
        assert f"{name}()" in msg and repr(param) in msg and repr(value) in msg, msg
        with pytest.raises(ParameterError, match=name):
            post.apply(img, [{"type": name, param: value}])
        with pytest.raises(ParameterError):
            post.FILTERS[name](**{param: value})
    for param, value in [("amount", 1.5), ("amount", -0.1), ("multipass", 0), ("multipass", 1.5),
                         ("amount", True)]:
        with pytest.raises(ParameterError, match=param):
            FUNCS[name](img, **{param: value})


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_unknown_parameter_lists_valid_names(name):
    with pytest.raises(ParameterError) as info:
        post.apply(hdr_image(), [{"type": name, "amuont": 0.5}])
    msg = str(info.value)
    assert name in msg and "'amuont'" in msg and "did you mean 'amount'" in msg
    assert "valid:" in msg and "multipass" in msg
    with pytest.raises(TypeError):
        FUNCS[name](hdr_image(), amuont=0.5)


@pytest.mark.parametrize("bad,match", [
    (np.zeros((4, 4), np.float32), "shape"),
    (np.zeros((4, 4, 2), np.float32), "shape"),
    (np.zeros((4, 4, 5), np.float32), "shape"),
    (np.zeros((0, 4, 3), np.float32), "shape"),
    (np.zeros((2, 4, 4, 3), np.float32), "shape"),
    (np.zeros((4, 4, 3), np.uint8), "float"),
    (np.zeros((4, 4, 3), np.int64), "float"),
    ("not an image", "image"),
])
def test_bad_images_raise(bad, match):
    for name in ("contrast", "crt"):
        with pytest.raises(ParameterError, match=match) as info:
            FUNCS[name](bad)
        assert f"{name}()" in str(info.value)
    with pytest.raises(DraawError, match="apply"):
        post.apply(bad, [])


def test_lists_and_other_drjit_tensors_are_accepted():
    out = post.lighten([[[0.5, 0.5, 0.5]]], 1.0)
    assert out.numpy().tolist() == [[[1.0, 1.0, 1.0]]]
    t64 = mi.TensorXf64(np.full((2, 2, 3), 0.25))
    assert post.contrast(t64, 2.0).numpy().tolist()[0][0] == [0.0, 0.0, 0.0]


def test_public_api_surface():
    expected = {
        "apply", "load_chain", "display_encoded", "Chain", "Filter", "FilterSpec", "Param", "FILTERS", "BOUNDARIES",
        "filter_class", "contrast", "tint", "bloom", "bloom_v2", "sharpen", "color_mapping",
        "chromatic_aberration", "edge_detection", "lighten", "crt", "linear", "log", "srgb",
        "Contrast", "Tint", "Bloom", "BloomV2", "Sharpen", "ColorMapping", "ChromaticAberration",
        "EdgeDetection", "Lighten", "CRT", "Linear", "Log", "SRGB"}
    assert set(post.__all__) == expected
    assert post.__all__ == sorted(post.__all__)
    assert list(post.FILTERS) == FILTER_NAMES
    for name in post.__all__:
        assert getattr(post, name) is not None


@pytest.mark.parametrize("module", ["color", "blur", "edges", "aberration", "crt_look", "tone",
                                    "chain"])
def test_doctests(module):
    mod = importlib.import_module(f"draaw_mi.post.{module}")
    result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


def test_numpy_booleans_are_booleans():
    """np.False_ (a checkbox's value through numpy, a mask's element) was refused: "parameter
    'clamp' must be true or false, got np.False_"; it means what False means."""
    img = hdr_image(6)
    for flag in (False, True):
        np.testing.assert_array_equal(np.array(post.bloom(img, clamp=np.bool_(flag))),
                                      np.array(post.bloom(img, clamp=flag)))


@pytest.mark.parametrize("word, flag", [("yes", True), ("YES", True), ("True", True), ("no", False),
                                        ("false", False)])
def test_a_chain_file_may_spell_a_flag_as_a_word(word, flag):
    """A chain entry's flag given as a word (a TOML/JSON file written by hand): "yes"/"no" and
    "true"/"false" in any case mean the flag ("yes" read as false clamped nothing)."""
    img = np.full((2, 3, 3), 0.9, np.float32)
    chain = [{"type": "lighten", "strength": 1.0}, {"type": "linear", "gamma": 1 / 3}]
    got = post.apply(img, [chain[0], dict(chain[1], clamp=word)]).numpy()
    want = post.apply(img, [chain[0], dict(chain[1], clamp=flag)]).numpy()
    np.testing.assert_array_equal(got, want)
    assert (got.max() <= 1.0) == flag                          # 1.8 ** (1/3) > 1 unclamped
