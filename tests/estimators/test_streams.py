"""The three stream builders from raw measurements: a bad sample anywhere ends the run with
`nonfinite_measurement` at that sample, never a finite estimate reported as success."""

import jax
import numpy as np
import pytest

from visjax import RESULTS
from visjax.estimators import (
    SaveAt,
    VelocityEstimator,
    fixed_camera,
    moving_point_stream,
    run,
    static_points_stream,
    velocity_stream,
)
from visjax.papers import chitrakaran, jang, nath


def _assert_stops_at(estimator, stream, k, dt=None):
    sol = run(estimator, stream, dt=dt, saveat=SaveAt(outputs=False), throw=False)
    assert sol.result == RESULTS.nonfinite_measurement
    assert int(sol.failed_sample) == k
    assert all(np.all(np.isfinite(x)) for x in jax.tree_util.tree_leaves(sol.final_state))
    with pytest.raises(RuntimeError, match="measurement sample is not finite"):
        run(estimator, stream, dt=dt, saveat=SaveAt(outputs=False))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_velocity_stream(bad):
    sc = chitrakaran.section6_scenario(0.3, 1000.0)
    pixels = np.asarray(sc.pixels).copy()
    pixels[37, 2, 1] = bad
    camera = fixed_camera(
        pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star, throw=False
    )
    stream = velocity_stream(sc.ts, pixels, camera, throw=False)
    est = VelocityEstimator(K=chitrakaran.K_EQ63, rho=chitrakaran.RHO_EQ63)
    _assert_stops_at(est, stream, 37)
    with pytest.raises(RuntimeError, match="not finite"):
        velocity_stream(sc.ts, pixels, camera)


def test_moving_point_stream_at_the_camera_rate():
    sc = jang.scenario("II.1", 1.0)
    pixels = np.asarray(sc.frame_pixels).copy()
    velocities = np.asarray(sc.frame_velocities).copy()
    pixels[12, 0] = np.nan
    stream = moving_point_stream(sc.frame_ts, pixels, velocities, sc.Kc_observer, throw=False)
    _assert_stops_at(jang.observer("II.1"), stream, 12, dt=1e-3)
    with pytest.raises(RuntimeError, match=r"moving_point_stream: sample 12 \(t = 0.4 s\)"):
        moving_point_stream(sc.frame_ts, pixels, velocities, sc.Kc_observer)
    velocities[12, 5] = np.nan
    pixels[12, 0] = 300.0
    stream = moving_point_stream(sc.frame_ts, pixels, velocities, sc.Kc_observer, throw=False)
    _assert_stops_at(jang.observer("II.1"), stream, 12, dt=1e-3)
    with pytest.raises(RuntimeError, match="sample 12"):
        moving_point_stream(sc.frame_ts, pixels, velocities, sc.Kc_observer)
    # held over, the dropped frame is no longer a failure
    pixels[12, 0] = np.nan
    velocities[12, 5] = 0.0
    moving_point_stream(sc.frame_ts, pixels, velocities, sc.Kc_observer, dropped="hold")


def test_static_points_stream():
    sc = nath.scenario(0.05)
    p_s = np.asarray(sc.p_s).copy()
    p_s[23, 1, 0] = np.inf  # a NaN pixel is a missing feature (masked), an infinite one is bad
    stream = static_points_stream(sc.ts, sc.R_b, sc.x_b, p_s, sc.p_c, sc.omega_c, throw=False)
    _assert_stops_at(nath.initial_estimator(sc), stream, 23)
    with pytest.raises(RuntimeError, match="static_points_stream: sample 23"):
        static_points_stream(sc.ts, sc.R_b, sc.x_b, p_s, sc.p_c, sc.omega_c)
    x_b = np.asarray(sc.x_b).copy()
    x_b[31, 2] = np.inf
    stream = static_points_stream(sc.ts, sc.R_b, x_b, sc.p_s, sc.p_c, sc.omega_c, throw=False)
    _assert_stops_at(nath.initial_estimator(sc), stream, 31)
    with pytest.raises(RuntimeError, match="sample 31"):
        static_points_stream(sc.ts, sc.R_b, x_b, sc.p_s, sc.p_c, sc.omega_c)
    # a NaN pixel is a feature not seen: no failure
    p_s[23, 1, 0] = np.nan
    static_points_stream(sc.ts, sc.R_b, sc.x_b, p_s, sc.p_c, sc.omega_c)


