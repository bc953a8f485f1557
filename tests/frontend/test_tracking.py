"""Thesis sections 2.4 and 5.1: video to pixel tracks. A textured table seen by a moving
camera is rendered with exact perspective; every tracked pixel is compared with the
projection of the table point it started on."""

import functools

import numpy as np
import pytest

from visjax.frontend import (
    Plane,
    detect_aruco,
    detect_tags,
    fiducial_marker,
    plane_homography,
    project_points,
    read_video,
    render_planes,
    textured_table,
    track_frames,
    track_marker,
    track_tags,
    write_video,
)
from visjax.geometry import undistort_pixels

SHAPE = (240, 320)
N_FRAMES = 30
K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])


def _rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    W = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * W + (1 - np.cos(angle)) * W @ W


def _translation(p):
    T = np.eye(4)
    T[:3, 3] = p
    return T


@functools.cache
def _table() -> Plane:
    # 640 x 480 texture pixels of 2.5 mm: a 1.6 m x 1.2 m table in the world plane z = 0
    return Plane(textured_table((480, 640), seed=1), 0.0025, _translation([-0.8, -0.6, 0.0]))


def _pose(k, pan=0.0):
    """A smooth known trajectory: the camera 0.9 m from the table, translating and turning
    a little (about 2.5 degrees over 30 frames), so the perspective changes."""
    s = k / (N_FRAMES - 1)
    R = _rot([0.3, 1.0, 0.2], 0.045 * np.sin(1.5 * s)) @ _rot([1.0, 0.0, 0.0], 0.12)
    p = np.array([0.06 * s - 0.03 + pan * k, 0.03 * np.sin(2 * s) + 0.05, -0.9 + 0.08 * s])
    return R, p


def _render(k, planes=None, pan=0.0):
    return render_planes([_table()] if planes is None else planes, K, *_pose(k, pan), SHAPE)


@functools.cache
def _frames() -> np.ndarray:
    return np.stack([_render(k) for k in range(N_FRAMES)])


def _back_project(R, p, uv, plane):
    """World points of the plane seen at pixels `uv` (the ray from the camera centre)."""
    rays = np.linalg.solve(K, np.c_[uv, np.ones(len(uv))].T).T @ R.T
    n, o = plane.T_world_plane[:3, 2], plane.T_world_plane[:3, 3]
    return p + ((o - p) @ n / (rays @ n))[:, None] * rays


def _truth(tracks, pan=0.0):
    """(N, n, 2): each feature's table point, from its detection, projected in every frame."""
    truth = np.full(tracks.pixels.shape, np.nan)
    for j, k0 in enumerate(tracks.born):
        w = _back_project(*_pose(k0, pan), tracks.pixels[k0, j][None], _table())
        for k in range(len(tracks.t)):
            truth[k, j] = project_points(K, *_pose(k, pan), w)[0]
    return truth


def _rms(tracks, truth):
    err = np.linalg.norm(tracks.pixels - truth, axis=-1)
    return float(np.sqrt(np.nanmean(err**2))), err


def test_tracks_match_the_projected_truth_lossless():
    frames = _frames()
    tracks = track_frames(frames, fps=30.0, max_features=150, redetect_below=0)
    n = tracks.pixels.shape[1]
    assert n >= 80
    assert np.all(tracks.born == 0)
    np.testing.assert_allclose(tracks.t, np.arange(N_FRAMES) / 30.0)
    alive = tracks.alive
    assert alive[0].all()
    # lost features are never revived: alive is a prefix of the frames
    assert np.all(alive[1:] <= alive[:-1])
    truth = _truth(tracks)
    # the view drifts about 20 px up and left: the features that stay a window inside the
    # image all survive the 30 frames; the others are lost at the border
    inside = np.all(
        (truth[..., 0] >= 12)
        & (truth[..., 0] <= SHAPE[1] - 13)
        & (truth[..., 1] >= 12)
        & (truth[..., 1] <= SHAPE[0] - 13),
        axis=0,
    )
    assert inside.sum() > 0.6 * n
    assert alive[-1, inside].mean() > 0.97
    rms, err = _rms(tracks, truth)
    assert rms < 0.5  # measured 0.12 px over all alive tracks (max 0.78 px)
    assert np.nanmax(err) < 1.5


