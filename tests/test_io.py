"""EXR/PNG I/O: bit-exact float32 round trips, AOV channel names, atomic writes, sRGB."""
from __future__ import annotations

import os
import stat

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import IOFailure, ParameterError
from draaw_mi.io import channel_names, srgb_encode


def test_exr_round_trip_is_bit_exact(tmp_path):
    rng = np.random.default_rng(0)
    img = (rng.standard_normal((7, 5, 3)) * 1e3).astype(np.float32)
    path = tmp_path / "a.exr"
    draaw_mi.write_exr(str(path), img)
    back = draaw_mi.read_exr(str(path))
    assert back.dtype == np.float32 and np.array_equal(back, img)


def test_exr_aov_channel_names(tmp_path):
    img = np.arange(4 * 3 * 6, dtype=np.float32).reshape(4, 3, 6)
    names = channel_names(6, ["depth.Z", "albedo.R", "albedo.G"])
    assert names == ["R", "G", "B", "depth.Z", "albedo.R", "albedo.G"]
    path = str(tmp_path / "aov.exr")
    draaw_mi.write_exr(path, img, channels=names)
    back, got = draaw_mi.read_exr(path, with_names=True)
    assert got[:3] == ["R", "G", "B"]
    for i, n in enumerate(names):
        assert np.array_equal(back[..., got.index(n)], img[..., i])


def test_exr_float32_overflow_is_inf_not_garbage(tmp_path):
    img = np.array([[[1e39, -1e39, 1.0]]], dtype=np.float64)
    path = str(tmp_path / "o.exr")
    with np.errstate(over="ignore"):
        draaw_mi.write_exr(path, img)
    back = draaw_mi.read_exr(path)
    assert np.isposinf(back[0, 0, 0]) and np.isneginf(back[0, 0, 1]) and back[0, 0, 2] == 1.0


def test_failed_write_keeps_the_old_file(tmp_path):
    path = tmp_path / "keep.exr"
    good = np.ones((2, 2, 3), np.float32)
    draaw_mi.write_exr(str(path), good)
    with pytest.raises(IOFailure):
        draaw_mi.write_exr(str(path), np.ones((2, 2, 3), np.float32), channels=["R", "G"])  # bad names
    assert np.array_equal(draaw_mi.read_exr(str(path)), good)
    assert [p.name for p in tmp_path.iterdir()] == ["keep.exr"]        # no temp files left


def test_atomic_write_reaches_the_disk_before_its_rename(tmp_path, monkeypatch):
    """The temporary file is fsynced before it is renamed into place, the folder after: a
    rename of unflushed data survives a killed process but not a power cut (an intact EXR
    header over zeroed pixels would count as a finished batch frame)."""
    events = []
    real_fsync, real_replace, real_open = os.fsync, os.replace, os.open
    names = {}

    def opening(path, flags, *a):
        fd = real_open(path, flags, *a)
        names[fd] = os.path.basename(os.fspath(path)) or os.fspath(path)
        return fd
    monkeypatch.setattr(os, "open", opening)
    monkeypatch.setattr(os, "fsync", lambda fd: (events.append(("fsync", names.get(fd))), real_fsync(fd)))
    monkeypatch.setattr(os, "replace", lambda a, b: (events.append(("replace", os.path.basename(b))),
                                                     real_replace(a, b)))
    draaw_mi.write_exr(str(tmp_path / "f.exr"), np.ones((2, 2, 3), np.float32))
    kinds = [(k, n if k == "replace" else (n.startswith(".draaw-") and "temp" or n)) for k, n in events]
    assert kinds == [("fsync", "temp"), ("replace", "f.exr"), ("fsync", tmp_path.name)], events


def test_unwritable_and_bad_paths(tmp_path):
    with pytest.raises(IOFailure, match="another image format.*write_png"):
        draaw_mi.write_exr(str(tmp_path / "x.png"), np.ones((2, 2, 3), np.float32))
    assert not list(tmp_path.iterdir())
    with pytest.raises(IOFailure, match="cannot"):
        draaw_mi.write_exr("/proc/forbidden/x.exr", np.ones((2, 2, 3), np.float32))
    with pytest.raises(IOFailure, match="does not exist"):
        draaw_mi.read_exr(str(tmp_path / "none.exr"))
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"not an exr")
    with pytest.raises(IOFailure, match="not a readable EXR"):
        draaw_mi.read_exr(str(junk))
    with pytest.raises(IOFailure, match="expected"):
        draaw_mi.write_exr(str(tmp_path / "x.exr"), np.ones((0, 2, 3), np.float32))


