"""Chains: dict and GO-Draaw forms, name matching, validation messages, JSON files."""
from __future__ import annotations

import json

import numpy as np
import pytest

import draaw_mi.post as post
from draaw_mi.errors import DraawError, IOFailure, ParameterError
from post_helpers import hdr_image

GO_DRAAW_CHAIN = [  # GO-Draaw's /submitShader body, one entry per shader it can run
    {"type": "contrast", "params": {"amount": 0.1, "multipass": 1, "Contrast": 1.2}},
    {"type": "tint", "params": {"amount": 0.1, "multipass": 1, "TintColor": [1, 0.5, 0.2],
                                "TintStrength": 0.3}},
    {"type": "bloom", "params": {"amount": 0.1, "multipass": 3, "BloomThreshold": 0.05,
                                 "BloomIntensity": 1.1}},
    {"type": "bloomV2", "params": {"amount": 0.1, "multipass": 3, "BloomThreshold": 0.05,
                                   "BloomIntensity": 1.1, "BloomSpread": 0.7}},
    {"type": "sharpen", "params": {"amount": 0.1, "multipass": 1, "Sharpness": 1.0}},
    {"type": "colorMapping", "params": {"amount": 0.1, "multipass": 1, "ColorR": 16,
                                        "ColorG": 16, "ColorB": 8}},
    {"type": "chromaticAberration", "params": {"amount": 0.1, "multipass": 1, "Strength": 2}},
    {"type": "edgeDetection", "params": {"amount": 0.1, "multipass": 1, "Strength": 1,
                                         "AlphaR": 1, "AlphaG": 0.5, "AlphaB": 0}},
    {"type": "Lighten", "params": {"amount": 0.1, "multipass": 1, "Lighten": 0.1}},
    {"type": "CRT", "params": {"amount": 0.1, "multipass": 1, "Base": 0.5, "Glow": 1.5,
                               "Radius": 16}},
]


def test_go_draaw_chain_names_and_values():
    chain = post.load_chain(GO_DRAAW_CHAIN)
    assert [f.spec.name for f in chain] == list(post.FILTERS)[:10]
    assert chain[1].params["color"] == (1.0, 0.5, 0.2)
    assert chain[5].params["levels"] == (16, 16, 8)
    assert chain[6].params["shift"] == 2.0
    assert chain[7].params["color"] == (1.0, 0.5, 0.0)      # AlphaG is used (GO-Draaw bug)
    assert chain[9].params["radius"] == 16.0
    out = chain(hdr_image(seed=20, channels=4))
    assert out.shape == (13, 17, 4) and np.all(np.isfinite(out.numpy()))


def test_flat_and_nested_forms_agree_and_names_are_case_insensitive():
    img = hdr_image(seed=21)
    a = post.apply(img, [{"type": "bloom_v2", "threshold": 0.2, "spread": 1.5, "amount": 0.5}])
    b = post.apply(img, [{"type": "BloomV2",
                          "params": {"bloomThreshold": 0.2, "BLOOM_SPREAD": 1.5, "Amount": 0.5}}])
    c = post.BloomV2(threshold=0.2, spread=1.5, amount=0.5)(img)
    d = post.bloom_v2(img, 0.2, spread=1.5, amount=0.5)
    for other in (b, c, d):
        np.testing.assert_array_equal(a.numpy(), other.numpy())


def test_component_names_override_the_whole_value():
    f = post.load_chain([{"type": "colorMapping", "levels": 8, "ColorG": 4}])[0]
    assert f.params["levels"] == (8, 4, 8)
    f = post.load_chain([{"type": "tint", "TintColor": "#ff8000"}])[0]
    assert f.params["color"] == (1.0, 128 / 255, 0.0)
    f = post.load_chain([{"type": "tint", "color": {"R": 1, "g": 0, "b": 0.5}}])[0]
    assert f.params["color"] == (1.0, 0.0, 0.5)


def test_filter_objects_and_dicts_mix():
    img = hdr_image(seed=22)
    chain = post.Chain([post.Contrast(1.5), {"type": "srgb"}])
    ref = post.srgb(post.contrast(img, 1.5))
    np.testing.assert_array_equal(chain(img).numpy(), ref.numpy())


def test_empty_chain_is_identity():
    img = hdr_image(seed=23, channels=4)
    np.testing.assert_array_equal(post.apply(img, []).numpy(), img)