def test_tracks_through_an_mp4_written_and_read_back(tmp_path):
    frames = _frames()
    path = write_video(tmp_path / "table.mp4", frames, 30.0)
    back, fps = read_video(path)
    assert back.shape == frames.shape and back.dtype == np.uint8
    assert fps == pytest.approx(30.0)
    # mp4v is lossy: a few grey levels of error, no shift
    assert np.abs(back.astype(float) - frames).mean() < 4.0
    tracks = track_frames(back, fps=fps, max_features=150, redetect_below=0)
    assert tracks.alive[-1].mean() > 0.6
    rms, _ = _rms(tracks, _truth(tracks))
    # the same bound as lossless: measured 0.13 px through mp4v (0.12 px lossless)
    assert rms < 0.5


def test_npz_video_is_lossless(tmp_path):
    frames = _frames()[:5]
    back, fps = read_video(write_video(tmp_path / "table.npz", frames, 12.5))
    np.testing.assert_array_equal(back, frames)
    assert fps == 12.5


def _occluder():
    """A textured board 0.25 m in front of the table, covering part of the view."""
    T = _translation([-0.12, -0.04, -0.25])
    return Plane(textured_table((100, 140), seed=7), 0.0025, T)


def test_forward_backward_check_drops_occluded_features():
    import cv2

    k0 = 15  # the board appears in front of the table in frame 15
    board = _occluder()
    frames = np.stack(
        [_render(k, [_table(), board] if k >= k0 else [_table()]) for k in range(N_FRAMES)]
    )
    R, p = _pose(k0)
    quad = project_points(K, R, p, board.world_points(board.corners_texture()))
    dropped = {}
    for fb, residual in ((0.5, 15.0), (0.5, np.inf), (np.inf, np.inf)):
        tracks = track_frames(
            frames, max_features=150, fb_threshold=fb, max_residual=residual, redetect_below=0
        )
        truth = _truth(tracks)
        # features well inside the board's image at frame k0 (their whole window covered)
        inside = np.array(
            [
                cv2.pointPolygonTest(quad.astype(np.float32), tuple(map(float, q)), True) > 12
                for q in truth[k0]
            ]
        )
        assert inside.sum() >= 15
        assert tracks.alive[k0 - 1, inside].all()  # tracked up to the occlusion
        dropped[fb, residual] = 1 - tracks.alive[k0, inside].mean()
        if fb == 0.5 and residual == 15.0:  # the defaults
            assert not tracks.alive[k0:, inside].any()  # NaN from the occlusion on
            rms, _ = _rms(tracks, truth)
            assert rms < 0.5  # the survivors are still right
        if fb == np.inf:
            # without the checks, covered features are reported at the wrong place
            err = np.linalg.norm(tracks.pixels[k0, inside] - truth[k0, inside], axis=-1)
            assert np.nanmax(err) > 2.0
    # the forward-backward check alone drops nearly all (measured 26 of 27: one false
    # match on the board is consistent both ways, the residual check catches it)
    assert dropped[0.5, np.inf] > 0.9
    assert dropped[np.inf, np.inf] < dropped[0.5, np.inf] - 0.2


def test_redetection_adds_columns():
    pan = 0.012  # metres per frame: the view slides off the first features
    frames = np.stack([_render(k, pan=pan) for k in range(N_FRAMES)])
    tracks = track_frames(frames, max_features=60, redetect_below=40, min_distance=10.0)
    n0 = int(np.sum(tracks.born == 0))
    n = tracks.pixels.shape[1]
    assert n0 == 60 and n > n0 + 10
    new = tracks.born > 0
    for j in np.flatnonzero(new):
        b = tracks.born[j]
        assert np.isnan(tracks.pixels[:b, j]).all() and tracks.alive[b, j]
        others = tracks.alive[b] & (np.arange(n) != j) & (tracks.born < b)
        d = np.linalg.norm(tracks.pixels[b, others] - tracks.pixels[b, j], axis=-1)
        assert d.min() >= 10.0 - 1e-9
    assert np.all(tracks.alive.sum(axis=1)[1:] >= 40)  # re-detection keeps enough alive
    rms, _ = _rms(tracks, _truth(tracks, pan))
    assert rms < 0.5