def test_srgb_matches_the_standard():
    x = np.array([0.0, 0.0031308, 0.18, 0.5, 1.0, 2.0, np.nan])
    ref = np.array([0.0, 12.92 * 0.0031308, 1.055 * 0.18 ** (1 / 2.4) - 0.055,
                    1.055 * 0.5 ** (1 / 2.4) - 0.055, 1.0, 1.0, 0.0])
    assert np.allclose(srgb_encode(x), ref, atol=1e-12)


def test_png_is_srgb_encoded(tmp_path):
    import matplotlib.image
    img = np.full((2, 3, 3), 0.18, np.float32)
    path = str(tmp_path / "p.png")
    draaw_mi.write_png(path, img)
    back = matplotlib.image.imread(path)
    assert back.shape[:2] == (2, 3)
    assert abs(back[0, 0, 0] * 255 - round((1.055 * 0.18 ** (1 / 2.4) - 0.055) * 255)) < 0.51
    assert os.listdir(tmp_path) == ["p.png"]


@pytest.mark.parametrize("channels", [2, 4])
def test_png_keeps_the_alpha_of_grey_and_colour_images(tmp_path, channels):
    """(grey, alpha) and RGBA images keep their last channel as a linear alpha (a grey image's
    alpha was dropped); a NaN alpha is stored as 0, by choice rather than by numpy's cast of
    NaN to uint8 (undefined; it warns). Read back with Pillow. The colour comes premultiplied
    by alpha, as a film (and the EXR) holds it, and the PNG stores it straight: 0.18 x alpha
    is 0.18 in every pixel (it was stored premultiplied: dark fringes along edges); where
    alpha is 0 the colour is kept as it is."""
    import warnings
    from PIL import Image
    img = np.zeros((2, 3, channels), np.float32)
    alpha = np.array([[0.0, 0.25, 1.0], [0.5, np.nan, 2.0]])
    img[..., 0] = 0.18 * np.where(np.isfinite(alpha) & (alpha > 0), np.clip(alpha, 0, 1), 1.0)
    img[..., -1] = alpha
    path = str(tmp_path / "a.png")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        draaw_mi.write_png(path, img)
    back = np.asarray(Image.open(path).convert("RGBA"))
    np.testing.assert_array_equal(back[..., 3], [[0, 64, 255], [128, 0, 255]])
    assert np.all(back[..., 0] == round((1.055 * 0.18 ** (1 / 2.4) - 0.055) * 255))


def test_png_and_exr_names_are_not_swapped(tmp_path):
    """write_png wrote an 8-bit PNG under an .exr name (write_exr refused the mirror case)."""
    from draaw_mi.errors import IOFailure
    img = np.full((2, 3, 3), 0.18, np.float32)
    with pytest.raises(IOFailure, match=r"write_png\('.*oops.exr'\): expected a '.png' name"):
        draaw_mi.write_png(str(tmp_path / "oops.exr"), img)
    with pytest.raises(IOFailure, match=r"write_exr\('.*oops.png'\)"):
        draaw_mi.write_exr(str(tmp_path / "oops.png"), img)
    assert not list(tmp_path.iterdir())


def test_png_exposure_scales_by_two_to_the_stops(tmp_path):
    """``exposure`` in stops multiplies the linear image by 2**exposure before encoding: 0.18
    written at +1 stop reads back as the sRGB code of 0.36, at -1 stop as that of 0.09 (the
    IEC 61966-2-1 transfer written out here, not the module's). Tolerance: the 8-bit rounding
    of the stored value (±0.5 level, +0.01 for float32 input); the two codes (162 and 85) are
    far from any rounding boundary, and a sign slip in the exponent swaps them."""
    from PIL import Image

    def srgb(x):                      # IEC 61966-2-1, for 0.0031308 < x <= 1
        return 1.055 * x ** (1 / 2.4) - 0.055

    img = np.full((2, 3, 3), 0.18, np.float32)
    for stops, linear in ((1.0, 0.36), (-1.0, 0.09)):
        path = str(tmp_path / f"e{stops:+.0f}.png")
        draaw_mi.write_png(path, img, exposure=stops)
        back = np.asarray(Image.open(path).convert("RGB"), dtype=float)
        assert back.shape == (2, 3, 3)
        assert np.all(np.abs(back - round(srgb(linear) * 255)) <= 0.51), (stops, back[0, 0], srgb(linear) * 255)


