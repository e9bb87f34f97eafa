"""Camera-path interpolation (draaw_mi.scene.camera_path) against closed forms.

The default (fixed) mode spreads ``total = int(duration * fps)`` frames evenly over the path:
frame j sits at path position u_j = j (n - 1) / (total - 1), in segment k = floor(u_j) (the
last frame in the last segment) at t = u_j - k, eased by smoothstep s(t) = t^2 (3 - 2t).
GO-Draaw's faithful mode (go-draaw-spec.md §2.9) is checked in test_bench.py and below.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from draaw_mi.scene.camera_path import interpolate


def smoothstep(t):
    return t * t * (3 - 2 * t)


def test_two_keys_are_eased_with_smoothstep():
    """2 keys x 0 -> 1 over 5 frames: u = 0, 1/4, 1/2, 3/4, 1, so x = s(u) = 0, 0.15625, 0.5,
    0.84375, 1 (linear easing would give 0.25 at the second frame). The other four components
    are constant. Tolerance: a few float64 roundings of numbers of order 1."""
    f = interpolate([(0, 2, 3, 0.5, -1), (1, 2, 3, 0.5, -1)], duration=5 / 60, fps=60)
    assert f.shape == (5, 5)
    np.testing.assert_allclose(f[:, 0], [0.0, 0.15625, 0.5, 0.84375, 1.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(f[:, 1:], np.tile([2, 3, 0.5, -1], (5, 1)), rtol=0, atol=1e-12)


@pytest.mark.parametrize("total", [10, 13])
def test_four_keys_every_frame_is_smoothstep_within_its_segment(total):
    """4 keys with unequal steps in all five components; every frame equals
    P_k + (P_{k+1} - P_k) s(t) with k, t from the exact rational u_j = 3 j / (total - 1)
    (10 frames put frames 0, 3, 6, 9 on the keys; 13 frames land nowhere special).
    Tolerance 1e-12: float64 arithmetic on values below 10 (a wrong easing, segment or
    frame spacing is off by > 1e-2)."""
    keys = np.array([(0.0, 1.0, -2.0, 0.1, -1.9),
                     (4.0, 1.5, -1.0, 0.4, -2.0),
                     (5.0, 3.5, 2.0, -0.3, -1.7),
                     (9.0, 3.0, 2.5, 0.2, -1.8)])
    f = interpolate([tuple(k) for k in keys], duration=total / 60, fps=60)
    assert f.shape == (total, 5)
    for j in range(total):
        u = Fraction(j * 3, total - 1)
        k = min(int(u), 2)
        t = float(u - k)
        ref = keys[k] + (keys[k + 1] - keys[k]) * smoothstep(t)
        np.testing.assert_allclose(f[j], ref, rtol=0, atol=1e-12, err_msg=f"frame {j}")
    if total == 10:
        np.testing.assert_allclose(f[[0, 3, 6, 9]], keys, rtol=0, atol=1e-12)


def test_faithful_mode_is_go_draaws_loop():
    """faithful=True follows the spec's pseudocode (§2.9) frame by frame: 3 keys, 9 frames,
    F = 9 // 2 = 4 per segment, frame i F + f = P_i + (P_{i+1} - P_i) (3t^3 - 2t^4) with t = f/F,
    frame 8 = the last key (9 = 2 * 4 + 1, no undivided frame left at the origin here).
    Tolerance: float64 roundings."""
    keys = np.array([(0.0, 1.0, 2.0, 0.3, -2.0), (8.0, -1.0, 2.0, 0.5, -1.5), (4.0, 3.0, 0.0, -0.5, -1.9)])
    f = interpolate([tuple(k) for k in keys], duration=9 / 60, fps=60, faithful=True)
    assert f.shape == (9, 5)
    for i in range(2):
        for fr in range(4):
            t = fr / 4
            ref = keys[i] + (keys[i + 1] - keys[i]) * (3 * t ** 3 - 2 * t ** 4)
            np.testing.assert_allclose(f[i * 4 + fr], ref, rtol=0, atol=1e-12, err_msg=f"frame {i * 4 + fr}")
    np.testing.assert_allclose(f[8], keys[2], rtol=0, atol=0)


@pytest.mark.parametrize("keys, match", [
    ({"x": 0}, "expected a list of keyframes, got dict"),
    ([{"x": 0, "y": 1, "z": 2, "cameraX": 0, "cameraY": "abc"}], "keyframe 0 = .*'abc'.*5 finite numbers"),
    ([[0, 1, 2, 3, [4]]], "keyframe 0 = .*5 finite numbers"),
    ([[0, 1, 2, 3]], "keyframe 0 = .*5 finite numbers"),
    ([], "no keyframes"),
])
def test_malformed_keyframes_name_the_keyframe(keys, match):
    """A string value or a JSON object instead of a list raised a bare ValueError."""
    from draaw_mi.scene.camera_path import as_keyframes
    from draaw_mi.errors import ParameterError
    with pytest.raises(ParameterError, match=match):
        as_keyframes(keys)


def test_an_infinite_duration_is_refused():
    from draaw_mi.errors import ParameterError
    with pytest.raises(ParameterError, match="duration=inf"):
        interpolate([[0, 0, 0, 0, 0], [1, 1, 1, 0, 0]], duration=float("inf"))


@pytest.mark.parametrize("duration, fps, frames", [(2.05, 60, 123), (4.1, 30, 123), (123 / 60.0, 60, 123)])
def test_frame_counts_are_rounded_not_cut_by_float_error(duration, fps, frames):
    """2.05 s at 60 fps is 123 frames: the product 122.99999999999999 was truncated to 122
    (and the panel's load_camera_path(frames=123) gave 122). Faithful mode keeps GO-Draaw's
    truncation (Go's int(D * 60))."""
    keys = [[0, 0, 0, 0, 0], [1, 1, 1, 0, 0]]
    assert len(interpolate(keys, duration=duration, fps=fps)) == frames
    assert len(interpolate(keys, duration=duration, fps=fps, faithful=True)) == int(duration * fps)


@pytest.mark.parametrize("kwargs, match", [({"fps": float("nan")}, "fps=nan"), ({"duration": "2"}, "duration='2'"),
                                           ({"fps": True}, "fps=True"), ({"fps": 0}, "fps=0")])
def test_bad_durations_and_rates_are_named(kwargs, match):
    from draaw_mi.errors import ParameterError
    with pytest.raises(ParameterError, match=f"camera path: {match}; expected a positive number"):
        interpolate([[0, 0, 0, 0, 0], [1, 1, 1, 0, 0]], **kwargs)


@pytest.mark.parametrize("duration, fps, faithful", [(0.01, 60, False), (1, 1, False), (1, 1, True),
                                                     (1.9, 1, True)])
def test_a_path_of_fewer_than_two_frames_is_refused(duration, fps, faithful):
    """A path starts at its first keyframe and ends at its last: one frame cannot be both
    (a single frame came back, the last keyframe's in faithful mode)."""
    from draaw_mi.errors import ParameterError
    with pytest.raises(ParameterError, match=r"gives [01] frame\(s\); need at least 2"):
        interpolate([[0, 0, 0, 0, 0], [1, 1, 1, 0, 0]], duration=duration, fps=fps, faithful=faithful)


@pytest.mark.parametrize("faithful", [False, True])
def test_one_keyframe_is_a_camera_that_stays_put_for_every_frame(faithful):
    """One keyframe: as many frames as duration x fps, each the keyframe (it gave one frame
    whatever the duration, so a benchmark over N frames timed one)."""
    from draaw_mi.errors import ParameterError
    key = [1.0, 2.0, 3.0, 0.5, -0.25]
    frames = interpolate([key], duration=0.1, fps=60, faithful=faithful)
    np.testing.assert_array_equal(frames, np.tile(key, (6, 1)))
    with pytest.raises(ParameterError, match="fps=0"):          # checked as for more keys
        interpolate([key], fps=0)


def test_dict_keyframes_read_camerax_as_theta_and_cameray_as_phi():
    """GO-Draaw's camera_positions.json records {x, y, z, cameraX (theta), cameraY (phi)}:
    a swap would turn every path to look the wrong way."""
    from draaw_mi.scene.camera_path import as_keyframes
    rows = as_keyframes([{"x": 0, "y": 1, "z": 2, "cameraX": 0.24, "cameraY": -2.08}])
    assert rows.tolist() == [[0.0, 1.0, 2.0, 0.24, -2.08]]


def test_angles_are_interpolated_as_the_numbers_given():
    """Two keys theta 0 -> 2 pi are a full orbit: the middle frame looks the other way
    (theta pi), a quarter of the way it has turned about pi / 2 by smoothstep's easing.
    Wrapping each step into [-pi, pi) (the "short way") made this camera stand still."""
    two_pi = 2 * np.pi
    frames = interpolate([(0, 0, 5, 0.0, 1.5), (0, 0, 5, two_pi, 1.5)], duration=1.0, fps=5)
    u = np.linspace(0.0, 1.0, len(frames))
    np.testing.assert_allclose(frames[:, 3], two_pi * u * u * (3 - 2 * u), atol=1e-12)
    assert frames[-1, 3] == two_pi and np.ptp(frames[:, 3]) == two_pi