def test_rendered_homography_agrees_with_projection():
    import cv2

    table = _table()
    R, p = _pose(20)
    H = plane_homography(table, K, R, p)
    corners = table.corners_texture()
    via_cv = cv2.perspectiveTransform(corners[None], H)[0]
    truth = project_points(K, R, p, table.world_points(corners))
    np.testing.assert_allclose(via_cv, truth, atol=1e-9)

    # a small bright blob on a dark board, tilted: its rendered centroid is its projection
    tex = np.zeros((60, 80), np.uint8)
    yy, xx = np.mgrid[0:60, 0:80]
    centre = np.array([37.3, 24.6])  # texture coordinates (x_t, y_t)
    tex[:] = np.clip(
        250 * np.exp(-((xx - centre[0]) ** 2 + (yy - centre[1]) ** 2) / (2 * 2.5**2)), 0, 255
    ).round()
    T = np.eye(4)
    T[:3, :3] = _rot([1.0, 0.5, 0.0], 0.5)
    T[:3, 3] = [-0.05, -0.02, -0.3]
    board = Plane(tex, 0.002, T)
    image = render_planes([board], K, R, p, SHAPE).astype(float)
    expected = project_points(K, R, p, board.world_points(centre[None]))[0]
    v, u = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    win = (np.abs(u - expected[0]) < 12) & (np.abs(v - expected[1]) < 12)
    weight = np.where(win, image, 0.0)
    centroid = np.array([(weight * u).sum(), (weight * v).sum()]) / weight.sum()
    assert np.linalg.norm(centroid - expected) < 0.15  # measured 0.035 px

    # honest skips: a board behind the camera draws nothing, neither does one seen edge-on
    behind = Plane(tex, 0.002, _translation(p - 0.5 * R[:, 2]))
    assert render_planes([behind], K, R, p, SHAPE, background=7).max() == 7
    edge = np.eye(4)
    edge[:3, :3] = R @ _rot([1.0, 0.0, 0.0], np.pi / 2)  # the board's plane holds the ray z
    edge[:3, 3] = p
    with pytest.raises(ValueError, match="edge-on"):
        plane_homography(Plane(tex, 0.002, edge), K, R, p)
    assert render_planes([Plane(tex, 0.002, edge)], K, R, p, SHAPE, background=7).max() == 7


def test_a_plane_crossing_the_camera_plane_is_drawn_only_in_front():
    # an 80 m x 80 m floor 0.5 m below the camera, half of it behind the camera
    R = _rot([1.0, 0.0, 0.0], -0.3)  # looking 0.3 rad down (y is down in the camera)
    p = np.zeros(3)
    floor = np.eye(4)
    floor[:3, :3] = _rot([1.0, 0.0, 0.0], np.pi / 2)  # plane normal along world -y
    floor[:3, 3] = [-40.0, 0.5, -40.0]
    plane = Plane(np.full((800, 800), 200, np.uint8), 0.1, floor)
    depth = (plane.world_points(plane.corners_texture()) - p) @ R[:, 2]
    assert depth.min() < 0 < depth.max()  # it crosses the camera's plane
    image = render_planes([plane], K, R, p, SHAPE, background=0)
    rows = image.mean(axis=1)
    # the horizon is at v = c_v - f tan(0.3) = 26.7 and the floor's far edge (40 m) at
    # v = 30.9; above the horizon the rays meet the floor only behind the camera
    assert rows[:26].max() == 0  # nothing mirrored from behind
    assert rows[33:].min() == 200  # the floor


def _marker(marker_id):
    """An ArUco marker 35 cm in front of the table, tilted by 0.35 rad, and its corners in
    texture coordinates."""
    tex, corners = fiducial_marker(marker_id, cell=12)
    T = np.eye(4)
    T[:3, :3] = _rot([0.2, 1.0, 0.0], 0.35)
    T[:3, 3] = [-0.08, -0.05, -0.35]
    return Plane(tex, 0.0015, T), corners