def test_a_stream_built_inside_jit_keeps_its_times_for_dt():
    """`run(..., dt=...)` needs concrete times; a stream built inside `jit(vmap)` from NumPy
    times keeps them concrete (version 1 refused it), and matches the one built outside."""
    sc = jang.scenario("II.1", 1.0)
    frame_ts = np.asarray(sc.frame_ts)
    pixels = np.asarray(sc.frame_pixels)
    observer = jang.observer("II.1")

    def final_depth(noise):
        stream = moving_point_stream(frame_ts, pixels + noise, sc.frame_velocities, sc.Kc_observer)
        sol = run(observer, stream, dt=1e-3, saveat=SaveAt(outputs=False), throw=False)
        return sol.final_state.z[2], sol.result._value

    noise = np.zeros((2,) + pixels.shape)
    noise[1] = 0.1
    z, codes = jax.jit(jax.vmap(final_depth))(noise)
    assert np.all(codes == RESULTS.successful._value)
    outside = run(
        observer,
        moving_point_stream(frame_ts, pixels, sc.frame_velocities, sc.Kc_observer),
        dt=1e-3,
        saveat=SaveAt(outputs=False),
    )
    np.testing.assert_allclose(z[0], outside.final_state.z[2], rtol=1e-12)
    assert z[1] != z[0]


# ---------------------------------------------------------------------------------------
# `reject`: a sample an outlier test rejected is held, as a missing one (the oracle: the
# same stream with those samples missing)


def _final(estimator, stream, dt=None):
    sol = run(estimator, stream, dt=dt, saveat=SaveAt(outputs=False), throw=False)
    assert sol.result == RESULTS.successful
    return sol.final_state


def _equal(a, b, rtol=1e-12):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_allclose(x, y, rtol=rtol, atol=1e-12)


@pytest.mark.slow  # the unit tier's time: a velocity compile or 200 fits
def test_velocity_stream_reject(no_jaxtyping):
    sc = chitrakaran.section6_scenario(0.3, 1000.0)
    pixels = np.asarray(sc.pixels).copy()
    camera = fixed_camera(pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star)
    est = VelocityEstimator(K=chitrakaran.K_EQ63, rho=chitrakaran.RHO_EQ63)
    bad = pixels.copy()
    bad[[40, 41, 120]] += 30.0  # whole frames thrown off
    reject = np.zeros(len(sc.ts), bool)
    reject[[40, 41, 120]] = True
    missing = pixels.copy()
    missing[[40, 41, 120]] = np.nan
    told = _final(est, velocity_stream(sc.ts, missing, camera, dropped="hold"))
    for dropped in ("hold", "stop"):
        stream = velocity_stream(sc.ts, bad, camera, dropped=dropped, reject=reject)
        _equal(_final(est, stream), told, rtol=1e-9)
    plain = _final(est, velocity_stream(sc.ts, bad, camera))
    assert np.max(np.abs(np.asarray(plain.eta - told.eta))) > 1.0
    # single features: out of view in that frame
    per = np.zeros(pixels.shape[:2], bool)
    per[[50, 51], 2] = True
    bad_one, missing_one = pixels.copy(), pixels.copy()
    bad_one[[50, 51], 2] += 30.0
    missing_one[[50, 51], 2] = np.nan
    _equal(
        _final(est, velocity_stream(sc.ts, bad_one, camera, dropped="hold", reject=per)),
        _final(est, velocity_stream(sc.ts, missing_one, camera, dropped="hold")),
    )
    with pytest.raises(ValueError, match='per-feature `reject` .* needs `dropped="hold"`'):
        velocity_stream(sc.ts, bad_one, camera, reject=per)
    first = np.zeros(len(sc.ts), bool)
    first[0] = True
    with pytest.raises(ValueError, match="first sample starts the run"):
        velocity_stream(sc.ts, pixels, camera, reject=first)
    with pytest.raises(ValueError, match="boolean mask"):
        velocity_stream(sc.ts, pixels, camera, reject=first.astype(float))
    with pytest.raises(ValueError, match=r"shape \(300,\) or \(300, 4\)"):
        velocity_stream(sc.ts, pixels, camera, reject=first[:10])


