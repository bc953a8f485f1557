"""`visjax.sim`'s catalogue of canonical scenes: each builds at a short duration with the
documented shapes, its points in front of the camera, the same arrays on every build; the
data-file forms (`*_record`) have the keys of `visjax.io`'s data classes."""

import dataclasses

import jax
import numpy as np
import pytest

from visjax import io, sim

T = 0.5  # seconds: every scene at 1 kHz or less, a few hundred samples


def _assert_same(a, b):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb
    for x, y in zip(la, lb):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def _camera_depths(R_b, x_b, R_c, x_c, world):
    """Depths of world points (n, 3) in the camera mounted at (R_c, x_c) on a platform at
    (R_b, x_b) (N, ...): the z of $R_c^T(R_b^T(w - x_b) - x_c)$, shape (N, n)."""
    R_b, x_b, R_c, x_c, world = (np.asarray(v) for v in (R_b, x_b, R_c, x_c, world))
    q = np.einsum("nji,nkj->nki", R_b, world[None] - x_b[:, None, :])  # platform frame
    return (q - x_c) @ R_c[:, 2]


@pytest.fixture(scope="module")
def plate():
    """The plate with pixel noise and dropouts (its second build: the velocity record)."""
    return sim.sinusoidal_plate_scene(T, noise_px=0.1, dropout=0.05, seed=0)


def _check_fixed_camera_scene(sc, n, n_points, pair):
    assert set(sc) == {"ts", "pixels", "A", "body", "features", "known_pair"}
    assert sc["ts"].shape == (n,) and sc["pixels"].shape == (n, n_points, 2)
    assert sc["A"].shape == (3, 3) and sc["features"].shape == (n_points, 3)
    assert sc["body"].R.shape == (n, 3, 3) and sc["body"].twist.shape == (n, 6)
    assert sc["known_pair"] == pair
    assert np.all(np.diff(np.asarray(sc["ts"])) > 0)
    # a fixed camera: its frame is the world's, depth = z of the object points
    depth = np.asarray(sim.object_points(sc["body"], sc["features"]))[..., 2]
    assert depth.min() > 1.0, depth.min()
    assert np.isfinite(sc["pixels"][0]).all()  # frame 0 complete: the reference


def test_sinusoidal_plate_scene(plate):
    _check_fixed_camera_scene(plate, 500, 6, (1, 3))
    missing = 1.0 - np.mean(np.isfinite(plate["pixels"][..., 0]))
    assert 0.02 < missing < 0.08, missing  # 5% dropouts, all in view


def test_spline_board_scene():
    sc = sim.spline_board_scene(T, noise_px=0.1)
    _check_fixed_camera_scene(sc, 500, 8, (0, 5))
    assert np.isfinite(sc["pixels"]).all()
    _assert_same(sc, sim.spline_board_scene(T, noise_px=0.1))


@pytest.mark.parametrize(
    "build, name",
    [
        (lambda: sim.sideways_camera_scene(T), "sideways"),
        (lambda: sim.circling_camera_scene(T), "circle_diagonal"),
    ],
    ids=["sideways", "circling"],
)
def test_moving_target_scenes(build, name):
    sc = build()
    n = int(T * sim.MOVING_TARGET_RATE_HZ)
    assert isinstance(sc, sim.MovingPointScene)
    assert sc.ts.shape == (n,) and sc.position.shape == (n, 3) and sc.pixels.shape == (n, 2)
    assert sc.camera_velocity.shape == (n, 6) and sc.x.shape == (n, 3)
    assert np.asarray(sc.position)[:, 2].min() > 2.0  # the target 2.5 m in front
    assert np.isfinite(sc.pixels).all()  # in view all along
    _assert_same(sc, sim.moving_target_scene(name, T))
    _assert_same(sc, build())
    cam = sim.moving_target_camera(name, sc.ts)
    assert cam.x.shape == (n, 3) and cam.twist.shape == (n, 6)
    # the scene table's default duration is the builders' default
    assert sim.MOVING_TARGET_SCENES[name]["duration"] == 20.0