def test_aruco_detector_finds_the_rendered_marker_corners():
    marker, corners = _marker(7)
    world = marker.world_points(corners)
    frames = np.stack([_render(k, [_table(), marker]) for k in range(6)])
    ids, found = detect_aruco(frames[0])
    assert list(ids) == [7]
    truth = project_points(K, *_pose(0), world)
    err = np.linalg.norm(found[0] - truth, axis=-1)
    assert err.max() < 0.5  # measured 0.10-0.25 px
    tracks = track_frames(frames, detector="aruco")
    assert tracks.pixels.shape[1] == 5
    assert list(tracks.marker_id) == [7] * 5 and list(tracks.corner) == [0, 1, 2, 3, 4]
    centre = marker.world_points(corners.mean(axis=0)[None])
    truth_k = np.stack([project_points(K, *_pose(k), np.vstack([world, centre])) for k in range(6)])
    assert tracks.alive[:, :4].all()  # the corners are tracked through the frames
    err = np.linalg.norm(tracks.pixels - truth_k, axis=-1)
    assert np.nanmax(err[:, :4]) < 0.5


def test_a_lens_view_shows_the_marker_where_the_lens_projects_it():
    """`render_planes(..., dist=)` draws what a camera with that lens sees: ArUco finds the
    marker's corners where `project_points(..., dist=)` puts them, several pixels from the
    pinhole's, and `undistort_pixels` brings them back to the pinhole's."""
    dist = np.array([-0.4, 0.1, 1e-3, -1e-3, 0.0])
    marker, corners = _marker(7)
    marker.T_world_plane[:3, 3] = [0.06, 0.04, -0.35]  # off the optical axis, in view
    world = marker.world_points(corners)
    R, p = _pose(0)
    image = render_planes([_table(), marker], K, R, p, SHAPE, supersample=2, dist=dist)
    ids, found = detect_aruco(image)
    assert list(ids) == [7]
    lens = project_points(K, R, p, world, dist=dist)
    pinhole = project_points(K, R, p, world)
    moved = np.linalg.norm(lens - pinhole, axis=-1)
    assert moved.min() > 1.0 and moved.max() > 10.0  # the lens moves every corner
    assert np.linalg.norm(found[0] - lens, axis=-1).max() < 0.5
    back = np.asarray(undistort_pixels(found[0], K, dist))
    assert np.linalg.norm(back - pinhole, axis=-1).max() < 0.5


def test_track_marker_follows_refines_and_recovers_the_marker():
    marker, corners = _marker(3)
    world = np.vstack([marker.world_points(corners), marker.world_points(corners.mean(0)[None])])
    # a grey card passes in front of the marker in frames 10-13
    card = Plane(np.full((40, 40), 128, np.uint8), 0.004, _translation([-0.12, -0.1, -0.5]))
    frames = np.stack(
        [
            _render(k, [_table(), marker, card] if 10 <= k <= 13 else [_table(), marker])
            for k in range(N_FRAMES)
        ]
    )
    tracks = track_marker(frames)
    assert list(tracks.corner) == [0, 1, 2, 3, 4] and set(tracks.marker_id) == {3}
    truth = np.stack([project_points(K, *_pose(k), world) for k in range(N_FRAMES)])
    err = np.linalg.norm(tracks.pixels - truth, axis=-1)
    covered = np.zeros(N_FRAMES, bool)
    covered[10:14] = True
    assert np.all(np.isnan(tracks.pixels[covered]))  # lost under the card, not drifting
    assert tracks.alive[~covered].all()  # re-detected as soon as it is seen again
    assert np.nanmax(err[~covered]) < 0.3
    assert np.sqrt(np.nanmean(err[~covered, 4] ** 2)) < 0.15  # the centre