@pytest.mark.parametrize("mode", [0o640, 0o444, 0o600])
def test_a_replaced_file_keeps_its_mode_and_a_new_one_gets_the_usual(tmp_path, mode):
    """A read-only or group-only output came back 0644 after an atomic rewrite."""
    from draaw_mi.io import write_text
    old = tmp_path / "report.md"
    old.write_text("old")
    os.chmod(old, mode)
    write_text(str(old), "new")
    assert old.read_text() == "new" and stat.S_IMODE(os.stat(old).st_mode) == mode
    new = tmp_path / "fresh.md"
    umask = os.umask(0o022)
    try:
        write_text(str(new), "x")
    finally:
        os.umask(umask)
    assert stat.S_IMODE(os.stat(new).st_mode) == 0o644


def test_a_rendered_rgba_films_edge_shows_its_surface_colour_in_the_png(tmp_path):
    """An rgba film's edge pixel holds colour x coverage (Mitsuba's premultiplied alpha); its
    PNG colour is the surface's, colour / alpha (PNG's alpha is straight): Mitsuba's Bitmap
    conversion to 8-bit sRGB RGBA with its Unpremultiply transform is the reference, within
    one 8-bit step. (Mitsuba's own film.write keeps the premultiplied colour in a PNG.)"""
    import mitsuba as mi
    from PIL import Image
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "hide_emitters": True},
                          "s": {"type": "sphere", "radius": 0.8, "bsdf": {"type": "diffuse"}},
                          "e": {"type": "constant"},
                          "sensor": {"type": "perspective", "fov": 40, "to_world": mi.ScalarTransform4f().look_at(
                              origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]), "film": {
                              "type": "hdrfilm", "width": 16, "height": 16, "pixel_format": "rgba",
                              "rfilter": {"type": "box"}}}})
    img = np.array(mi.render(scene, spp=16, seed=1))
    edge = (img[..., 3] > 0.1) & (img[..., 3] < 0.9)
    assert edge.sum() >= 4                                   # a real edge to look at
    path = str(tmp_path / "e.png")
    draaw_mi.write_png(path, img)
    bmp = mi.Bitmap(img, mi.Bitmap.PixelFormat.RGBA)
    ref = np.array(bmp.convert(mi.Bitmap.PixelFormat.RGBA, mi.Struct.Type.UInt8, srgb_gamma=True,
                               alpha_transform=mi.Bitmap.AlphaTransform.Unpremultiply))
    back = np.asarray(Image.open(path).convert("RGBA")).astype(int)
    assert np.abs(back[edge] - ref[edge].astype(int)).max() <= 1


def test_exr_header_ints_beyond_int32_come_back_whole(tmp_path):
    """An EXR int attribute is 32-bit: a seed of 3000000000 (render takes 0 .. 2**32 - 1) was
    read back as -1294967296; it is stored as its decimal string."""
    from draaw_mi.batch import read_header
    path = str(tmp_path / "m.exr")
    draaw_mi.write_exr(path, np.ones((2, 2, 3)), metadata={"draaw:seed": 3_000_000_000, "n": 7,
                                                           "neg": -2 ** 31})
    h = read_header(path)
    assert (h["draaw:seed"], h["n"], h["neg"]) == ("3000000000", 7, -2 ** 31)


@pytest.mark.parametrize("image, match", [(np.ones(5), r"write_exr\('.*x.exr'\): image of shape \(5,\)"),
                                          (np.ones((2, 2, 5)), r"write_exr\('.*x.exr'\): 5 channels with 0 AOV")])
def test_write_exr_errors_name_the_call(tmp_path, image, match):
    with pytest.raises(IOFailure, match=match):
        draaw_mi.write_exr(str(tmp_path / "x.exr"), image)


