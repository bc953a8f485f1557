"""`frontend.annotate_frames`: the overlays of a tracking video, where they belong and only
where they can be drawn; the result written as `write_video`'s lossless NPZ."""

import numpy as np

from visjax.frontend import annotate_frames, write_video


def test_overlays_drawn_where_given_and_skipped_where_not(tmp_path):
    frames = np.full((3, 60, 80), 40, np.uint8)
    tracked = np.array([[20.0, 30.0], [np.nan, 5.0], [60.0, 30.0]])
    projected = np.array([[50.0, 40.0], [1e5, 0.0], [np.inf, 1.0]])
    out = annotate_frames(frames, tracked, projected, ["a", "b", "c"])
    assert out.shape == (3, 60, 80, 3) and out.dtype == np.uint8
    green = (out[..., 1] > 150) & (out[..., 0] < 100) & (out[..., 2] < 100)
    red = (out[..., 2] > 150) & (out[..., 1] < 100) & (out[..., 0] < 100)
    # frame 0: a circle of radius 6 around (20, 30) and a cross at (50, 40)
    ys, xs = np.nonzero(green[0])
    np.testing.assert_allclose(np.hypot(xs - 20, ys - 30), 6.0, atol=1.5)
    ys, xs = np.nonzero(red[0])
    assert abs(np.median(xs) - 50) <= 1 and abs(np.median(ys) - 40) <= 1
    # frame 1: a non-finite tracked pixel and a projection 1e5 px away: nothing drawn
    assert not green[1].any() and not red[1].any()
    assert green[2].any() and not red[2].any()
    # the captions are white text at the top left, the rest of the frame untouched
    white = out[..., 0] > 200
    assert white[:, :25, :40].any(axis=(1, 2)).all() and not white[:, 30:, :].any()
    with np.load(write_video(tmp_path / "v.npz", out, 30.0)) as saved:  # colour, lossless
        np.testing.assert_array_equal(saved["frames"], out)
        assert float(saved["fps"]) == 30.0


def test_a_video_too_large_once_decoded_is_refused_before_decoding(tmp_path, monkeypatch):
    """Issue 44: the decoded size (frames x width x height, and the stack's copy) is
    checked against `visjax.io.max_data_bytes()` from the container's header, before any
    frame is decoded; an implausible `fps` (1e-9: tracks 1e9 s apart) is refused."""
    import pytest

    from visjax.frontend import read_video
    from visjax.io import DataFormatError

    frames = np.zeros((10, 48, 64), np.uint8)
    frames[:, 10:20, 10:20] = 200
    path = write_video(tmp_path / "v.mp4", frames, 30.0)
    assert read_video(path)[0].shape == (10, 48, 64)
    monkeypatch.setenv("VISJAX_MAX_DATA_BYTES", str(2 * 10 * 48 * 64 - 1))
    with pytest.raises(DataFormatError, match=r"10 frames of 3072 pixels decode to .*limit"):
        read_video(path)
    monkeypatch.delenv("VISJAX_MAX_DATA_BYTES")
    np.savez(tmp_path / "slow.npz", frames=frames, fps=1e-9)
    with pytest.raises(DataFormatError, match="`fps` is 1e-09, outside the plausible"):
        read_video(tmp_path / "slow.npz")
