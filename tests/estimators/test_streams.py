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