def test_apriltag_corners_are_features_4i_to_4i_plus_3_at_sub_pixel_accuracy(tmp_path, capsys):
    """An AprilTag of the 36h11 family (id 3) drawn on the scene by the renderer: its four
    corners are found in every frame within 0.5 px of their projections (measured 0.14-0.31
    px), as features 12-15
    (4 i + c) of `track_tags` and of `visjax track --tags 36h11`; ids never seen are NaN;
    --tags with --planar is refused in one line."""
    from visjax.cli import main

    tex, corners = fiducial_marker(3, cell=8, dictionary="36h11")
    T = np.eye(4)
    T[:3, :3] = _rot([0.2, 1.0, 0.0], 0.35)
    T[:3, 3] = [-0.08, -0.05, -0.35]
    tag = Plane(tex, 0.0015, T)
    frames = np.stack([_render(k, [_table(), tag]) for k in range(4)])
    tracks = track_tags(frames, "36h11", fps=30.0)
    assert tracks.pixels.shape == (4, 16, 2)
    assert np.all(np.isnan(tracks.pixels[:, :12])) and tracks.alive[:, 12:].all()
    assert list(tracks.marker_id[12:]) == [3] * 4 and list(tracks.corner[12:]) == [0, 1, 2, 3]
    truth = np.stack([project_points(K, *_pose(k), tag.world_points(corners)) for k in range(4)])
    assert np.linalg.norm(tracks.pixels[:, 12:] - truth, axis=-1).max() < 0.5
    assert list(detect_tags(frames[0], "36h11")[0]) == [3]
    assert len(detect_tags(frames[0], "25h9")[0]) == 0  # another family's dictionary
    with pytest.raises(ValueError, match="unknown AprilTag family"):
        detect_tags(frames[0], "36h12")

    video = write_video(tmp_path / "tag.npz", frames, 30.0)
    out = tmp_path / "tags.npz"
    assert main(["track", str(video), "--tags", "36h11", "--quiet", "--out", str(out)]) == 0
    with np.load(out) as data:
        np.testing.assert_array_equal(data["pixels"], tracks.pixels)
    argv = ["track", str(video), "--tags", "36h11", "--planar", "--out", str(tmp_path / "x.npz")]
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2 and "no --detector or --planar" in capsys.readouterr().err


def test_cli_track_writes_npz_and_csv(tmp_path, capsys):
    from visjax.cli import main
    from visjax.io import load_tracks_csv

    video = write_video(tmp_path / "small.mp4", _frames()[:12], 30.0)
    out = tmp_path / "res" / "tracks.npz"
    assert main(["track", str(video), "--out", str(out), "--max-features", "40"]) == 0
    printed = capsys.readouterr().out
    assert "12 frames" in printed and str(out) in printed
    with np.load(out) as data:
        assert set(data.files) == {"t", "pixels"}
        t, pixels = data["t"], data["pixels"]
    assert t.shape == (12,) and pixels.shape[0] == 12 and pixels.shape[2] == 2
    assert 20 <= pixels.shape[1] <= 40
    np.testing.assert_allclose(t, np.arange(12) / 30.0)
    assert np.isfinite(pixels[0]).all()
    assert [p.name for p in out.parent.iterdir()] == ["tracks.npz"]  # no staging left

    csv = tmp_path / "tracks.csv"
    assert main(["track", str(video), "--out", str(csv), "--quiet", "--fps", "10"]) == 0
    assert capsys.readouterr().out == ""
    t_csv, pixels_csv = load_tracks_csv(csv)
    np.testing.assert_allclose(t_csv, np.arange(12) / 10.0)
    assert pixels_csv.shape[1] >= 20


@pytest.mark.parametrize(
    "extra",
    [
        ["--fb-threshold", "-1"],
        ["--max-features", "0"],
        ["--fps", "nan"],
        ["--detector", "sift"],
    ],
    ids=" ".join,
)
def test_cli_track_bad_options(extra, tmp_path, capsys):
    from visjax.cli import main

    video = write_video(tmp_path / "v.npz", _frames()[:2], 30.0)
    out = tmp_path / "o" / "tracks.npz"
    with pytest.raises(SystemExit) as e:
        main(["track", str(video), "--out", str(out)] + extra)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("visjax: error:") and err.count("\n") == 1
    assert not out.parent.exists()


