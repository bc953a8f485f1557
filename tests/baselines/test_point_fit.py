"""The moving-point baselines for Jang's thesis: windowed triangulation from the known
camera motion (exact for a static point and for a point at constant velocity), the
inverse-depth EKF, causality, result codes under vmap, gradients."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax._results import RESULTS
from visjax.baselines import moving_point_ekf, triangulate_point, triangulation_residuals
from visjax.estimators import moving_point_stream
from visjax.sim import moving_camera_point

RATE = 30.0
TS = jnp.arange(150.0) / RATE
KC = jnp.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
triangulate = eqx.filter_jit(triangulate_point)
ekf = eqx.filter_jit(moving_point_ekf)


def held(f):
    """The camera velocity held between the 30 Hz samples, as the baselines assume."""
    return lambda t: f(jnp.floor(t * RATE + 1e-9) / RATE)


def scene(rotation, v_p, stop=jnp.inf):
    def u(t):
        v = jnp.array([0.1 + 0.1 * jnp.sin(2 * t), -0.05 + 0.08 * jnp.cos(1.5 * t), 0.02])
        return jnp.concatenate([jnp.where(t < stop, v, 0.0), rotation])

    x = moving_camera_point(held(u), lambda t: v_p, jnp.array([0.1, -0.05, 1 / 1.5]), TS)
    pixels = x[:, :2] @ KC[:2, :2].T + KC[:2, 2][None]
    stream = moving_point_stream(TS, pixels, jax.vmap(held(u))(TS), KC)
    position = jnp.stack([x[:, 0] / x[:, 2], x[:, 1] / x[:, 2], 1 / x[:, 2]], 1)
    return stream, np.asarray(position)


@pytest.fixture(scope="module")
def static():
    return scene(jnp.array([0.05, -0.03, 0.1]), jnp.zeros(3))


@pytest.fixture(scope="module")
def moving():
    return scene(jnp.zeros(3), jnp.array([0.02, 0.01, 0.0]))


def test_triangulation_exact_for_the_models_it_assumes(static, moving):
    for (stream, position), order in ((static, 0), (moving, 1)):
        sol = triangulate(stream, window=30, order=order)
        assert sol.result == RESULTS.successful
        err = np.abs(np.asarray(sol.outputs.position) - position)
        started = np.isfinite(err[:, 0])
        assert started[30:].all()  # the warm-up is shorter than a window
        np.testing.assert_array_less(err[30:], 1e-7)  # the truth's integration: ~1e-9
    # a moving point under the static model is not exact
    wrong = triangulate(moving[0], window=30, order=0)
    assert np.nanmax(np.abs(np.asarray(wrong.outputs.position) - moving[1])[30:]) > 1e-3


def test_causal_and_a_camera_that_stops_translating_is_flagged(static):
    stream, _ = static
    sol = triangulate(stream, window=30)
    later = jnp.arange(len(TS))[:, None] > 100
    moved = eqx.tree_at(lambda s: s.ys.y, stream, jnp.where(later, stream.ys.y + 0.01, stream.ys.y))
    other = triangulate(moved, window=30)
    np.testing.assert_array_equal(other.outputs.position[:101], sol.outputs.position[:101])
    # the camera only turns after 2 s (sample 60): a window of 30 frames after it does not
    # determine the depth
    still, _ = scene(jnp.array([0.05, -0.03, 0.1]), jnp.zeros(3), stop=2.0)
    bad = triangulate(still, window=30, throw=False)
    assert bad.result == RESULTS.singular and 60 < int(bad.failed_sample) <= 90


def test_ekf_converges_static_and_moving(static, moving):
    stream, position = static
    sol = ekf(stream, r_norm=1e-4, depth0=1.0, sigma_depth0=0.5, q_velocity=0.0, substeps=10)
    err = np.abs(np.asarray(sol.outputs.position) - position)
    assert err[0, 2] > 0.4 and err[-1].max() < 1e-6  # from a 50 cm depth error
    stream, position = moving
    sol = ekf(
        stream,
        r_norm=1e-4,
        depth0=1.0,
        sigma_depth0=0.5,
        q_velocity=0.0,
        sigma_velocity0=0.05,
        substeps=10,
    )
    err = np.abs(np.asarray(sol.outputs.position) - position)
    assert err[-1].max() < 1e-3, err[-1]


def test_vmap_over_noise_seeds_flags_the_bad_seed(static):
    stream, _ = static
    keys = jax.random.split(jax.random.key(1), 3)
    ys = jax.vmap(lambda k: stream.ys.y + 1e-4 * jax.random.normal(k, stream.ys.y.shape))(keys)
    ys = ys.at[2, 80, 0].set(jnp.inf)

    def both(y):
        s = eqx.tree_at(lambda s: s.ys.y, stream, y)
        return (
            triangulate_point(s, window=30, throw=False),
            moving_point_ekf(
                s, r_norm=1e-4, depth0=1.0, sigma_depth0=0.5, q_velocity=0.0, throw=False
            ),
        )

    tri, filt = eqx.filter_jit(jax.vmap(both))(ys)
    for sol in (tri, filt):
        codes = np.asarray(sol.result._value)
        assert codes[0] == codes[1] == RESULTS.successful._value
        assert codes[2] == RESULTS.nonfinite_measurement._value
        assert int(sol.failed_sample[2]) == 80
    one = triangulate(eqx.tree_at(lambda s: s.ys.y, stream, ys[1]), window=30)
    np.testing.assert_allclose(tri.outputs.position[1], one.outputs.position, rtol=1e-9)


def test_gradient_of_the_loss_with_respect_to_the_measurements(static):
    stream, position = static

    def loss(y):
        s = eqx.tree_at(lambda s: s.ys.y, stream, y)
        return jnp.sum(triangulation_residuals(position[100] + 0.01, s, 100, 30) ** 2)

    g = jax.jit(jax.grad(loss))(stream.ys.y)
    r = triangulation_residuals(position[100] + 0.01, stream, 100, 30)
    np.testing.assert_allclose(g[71:101], 2 * r, rtol=1e-12)
    assert np.all(g[:71] == 0) and np.all(np.isfinite(g))


def test_bad_arguments(static, no_jaxtyping):
    stream, _ = static
    with pytest.raises(ValueError, match="window"):
        triangulate_point(stream, window=1)
    with pytest.raises(ValueError, match="order"):
        triangulate_point(stream, window=10, order=3)
    with pytest.raises(ValueError, match="stream"):
        moving_point_ekf(None, r_norm=1e-4, depth0=1.0, sigma_depth0=0.5, q_velocity=0.0)


def test_the_warm_up_lasts_until_the_window_is_wide_enough(static):
    """`min_baseline`: the warm-up ends at the first window that determines the point with
    its camera centres at least that far apart; after it the estimates are those without
    the test (the fits are the same), and a wider requirement starts later. With pixel
    noise, a window of a few frames gives a depth of either sign: a lucky one ending the
    warm-up makes the next one a failure (`behind_camera`), which the test prevents."""
    stream, _ = static
    noisy = eqx.tree_at(
        lambda s: s.ys.y,
        stream,
        stream.ys.y + 1e-2 * jax.random.normal(jax.random.key(3), stream.ys.y.shape),
    )  # 8 px at this focal length: windows of a few frames give either sign
    starts, runs = [], {}
    for b in (0.0, 0.02, 0.05):
        sol = triangulate(noisy, window=30, min_baseline=b, throw=False)
        p = np.asarray(sol.outputs.position)
        starts.append(int(np.argmax(np.isfinite(p[:, 0]))))
        runs[b] = (sol, p)
    assert starts[0] < starts[1] < starts[2]
    assert runs[0.0][0].result == RESULTS.behind_camera  # started by a lucky narrow window
    assert runs[0.02][0].result == runs[0.05][0].result == RESULTS.successful
    plain, late = runs[0.0][1], runs[0.05][1]
    np.testing.assert_array_equal(late[starts[2] :], plain[starts[2] :])
    assert np.isnan(late[: starts[2]]).all()
    never = triangulate(noisy, window=30, min_baseline=1e3)
    assert np.isnan(np.asarray(never.outputs.position)).all()