@pytest.mark.parametrize(
    "build, n, n_unknown, n_known, dt",
    [
        (lambda: sim.tilted_platform_scene(T), 500, 5, 6, None),
        (lambda: sim.side_looking_platform_scene(T), 50, 4, 8, 1e-3),
    ],
    ids=["tilted", "side_looking"],
)
def test_platform_scenes(build, n, n_unknown, n_known, dt):
    sc = build()
    assert sc["ts"].shape == (n,)
    assert sc["R_b"].shape == (n, 3, 3) and sc["x_b"].shape == (n, 3)
    assert sc["p_s"].shape == (n, n_unknown, 2) and sc["p_c"].shape == (n, n_known, 2)
    assert sc["omega_s"].shape == (n_unknown, 3) and sc["omega_c"].shape == (n_known, 3)
    assert sc["A"].shape == (3, 3) and sc["dt"] == dt
    A0, R0, x0 = sc["nominal"]
    assert A0.shape == (3, 3) and R0.shape == (3, 3) and x0.shape == (3,)
    for world in (sc["omega_s"], sc["omega_c"]):
        depth = _camera_depths(sc["R_b"], sc["x_b"], sc["R_c"], sc["x_c"], world)
        assert depth.min() > 1.5, depth.min()
    assert np.isfinite(sc["p_s"]).all() and np.isfinite(sc["p_c"]).all()
    _assert_same(sc, build())


def test_records_are_data_files(plate):
    """The `*_record` forms: the keys of the `visjax.io` data classes (every required field),
    their scenes' arrays and shapes, noise-free and complete when asked, the same on every
    build."""
    records = [
        (io.VelocityData, sim.sinusoidal_plate_record(T, noise_px=0.0, dropout=0.0)),
        (io.MovingPointData, sim.sideways_camera_record(2 * T, noise_px=0.0)),
        (io.StaticPointsData, sim.tilted_platform_record(2 * T, noise_px=0.0, dropout=0.0)),
    ]
    for cls, rec in records:
        fields = {f.name: f for f in dataclasses.fields(cls)}
        required = {k for k, f in fields.items() if f.default is dataclasses.MISSING}
        assert required <= set(rec) <= set(fields), (cls.__name__, set(rec) ^ set(fields))
        assert all(isinstance(v, np.ndarray) for v in rec.values())
        assert np.isfinite(rec["pixels"]).all(), cls.__name__  # in front, in view
        cls(**rec)  # a valid data object
    v, s, e = (rec for _, rec in records)
    assert v["pixels"].shape == (500, 6, 2) and v["velocity"].shape == (500, 6)
    assert s["pixels"].shape == (50, 2) and s["camera_velocity"].shape == (200, 6)
    assert s["position"][:, 2].min() > 2.0
    assert e["pixels"].shape == (200, 11, 2) and e["platform_R"].shape == (200, 3, 3)
    _assert_same(s, sim.sideways_camera_record(2 * T, noise_px=0.0))
    _assert_same(e, sim.tilted_platform_record(2 * T, noise_px=0.0, dropout=0.0))
    # the velocity record with noise and dropouts: the plate scene's arrays (features and
    # noise from the same seed), so built twice the same
    noisy = sim.sinusoidal_plate_record(T, seed=0, noise_px=0.1, dropout=0.05)
    np.testing.assert_array_equal(noisy["t"], plate["ts"])
    np.testing.assert_array_equal(noisy["pixels"], plate["pixels"])
    np.testing.assert_array_equal(noisy["velocity"], plate["body"].twist)
    np.testing.assert_array_equal(noisy["R_star"], plate["body"].R[0])
    np.testing.assert_array_equal(noisy["s1"], plate["features"][0])
    # the euclidean record's features are the tilted scene's
    sc = sim.tilted_platform_scene(T)
    np.testing.assert_allclose(e["known_features"], sc["omega_c"], rtol=0, atol=1e-15)
    np.testing.assert_allclose(e["features"], sc["omega_s"], rtol=0, atol=1e-15)