def test_png_of_colour_and_an_aov_keeps_the_aov_out_given_the_names(tmp_path):
    """R, G, B and a depth AOV are four channels: without names they are taken for RGBA (as
    documented); with render's channel names the depth is left out, and an A channel is the
    alpha wherever it is."""
    from PIL import Image
    img = np.zeros((2, 3, 5), np.float32)
    img[..., :3], img[..., 3], img[..., 4] = 0.18, 0.5, 7.0          # R, G, B, A, depth.Z
    draaw_mi.write_png(str(tmp_path / "a.png"), img, channels=["R", "G", "B", "A", "depth.Z"])
    back = np.asarray(Image.open(str(tmp_path / "a.png")).convert("RGBA"))
    assert np.all(back[..., 3] == 128) and np.all(back[..., 0] == round(float(srgb_encode(np.array([0.36]))[0]) * 255))
    draaw_mi.write_png(str(tmp_path / "d.png"), img[..., [0, 1, 2, 4]], channels=["R", "G", "B", "depth.Z"])
    back = np.asarray(Image.open(str(tmp_path / "d.png")).convert("RGBA"))
    assert np.all(back[..., 3] == 255) and np.all(back[..., 0] == round(float(srgb_encode(np.array([0.18]))[0]) * 255))
    with pytest.raises(IOFailure, match=r"write_png\('.*x.png'\): channels \['depth.Z'\]; expected R, G, B or Y"):
        draaw_mi.write_png(str(tmp_path / "x.png"), img[..., 4:], channels=["depth.Z"])


def test_exr_header_ints_at_the_int32_bounds(tmp_path):
    """The bounds of EXR's 32-bit int: 2**31 - 1 and -2**31 are ints, one past either is kept
    as its decimal string (2**31 stored as an int wrapped to -2147483648)."""
    from draaw_mi.batch import read_header
    path = str(tmp_path / "b.exr")
    meta = {"hi": 2 ** 31 - 1, "lo": -2 ** 31, "over": 2 ** 31, "under": -2 ** 31 - 1}
    draaw_mi.write_exr(path, np.ones((2, 2, 3)), metadata=meta)
    h = read_header(path)
    assert [h[k] for k in meta] == [2 ** 31 - 1, -2 ** 31, "2147483648", "-2147483649"]