@pytest.mark.parametrize("chain,parts", [
    ([{"type": "blom"}], ["chain[0]", "'blom'", "did you mean 'bloom'", "valid:", "crt"]),
    ([{"type": "xyz"}], ["unknown filter type 'xyz'", "valid:", "colorMapping"]),
    ([{"type": "contrast"}, {"type": "bloom", "treshold": 1}],
     ["chain[1] (bloom)", "'treshold'", "did you mean 'threshold'", "BloomThreshold"]),
    ([{"type": "bloom", "threshold": 0.1, "BloomThreshold": 0.2}], ["given twice"]),
    ([{"type": "bloom", "amount": 0.1, "params": {"amount": 0.2}}], ["both"]),
    ([{"type": "bloom", "params": [1, 2]}], ["'params' must be a dict"]),
    ([{"amount": 0.5}], ["no 'type'", "amount"]),
    (["bloom"], ["chain entry must be a dict"]),
    ([{"type": "crt", "Radius": 500}], ["chain[0] (crt)", "'radius'", "500", "[0, 100]"]),
    ({"type": "bloom"}, ["must be a list"]),
])
def test_chain_errors_name_the_entry_and_the_valid_names(chain, parts):
    with pytest.raises(ParameterError) as info:
        post.apply(hdr_image(), chain)
    for part in parts:
        assert part in str(info.value), (part, str(info.value))


def test_whole_chain_is_validated_before_running():
    calls = []

    class Spy(post.Lighten):
        def __call__(self, image):  # pragma: no cover - must not run
            calls.append(1)
            return super().__call__(image)
    with pytest.raises(ParameterError):
        post.Chain([Spy(), {"type": "nope"}])
    assert calls == []


def test_load_chain_from_files(tmp_path):
    img = hdr_image(seed=24)
    path = tmp_path / "chain.json"
    path.write_text(json.dumps(GO_DRAAW_CHAIN))
    chain = post.load_chain(path)
    np.testing.assert_array_equal(post.apply(img, str(path)).numpy(), chain(img).numpy())

    wrapped = tmp_path / "wrapped.json"
    wrapped.write_text(json.dumps({"chain": [{"type": "srgb"}]}))
    assert post.load_chain(wrapped)[0].spec.name == "srgb"

    saved = tmp_path / "saved.json"
    chain.save(saved)
    again = post.load_chain(saved)
    assert again == chain and again.to_list() == chain.to_list()
    assert post.Chain(chain.to_list()) == chain


@pytest.mark.parametrize("text,parts", [
    ('[{"type": "bloom",}]', ["bad.json", "malformed JSON", "line 1"]),
    ('[{"type": "bloom"}\n{"type": "tint"}]', ["bad.json", "line 2"]),
    ('{"filters": []}', ["bad.json", "keys ['filters']"]),
    ('"bloom"', ["bad.json", "list of filters"]),
    ('[{"type": "bloom", "threshold": -1}]', ["bad.json: chain[0] (bloom)", "'threshold'"]),
])
def test_load_chain_bad_files(tmp_path, text, parts):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(ParameterError) as info:
        post.load_chain(path)
    for part in parts:
        assert part in str(info.value), (part, str(info.value))


def test_load_chain_missing_file(tmp_path):
    path = tmp_path / "missing.json"
    with pytest.raises(IOFailure, match="missing.json") as info:
        post.load_chain(path)
    assert isinstance(info.value, DraawError)


def test_save_replaces_a_chain_only_when_the_new_one_is_complete(tmp_path, monkeypatch):
    """Chain.save wrote into the target directly: a crash mid-write left '[{"type": "bl' in
    place of the previous chain."""
    path = tmp_path / "chain.json"
    post.Chain([{"type": "srgb"}]).save(path)
    before = path.read_text()

    import os

    def crash(*args, **kwargs):         # killed after the new text is written, before it replaces
        raise KeyboardInterrupt("killed while writing")
    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(KeyboardInterrupt):
        post.Chain([{"type": "bloom"}]).save(path)
    assert path.read_text() == before and [p.name for p in tmp_path.iterdir()] == ["chain.json"]


def test_a_binary_file_is_no_chain(tmp_path):
    path = tmp_path / "image.json"
    path.write_bytes(bytes(range(256)))
    with pytest.raises(ParameterError, match=r"image.json: not a post chain file"):
        post.load_chain(path)