def test_cli_track_bad_files(tmp_path, capsys):
    from visjax.cli import main

    out = tmp_path / "tracks.npz"
    with pytest.raises(SystemExit) as e:
        main(["track", str(tmp_path / "missing.mp4"), "--out", str(out)])
    assert e.value.code == 2 and "no such file" in capsys.readouterr().err
    video = write_video(tmp_path / "v.npz", _frames()[:2], 30.0)
    with pytest.raises(SystemExit) as e:
        main(["track", str(video), "--out", str(tmp_path / "tracks.txt")])
    assert e.value.code == 2 and ".npz or .csv" in capsys.readouterr().err
    garbage = tmp_path / "garbage.mp4"
    garbage.write_text("not a video")
    assert main(["track", str(garbage), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("visjax: error:") and err.count("\n") == 1
    # no marker in the video: an error, not an empty tracks file
    assert main(["track", str(video), "--out", str(out), "--detector", "aruco"]) == 2
    assert "found no feature" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["garbage.mp4", "v.npz"]


def test_cli_track_refuses_damaged_videos_and_stills(tmp_path, capsys):
    """A corrupt MP4 (its decoder's complaints, read while decoding; or fewer frames
    decode than its container declares), a still image renamed `.mp4`, a one-frame NPZ:
    one line, exit status 2, nothing written; `--allow-damaged` tracks a video whose
    damage the decoder concealed."""
    import cv2

    from visjax.cli import main

    frames = _frames()[:24]
    raw = write_video(tmp_path / "good.mp4", frames, 30.0).read_bytes()

    def garbled(name, size):  # `size` bytes in the middle of the stream overwritten
        data = bytearray(raw)
        data[len(raw) // 2 : len(raw) // 2 + size] = bytes(i % 251 for i in range(size))
        (tmp_path / name).write_bytes(bytes(data))
        return tmp_path / name

    concealed, broken = garbled("concealed.mp4", 64), garbled("broken.mp4", 1024)
    png = tmp_path / "still.png"
    cv2.imwrite(str(png), frames[0])
    png.rename(tmp_path / "still.mp4")
    write_video(tmp_path / "one.npz", frames[:1], 30.0)
    out = tmp_path / "out" / "tracks.npz"
    for name, words in (
        ("concealed.mp4", "the decoder reported"),
        ("broken.mp4", "a damaged video"),
        ("still.mp4", "tracking needs at least 2"),
        ("one.npz", "tracking needs at least 2"),
    ):
        assert main(["track", str(tmp_path / name), "--out", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("visjax: error:") and words in err and err.count("\n") == 1, err
    assert not out.parent.exists()
    back, _ = read_video(tmp_path / "good.mp4")  # the intact file reads whole, no complaint
    assert back.shape[0] == 24
    # every frame of the concealed one decodes: tracked when allowed
    back, _ = read_video(concealed, allow_damaged=True)
    assert back.shape[0] == 24
    assert main(["track", str(concealed), "--out", str(out), "--quiet", "--allow-damaged"]) == 0
    assert out.is_file()
    # the broken one ends early: refused even when allowed
    with pytest.raises(ValueError, match="declares 24 frames but only"):
        read_video(broken, allow_damaged=True)


def test_bad_inputs_raise_the_documented_errors(tmp_path):
    frames = _frames()[:3]
    with pytest.raises(ValueError, match="uint8"):
        track_frames(frames.astype(float))
    with pytest.raises(ValueError, match=r"\(N, H, W\)"):
        track_frames(frames[0])
    with pytest.raises(ValueError, match="detector"):
        track_frames(frames, detector="sift")
    with pytest.raises(ValueError, match="points"):
        track_frames(frames, points=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="fps"):
        track_frames(frames, fps=0.0)
    with pytest.raises(FileNotFoundError):
        read_video(tmp_path / "missing.mp4")
    (tmp_path / "junk.mp4").write_bytes(b"\x00" * 100)
    with pytest.raises(ValueError, match="junk.mp4"):
        read_video(tmp_path / "junk.mp4")
    np.savez(tmp_path / "nokeys.npz", images=frames)
    with pytest.raises(ValueError, match="'frames' and 'fps'"):
        read_video(tmp_path / "nokeys.npz")
    np.savez(tmp_path / "float.npz", frames=frames.astype(np.float32), fps=30.0)
    with pytest.raises(ValueError, match="uint8"):
        read_video(tmp_path / "float.npz")
    with pytest.raises(ValueError, match="uint8"):
        write_video(tmp_path / "x.mp4", frames.astype(np.int16), 30.0)
    with pytest.raises(OSError, match="could not open"):
        write_video(tmp_path / "no" / "such" / "x.mp4", frames, 30.0)
    # a point behind the camera has no pixel
    R, p = _pose(0)
    uv = project_points(K, R, p, np.array([p + R[:, 2], p - R[:, 2]]))
    np.testing.assert_allclose(uv[0], K[:2, 2], atol=1e-9)
    assert np.isnan(uv[1]).all()


def test_homography_outliers_are_cut_where_they_drift():
    """Thirty features of a plane seen by a moving camera (exact homographies, 0.3 px
    noise), three of them drifting 0.5 px per frame from frame 12 (a feature sliding along
    an edge): the three are cut, once their drift over the gap passes the threshold, and
    no other track is touched."""
    from visjax.frontend import LOST_REASONS, Tracks, reject_homography_outliers

    rng = np.random.default_rng(0)
    n_frames, n = 40, 30
    A = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    p0 = rng.uniform([40, 40], [600, 440], size=(n, 2))
    pixels = np.empty((n_frames, n, 2))
    for k in range(n_frames):
        R = _rot([0.2, 1.0, 0.1], 0.004 * k)
        t = np.array([0.01, -0.004, 0.006]) * k
        H = A @ (R - np.outer(t, [0, 0, 1.0]) / 2.0) @ np.linalg.inv(A)
        q = np.c_[p0, np.ones(n)] @ H.T
        pixels[k] = q[:, :2] / q[:, 2:]
    pixels += 0.3 * rng.normal(size=pixels.shape)
    drifting = np.array([3, 17, 25])
    pixels[12:, drifting] += 0.5 * np.arange(1, n_frames - 11)[:, None, None] * np.array([1.0, 0.6])
    tracks = Tracks(
        t=np.arange(n_frames) / 30.0, pixels=pixels, born=np.zeros(n, int),
        marker_id=np.full(n, -1), corner=np.full(n, -1), fps=30.0,
    )  # fmt: skip
    cut = reject_homography_outliers(tracks, threshold_px=3.0, gap=10)
    assert np.isfinite(tracks.pixels).all()  # the input is not modified
    others = np.setdiff1d(np.arange(n), drifting)
    np.testing.assert_array_equal(cut.pixels[:, others], pixels[:, others])
    assert np.all(cut.lost_reason[drifting] == LOST_REASONS.index("homography"))
    assert np.all(cut.lost_reason[others] == -1)
    # 0.5 x 1.17 px per frame: past 3 px over the 10-frame gap from about frame 17
    assert np.all((cut.lost_frame[drifting] >= 15) & (cut.lost_frame[drifting] <= 20))
    for j in drifting:
        f = cut.lost_frame[j]
        assert np.isnan(cut.pixels[f:, j]).all() and np.isfinite(cut.pixels[:f, j]).all()
    assert cut.lost_counts()["homography"] == 3
    with pytest.raises(ValueError, match="`gap` must be >= 1"):
        reject_homography_outliers(tracks, gap=0)


def test_cli_track_planar_reports_why_tracks_ended(tmp_path, capsys):
    from visjax.cli import main

    video = write_video(tmp_path / "small.mp4", _frames()[:12], 30.0)
    out = tmp_path / "tracks.npz"
    assert main(["track", str(video), "--out", str(out), "--planar", "--max-features", "40"]) == 0
    printed = capsys.readouterr().out
    assert "tracks ended by:" in printed
    # the table is a plane: its tracks follow the homography (none cut at 3 px)
    assert "homography" not in printed.split("tracks ended by:")[1]