@pytest.mark.parametrize("writer, name", [("write_exr", "d.exr"), ("write_png", "d.png")])
def test_writing_onto_a_folder_is_one_clear_error(tmp_path, writer, name):
    """An output name that is a folder: an IOFailure naming it before anything is encoded
    (without the check: a bare IsADirectoryError after the encoding)."""
    (tmp_path / name).mkdir()
    with pytest.raises(IOFailure, match="it is a folder"):
        getattr(draaw_mi, writer)(str(tmp_path / name), np.ones((2, 2, 3), np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]       # no temporary file left


def test_duplicate_channel_names_are_refused_and_nothing_is_written(tmp_path):
    """Channels R, G, G: EXR keeps one channel per name, so one of them was silently lost."""
    path = tmp_path / "dup.exr"
    with pytest.raises(IOFailure, match="duplicate channel names"):
        draaw_mi.write_exr(str(path), np.ones((2, 2, 3), np.float32), channels=["R", "G", "G"])
    assert not path.exists()


def test_a_png_of_xyz_channels_is_the_colour_they_describe(tmp_path):
    """X, Y, Z channels (a Mitsuba xyz film) are converted to sRGB: a saturated colour keeps its
    hue (reading only Y, it came out grey). Reference: Mitsuba's srgb_to_xyz for the input."""
    import mitsuba as mi
    from PIL import Image
    rgb = np.array([0.8, 0.2, 0.1])
    xyz = np.array(mi.srgb_to_xyz(mi.ScalarColor3f(*rgb)), np.float64).ravel()
    img = np.tile(xyz.astype(np.float32), (2, 3, 1))
    draaw_mi.write_png(str(tmp_path / "x.png"), img, channels=["X", "Y", "Z"])
    back = np.asarray(Image.open(str(tmp_path / "x.png")).convert("RGB")).astype(int)
    want = np.round(255 * srgb_encode(rgb)).astype(int)
    assert np.abs(back - want).max() <= 1, (back[0, 0], want)


def test_what_is_not_an_image_or_not_a_file_is_said_so(tmp_path):
    """``write_exr(path, "hello")`` raised NumPy's ValueError; ``read_exr`` of a folder said it
    did not exist."""
    with pytest.raises(draaw_mi.IOFailure, match=r"write_exr\(.*\): image of type str is not an array of numbers"):
        draaw_mi.write_exr(str(tmp_path / "x.exr"), "hello")
    assert not (tmp_path / "x.exr").exists()
    with pytest.raises(draaw_mi.IOFailure, match=r"read_exr: .* is a folder; expected an EXR file"):
        draaw_mi.read_exr(str(tmp_path))
    with pytest.raises(draaw_mi.IOFailure, match=r"read_exr: .* does not exist"):
        draaw_mi.read_exr(str(tmp_path / "nothing.exr"))


def test_an_interrupt_during_the_openexr_import_is_not_a_missing_package(monkeypatch):
    """SIGTERM (the CLI's Terminated, a KeyboardInterrupt) landing in OpenEXR's first import
    fails the extension's initialisation with an ImportError from it: that is the interrupt,
    not "EXR files need the OpenEXR package"; a real ImportError still says that."""
    import builtins
    import sys

    from draaw_mi.io import openexr

    class Terminated(KeyboardInterrupt):
        pass
    real_import = builtins.__import__

    def importing(name, *a, **k):
        if name != "OpenEXR":
            return real_import(name, *a, **k)
        try:
            raise Terminated
        except Terminated as e:
            raise ImportError("initialization failed") from e
    monkeypatch.delitem(sys.modules, "OpenEXR", raising=False)
    monkeypatch.setattr(builtins, "__import__", importing)
    with pytest.raises(Terminated):
        openexr("write_exr")
    monkeypatch.setattr(builtins, "__import__",
                        lambda name, *a, **k: (_ for _ in ()).throw(ImportError("No module named 'OpenEXR'"))
                        if name == "OpenEXR" else real_import(name, *a, **k))
    with pytest.raises(IOFailure, match="write_exr: EXR files need the OpenEXR package"):
        openexr("write_exr")


@pytest.mark.parametrize("writer, name", [("write_exr", "x.exr"), ("write_png", "x.png"), ("write_text", "r.md")])
def test_a_path_through_a_missing_folder_and_back_is_written_where_it_resolves(tmp_path, writer, name):
    """``d/missing/../x.exr``: the temporary file and the rename both go to the folder the
    path resolves to (d/); abspath folded the ".." for the one, os.replace took the literal
    path for the other and raised a bare FileNotFoundError."""
    from draaw_mi import io
    path = os.path.join(str(tmp_path), "missing", os.pardir, name)
    data = "x" if writer == "write_text" else np.ones((2, 2, 3), np.float32)
    getattr(io, writer)(path, data)
    assert sorted(os.listdir(tmp_path)) == [name]


def test_a_failed_rename_is_an_io_failure_naming_the_path(tmp_path, monkeypatch):
    from draaw_mi import io

    def refuse(src, dst):
        raise PermissionError(13, "Permission denied")
    monkeypatch.setattr(io.os, "replace", refuse)
    path = str(tmp_path / "x.exr")
    with pytest.raises(IOFailure, match=rf"cannot write '{path}': renaming the finished file onto it failed: "
                                        r"Permission denied"):
        draaw_mi.write_exr(path, np.ones((2, 2, 3), np.float32))
    assert not list(tmp_path.iterdir())                  # (the temporary file is removed)


@pytest.mark.parametrize("exposure", [float("nan"), float("inf"), -float("inf"), "1", None])
def test_png_exposure_must_be_a_finite_number(tmp_path, exposure):
    """NaN stops wrote a black image and Inf a white one."""
    path = str(tmp_path / "e.png")
    with pytest.raises(ParameterError, match=rf"write_png\('{path}'\): exposure={exposure!r}; expected a finite "
                                             r"number of stops"):
        draaw_mi.write_png(path, np.full((2, 2, 3), 0.2, np.float32), exposure=exposure)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("exposure", [np.array(1.0), np.float32(1.0), mi.Float(1.0), [1.0]])
def test_png_exposure_of_one_numpy_or_drjit_value_is_a_number(tmp_path, exposure):
    path = str(tmp_path / "e.png")
    draaw_mi.write_png(path, np.full((2, 2, 3), 0.2, np.float32), exposure=exposure)
    plain = str(tmp_path / "p.png")
    draaw_mi.write_png(plain, np.full((2, 2, 3), 0.2, np.float32), exposure=1.0)
    assert open(path, "rb").read() == open(plain, "rb").read()
