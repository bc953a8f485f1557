"""Depth from one known length (Chitrakaran et al., the premise before eq. (56)): exact on
random irregular coplanar feature sets, whatever the object origin; under jit, vmap, grad."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax.estimators import depth_from_feature_length, fixed_camera, velocity_stream
from visjax.geometry import intrinsic_matrix, project
from visjax.papers import chitrakaran


def _scene(rng, n=5):
    """A random plane in front of a random camera, `n` irregular points on it."""
    normal = np.array([*rng.uniform(-0.5, 0.5, 2), 1.0])  # facing the camera, tilted
    normal /= np.linalg.norm(normal)
    d = rng.uniform(0.5, 5.0)
    a, b = np.linalg.svd(normal[None])[2][1:]  # two directions in the plane
    uv = rng.uniform(-0.3, 0.3, (n, 2)) * d
    points = d * normal + uv[:, :1] * a + uv[:, 1:] * b  # n . X = d for all
    A = np.asarray(
        intrinsic_matrix(*rng.uniform([400, 400, 200, 150, -5], [1500, 1500, 500, 400, 5]))
    )
    return points, A, normal


def test_exact_on_random_irregular_coplanar_sets():
    rng = np.random.default_rng(3)
    for _ in range(50):
        points, A, normal = _scene(rng)
        assert np.all(points[:, 2] > 0)
        p = np.asarray(project(points, A).pixels)
        i, j = rng.choice(5, 2, replace=False)
        L = np.linalg.norm(points[i] - points[j])
        z1 = depth_from_feature_length(p, A, normal, (int(i), int(j), L))
        np.testing.assert_allclose(z1, points[0, 2], rtol=1e-9)
        # the sign of the normal does not matter
        np.testing.assert_allclose(
            depth_from_feature_length(p, A, -normal, (int(i), int(j), L)), points[0, 2], rtol=1e-9
        )


def test_jit_vmap_grad():
    rng = np.random.default_rng(4)
    scenes = [_scene(rng) for _ in range(8)]
    P = np.stack([np.asarray(project(s[0], s[1]).pixels) for s in scenes])
    A = np.stack([s[1] for s in scenes])
    N = np.stack([s[2] for s in scenes])
    L = np.array([np.linalg.norm(s[0][1] - s[0][3]) for s in scenes])
    f = jax.jit(jax.vmap(lambda p, a, n, l: depth_from_feature_length(p, a, n, (1, 3, l))))
    np.testing.assert_allclose(f(P, A, N, L), [s[0][0, 2] for s in scenes], rtol=1e-9)
    # z1* is linear in L: dz1*/dL = z1*/L exactly
    g = jax.grad(lambda l: depth_from_feature_length(P[0], A[0], N[0], (1, 3, l)))(L[0])
    np.testing.assert_allclose(g, scenes[0][0][0, 2] / L[0], rtol=1e-9)
    # L <= 0: z1* <= 0 raises, also under vmap
    with pytest.raises((RuntimeError, ValueError), match="z1\\* <= 0"):
        f(P, A, N, -L)


def test_bad_known_length(no_jaxtyping):
    rng = np.random.default_rng(5)
    points, A, normal = _scene(rng)
    p = np.array(project(points, A).pixels)
    with pytest.raises(ValueError, match="two different features"):
        depth_from_feature_length(p, A, normal, (2, 2, 1.0))
    with pytest.raises(ValueError, match="two different features"):
        depth_from_feature_length(p, A, normal, (0, 7, 1.0))
    with pytest.raises(ValueError, match=r"\(i, j, L\)"):
        depth_from_feature_length(p, A, normal, 0.3)
    p[3] = p[1]
    with pytest.raises(RuntimeError, match="coincide"):
        depth_from_feature_length(p, A, normal, (1, 3, 0.2))
    with pytest.raises(RuntimeError, match="z1"):
        depth_from_feature_length(p, A, normal, (0, 1, -0.2))


def test_the_stream_uses_the_known_length():
    """On the section-6 scenario, a length between two features (not through the object
    origin) gives the true z1* and the same stream as the true constants."""
    sc = chitrakaran.section6_scenario(0.3, 1000.0)
    s = np.asarray(sc.s)
    L = float(np.linalg.norm(s[1] - s[2]))
    camera = fixed_camera(
        sc.pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, known_length=(1, 2, L)
    )
    stream = velocity_stream(sc.ts, sc.pixels, camera)
    z1 = camera.z1_star
    np.testing.assert_allclose(z1, sc.z1_star, rtol=1e-9)
    camera = fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star)
    ref = velocity_stream(sc.ts, sc.pixels, camera)
    np.testing.assert_allclose(stream.measured().ys.J, ref.measured().ys.J, rtol=1e-8, atol=1e-10)
    assert jnp.shape(z1) == ()


@pytest.mark.slow
def test_any_reference_image(no_jaxtyping):
    """The reference image given apart from the frames: the run can start anywhere, and
    the measurements are those of the full stream from there on (no spike at the start)."""
    sc = chitrakaran.section6_scenario(0.2, 1000.0)
    kw = dict(n_star=sc.n_star, z1_star=sc.z1_star)
    full = velocity_stream(
        sc.ts, sc.pixels, fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0], **kw)
    )
    camera = fixed_camera(
        sc.pixels[120:], sc.A, sc.R_star, sc.s[0], reference_pixels=sc.pixels[0], **kw
    )
    late = velocity_stream(sc.ts[120:], sc.pixels[120:], camera)
    late, full = late.measured().ys, full.measured().ys
    np.testing.assert_allclose(late.e, full.e[120:], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(late.J_inv, full.J_inv[120:], rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="reference_pixels"):
        fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0], reference_pixels=sc.pixels[0, :3], **kw)


def test_velocity_in_the_object_frame():
    """Remark 6: `v_object` is the estimate expressed in the object frame, R^T v with the
    true orientation R (noise-free, R = R_bar R* to 1e-9), and tracks R^T v_true."""
    from visjax.estimators import SaveAt, VelocityEstimator, run

    sc = chitrakaran.section6_scenario(0.3, 1000.0)
    camera = fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star)
    stream = velocity_stream(sc.ts, sc.pixels, camera)
    np.testing.assert_allclose(stream.measured().ys.R, sc.R, atol=1e-9)
    sol = run(
        VelocityEstimator(K=chitrakaran.K_EQ63, rho=chitrakaran.RHO_EQ63),
        stream,
        saveat=SaveAt(outputs=True),
    )
    R = np.asarray(sc.R)
    v, v_obj = np.asarray(sol.outputs.v_hat), np.asarray(sol.outputs.v_object)
    expected = np.concatenate(
        [np.einsum("nji,nj->ni", R, v[:, :3]), np.einsum("nji,nj->ni", R, v[:, 3:])], 1
    )
    np.testing.assert_allclose(v_obj, expected, atol=1e-9)
    # and against the truth, as v_hat is against its truth
    true = np.asarray(sc.velocity)
    true_obj = np.concatenate(
        [np.einsum("nji,nj->ni", R, true[:, :3]), np.einsum("nji,nj->ni", R, true[:, 3:])], 1
    )
    err_cam = np.max(np.abs(v - true)[150:])
    err_obj = np.max(np.abs(v_obj - true_obj)[150:])
    np.testing.assert_allclose(err_obj, err_cam, rtol=0.5)


@pytest.mark.slow
def test_a_failed_depth_recovery_is_a_result_code_with_throw_false():
    """0.1 px of noise on 2 s of frames: the plane normal measured from them is ~1.7 deg off,
    so the default depth path (the object origin's pixel) breaks its premise check. It
    raises by default; with `throw=False` the camera's result is `depth_recovery_failed`,
    every frame's result says so and `run` stops at the first sample, also inside `vmap`;
    the known length between two features recovers z1* from the same frames."""
    from visjax import RESULTS
    from visjax.estimators import SaveAt, VelocityEstimator, run

    sc = chitrakaran.section6_scenario(2.0, 1000.0)
    keys = jax.vmap(jax.random.key)(jnp.arange(2))
    noisy = sc.pixels + 0.1 * jax.random.normal(keys[0], sc.pixels.shape)
    args = (noisy, sc.A, sc.R_star, sc.s[0])
    with pytest.raises(RuntimeError, match="R\\* s1 = d\\* w does not hold"):
        fixed_camera(*args)
    camera = fixed_camera(*args, throw=False)
    stream = velocity_stream(sc.ts, noisy, camera, throw=False)
    assert camera.result == RESULTS.depth_recovery_failed
    assert stream.measurement(5).result == RESULTS.depth_recovery_failed
    assert np.all(np.isnan(np.asarray(stream.measurement(5).J)))
    est = VelocityEstimator(K=chitrakaran.K_EQ63, rho=chitrakaran.RHO_EQ63)
    sol = run(est, stream, saveat=SaveAt(outputs=False), throw=False)
    assert sol.result == RESULTS.nonfinite_measurement and int(sol.failed_sample) == 0

    def one(key):
        pixels = sc.pixels + 0.1 * jax.random.normal(key, sc.pixels.shape)
        camera = fixed_camera(pixels, sc.A, sc.R_star, sc.s[0], throw=False)
        s = velocity_stream(sc.ts, pixels, camera, throw=False)
        z = camera.result._value
        return run(est, s, saveat=SaveAt(outputs=False), throw=False).result._value, z

    codes, camera_codes = jax.vmap(one)(keys)
    assert np.all(np.asarray(camera_codes) == RESULTS.depth_recovery_failed._value)
    assert np.all(np.asarray(codes) == RESULTS.nonfinite_measurement._value)
    # the paper's premise, a known length (features 1 and 3: the square's diagonal)
    length = float(jnp.linalg.norm(sc.s[0] - sc.s[2]))
    z1 = fixed_camera(*args, known_length=(0, 2, length)).z1_star
    assert abs(float(z1) - float(sc.z1_star)) < 0.05