def test_moving_point_stream_reject():
    sc = jang.scenario("II.1", 1.0)
    pixels = np.asarray(sc.frame_pixels).copy()
    v = sc.frame_velocities
    reject = np.zeros(len(sc.frame_ts), bool)
    reject[[12, 13]] = True
    bad, missing = pixels.copy(), pixels.copy()
    bad[[12, 13]] += 40.0
    missing[[12, 13]] = np.nan
    obs = jang.observer("II.1")
    told = _final(
        obs, moving_point_stream(sc.frame_ts, missing, v, sc.Kc_observer, dropped="hold"), 1e-3
    )
    for dropped in ("stop", "hold"):
        stream = moving_point_stream(
            sc.frame_ts, bad, v, sc.Kc_observer, dropped=dropped, reject=reject
        )
        _equal(_final(obs, stream, 1e-3), told)
    # a frame that is NaN without being rejected still stops a "stop" stream
    missing[20] = np.nan
    stream = moving_point_stream(
        sc.frame_ts, missing, v, sc.Kc_observer, reject=reject, throw=False
    )
    sol = run(obs, stream, dt=1e-3, saveat=SaveAt(outputs=False), throw=False)
    assert sol.result == RESULTS.nonfinite_measurement and int(sol.failed_sample) == 20


def test_static_points_stream_reject():
    sc = nath.scenario(0.05)
    est = nath.initial_estimator(sc)
    n, m = sc.p_s.shape[1], sc.p_c.shape[1]
    p_s, p_c = np.asarray(sc.p_s).copy(), np.asarray(sc.p_c).copy()
    per = np.zeros((len(sc.ts), n + m), bool)
    per[10, 1] = per[11, n] = True  # an unknown and a known feature
    bad_s, bad_c = p_s.copy(), p_c.copy()
    bad_s[10, 1] += 25.0
    bad_c[11, 0] += 25.0
    miss_s, miss_c = p_s.copy(), p_c.copy()
    miss_s[10, 1] = np.nan
    miss_c[11, 0] = np.nan
    args = (sc.ts, sc.R_b, sc.x_b)
    told = _final(est, static_points_stream(*args, miss_s, miss_c, sc.omega_c))
    _equal(_final(est, static_points_stream(*args, bad_s, bad_c, sc.omega_c, reject=per)), told)
    whole = np.zeros(len(sc.ts), bool)
    whole[30] = True
    miss_s[30], miss_c[30] = np.nan, np.nan
    bad_s[30] += 25.0
    per[30] = True
    _equal(
        _final(est, static_points_stream(*args, bad_s, bad_c, sc.omega_c, reject=per)),
        _final(est, static_points_stream(*args, miss_s, miss_c, sc.omega_c)),
    )


def test_present_only_streams_reject(no_jaxtyping):
    from visjax.baselines import ekf_stream
    from visjax.papers import hamel, spica

    sc = spica.point_depth_scene(0.05, 1000.0)
    reject = np.zeros(len(sc.ts), bool)
    reject[[5, 9]] = True
    stream = spica.point_depth_stream(sc.ts, sc.pixels, sc.twists, sc.K, reject=reject)
    np.testing.assert_array_equal(stream.present, ~reject)
    group = np.zeros((len(sc.ts), 3, 3))
    stream = hamel.homography_stream(sc.ts, sc.pixels, group, sc.K, reject=reject)
    np.testing.assert_array_equal(stream.present, ~reject)
    zs = np.ones((len(sc.ts), 4))
    stream = ekf_stream(sc.ts, zs, reject=reject)
    np.testing.assert_array_equal(np.asarray(stream.ys.seen).any(axis=1), ~reject)
    per = np.zeros(zs.shape, bool)
    per[3, 1] = True
    stream = ekf_stream(sc.ts, zs, reject=per)
    assert not bool(stream.ys.seen[3, 1]) and int(np.asarray(stream.ys.seen).sum()) == zs.size - 1
    with pytest.raises(ValueError, match="first sample starts the run"):
        spica.point_depth_stream(sc.ts, sc.pixels, sc.twists, sc.K, reject=~reject)
