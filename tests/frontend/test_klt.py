"""Seed 003, section 2.4: KLT tracking of a rendered marker with a known sub-pixel path."""

import numpy as np
import pytest

from visjax.frontend import klt_track, klt_translation, render_marker


def _path(n=25):
    t = np.arange(n)
    return np.stack([300 + 1.7 * t + 0.3 * np.sin(0.5 * t), 220 - 0.9 * t], axis=1)


def test_opencv_klt_follows_a_subpixel_path():
    path = _path()
    frames = np.stack([render_marker(c) for c in path])
    tracks, ok = klt_track(frames, path[:1])
    assert ok.all()
    # each frame-to-frame step is accurate to a few hundredths of a pixel; the static
    # background inside the window biases every step slightly, so the drift accumulates
    steps = np.diff(tracks[:, 0], axis=0) - np.diff(path, axis=0)
    assert np.abs(steps).max() < 0.02
    assert np.abs(tracks[:, 0] - path).max() < 0.25  # pixels, after 24 steps


def test_thesis_klt_iteration_matches_truth_and_opencv():
    path = _path(6)
    frames = np.stack([render_marker(c) for c in path])
    tracks, _ = klt_track(frames, path[:1])
    for k in range(1, 6):
        d, converged = klt_translation(frames[k - 1], frames[k], path[k - 1])
        assert converged
        np.testing.assert_allclose(d, path[k] - path[k - 1], atol=0.05)
        np.testing.assert_allclose(path[k - 1] + d, tracks[k, 0], atol=0.1)


def test_bad_frames():
    with pytest.raises(ValueError, match="uint8"):
        klt_track(np.zeros((2, 10, 10)), np.zeros((1, 2)))
