"""Scene builders: trajectories against independent solutions, rigs against eq. (5) of
Nath et al., the field of view, feature sets and the sampler."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax.geometry import feature_in_camera, project, so3_exp
from visjax.sim import (
    CameraRig,
    Sampler,
    box_features,
    constant_twist_trajectory,
    integrate_twist,
    intrinsics,
    object_points,
    planar_features,
    points_in_camera,
    sinusoidal_trajectory,
    spline_trajectory,
    view,
)

TS = jnp.linspace(0.0, 2.0, 41)
R0 = so3_exp(jnp.array([0.3, -0.2, 0.1]))
X0 = jnp.array([0.1, -0.2, 2.0])


def _rotation_rate(R, dt):
    """[w]_x = dR R^T by central differences of the sampled rotations (interior samples)."""
    dR = (R[2:] - R[:-2]) / (2 * dt)
    W = dR @ np.swapaxes(R[1:-1], -1, -2)
    return (
        np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], 1) / 2
    )


def test_constant_twist_closed_form_matches_the_ode():
    twist = jnp.array([0.1, -0.05, 0.2, 0.3, -0.1, 0.25])
    a = constant_twist_trajectory(twist, X0, R0, TS)
    b = integrate_twist(lambda t: twist + 0.0 * t, X0, R0, TS)
    np.testing.assert_allclose(a.R, b.R, atol=1e-10)
    np.testing.assert_allclose(a.x, b.x, atol=1e-10)


def test_sinusoidal_twist_is_the_derivative_of_the_pose():
    a = jnp.array([0.1, 0.2, -0.1, 0.3, -0.2, 0.4])
    f = jnp.array([0.5, 0.3, 0.7, 0.2, 0.4, 0.6])
    ts = jnp.linspace(0.0, 2.0, 2001)
    tr = sinusoidal_trajectory(a, f, X0, R0, ts, phase=jnp.full(6, 0.3), offset=jnp.full(6, 0.05))
    expected = a[None] * jnp.sin(2 * jnp.pi * f[None] * ts[:, None] + 0.3) + 0.05
    np.testing.assert_allclose(tr.twist, expected, atol=1e-14)
    dt = float(ts[1] - ts[0])
    np.testing.assert_allclose((tr.x[2:] - tr.x[:-2]) / (2 * dt), tr.twist[1:-1, :3], atol=1e-6)
    np.testing.assert_allclose(_rotation_rate(np.asarray(tr.R), dt), tr.twist[1:-1, 3:], atol=1e-6)


@pytest.mark.slow
def test_spline_through_poses(no_jaxtyping):
    knots = jnp.array([0.0, 0.7, 1.3, 2.0])
    R_k = jnp.stack([so3_exp(jnp.array([0.1 * k, -0.2 * k, 0.15 * k * k])) for k in range(4)])
    x_k = jnp.array([[0.0, 0.0, 2.0], [0.2, -0.1, 2.1], [0.1, 0.3, 1.8], [-0.2, 0.1, 2.2]])
    at_knots = spline_trajectory(knots, R_k, x_k, knots)
    np.testing.assert_allclose(at_knots.R, R_k, atol=1e-12)
    np.testing.assert_allclose(at_knots.x, x_k, atol=1e-12)
    ts = jnp.linspace(0.0, 2.0, 4001)
    tr = spline_trajectory(knots, R_k, x_k, ts)
    dt = float(ts[1] - ts[0])
    np.testing.assert_allclose((tr.x[2:] - tr.x[:-2]) / (2 * dt), tr.twist[1:-1, :3], atol=1e-5)
    np.testing.assert_allclose(_rotation_rate(np.asarray(tr.R), dt), tr.twist[1:-1, 3:], atol=1e-5)
    # velocity continuous across the interior knots (C1 at least; the spline is C2)
    j = int(np.searchsorted(np.asarray(ts), 0.7))
    np.testing.assert_allclose(tr.twist[j - 1], tr.twist[j + 1], atol=5e-3)
    with pytest.raises(ValueError, match="increasing"):
        spline_trajectory(knots[::-1], R_k, x_k, ts)
    with pytest.raises(ValueError, match="R_knots"):
        spline_trajectory(knots, R_k[:3], x_k, ts)


def test_rig_follows_eq5_and_the_field_of_view():
    A = intrinsics(900.0, cx=524.0, cy=371.0, skew_angle_deg=91.5)
    R_c = so3_exp(jnp.array([0.2, 0.1, -0.3]))
    x_c = jnp.array([0.05, -0.02, 0.1])
    rig = CameraRig(A=A, R_c=R_c, x_c=x_c, image_size=(1024, 768))
    body = sinusoidal_trajectory(jnp.full(6, 0.1), jnp.full(6, 0.3), X0, R0, TS)
    w = box_features(5, [-1.0, -1.0, 2.0], [1.0, 1.0, 3.0], seed=1)
    P = points_in_camera(rig, w, body)
    ref = jax.vmap(lambda Rb, xb: jax.vmap(lambda q: feature_in_camera(q, Rb, xb, R_c, x_c))(w))(
        body.R, body.x
    )
    np.testing.assert_allclose(P, ref, atol=1e-13)
    # view: behind the camera and outside the image are NaN; the rest is project()
    pts = jnp.array([[0.0, 0.0, 2.0], [0.0, 0.0, -2.0], [5.0, 0.0, 1.0], [0.1, -0.1, 1.5]])
    p = view(rig, pts)
    p = np.asarray(p)
    assert np.isnan(p[1]).all() and np.isnan(p[2]).all()
    np.testing.assert_allclose(p[[0, 3]], project(pts[jnp.array([0, 3])], A).pixels, atol=1e-12)
    assert np.isfinite(view(CameraRig(A=A, image_size=None), pts[2])).all()
    # the skew angle enters as eq. (4) of Nath et al.
    np.testing.assert_allclose(A[0, 1], 900.0 / np.tan(np.deg2rad(91.5)), rtol=1e-12)


def test_rig_errors(no_jaxtyping):
    A = intrinsics(900.0)
    with pytest.raises(ValueError, match="image_size"):
        CameraRig(A=A, image_size=(640,))
    with pytest.raises(ValueError, match="x_c"):
        CameraRig(A=A, x_c=jnp.zeros(2))
    with pytest.raises(ValueError, match="skew angle"):
        intrinsics(900.0, skew_angle_deg=180.0)


def test_feature_sets():
    s = np.asarray(planar_features(7, size=0.4, normal=(0.2, -0.1, 1.0), offset=0.05, seed=3))
    nu = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
    np.testing.assert_allclose(s @ nu, 0.05, atol=1e-14)  # coplanar, origin off the plane
    d = np.linalg.norm(s[:, None] - s[None], axis=-1) + np.eye(7)
    assert d.min() > 0.04
    b = np.asarray(box_features(50, [0, 0, 1], [1, 2, 3], seed=0))
    assert np.all(b >= [0, 0, 1]) and np.all(b <= [1, 2, 3])
    assert np.linalg.matrix_rank(b - b.mean(0)) == 3
    with pytest.raises(ValueError, match="normal"):
        planar_features(4, size=1.0, normal=(0, 0, 0))


def test_sampler_rate_jitter_noise_dropouts():
    s = Sampler(rate_hz=50.0, jitter_s=0.004, noise_px=0.5, dropout=0.1)
    ts = np.asarray(s.times(20.0, jax.random.key(0)))
    assert ts.shape == (1000,) and ts[0] == 0.0 and np.all(np.diff(ts) > 0)
    dev = ts - np.arange(1000) / 50.0
    assert np.abs(dev).max() <= 0.004 and np.abs(dev).max() > 0.003
    rig = CameraRig(A=intrinsics(800.0), image_size=None)
    P = jnp.broadcast_to(jnp.array([[0.1, 0.05, 2.0], [-0.1, 0.0, 1.5]]), (1000, 2, 3))
    p, seen = s.record(rig, P, jax.random.key(1))
    assert bool(seen[0].all())
    frac = 1.0 - float(jnp.mean(seen))
    assert 0.08 < frac < 0.12
    clean = view(rig, P)
    err = np.asarray(p - clean)[np.asarray(seen)]
    assert 0.45 < err.std() < 0.55 and abs(err.mean()) < 0.05
    assert np.isnan(np.asarray(p)[~np.asarray(seen)]).all()
    for bad in (
        dict(rate_hz=0.0),
        dict(rate_hz=10.0, jitter_s=0.06),
        dict(rate_hz=10.0, dropout=1.0),
    ):
        with pytest.raises(ValueError):
            Sampler(**bad)
    with pytest.raises(ValueError, match="key"):
        s.record(rig, P)


def test_jit_vmap_grad():
    rig = CameraRig(A=intrinsics(800.0), image_size=None)
    s = jnp.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.02]])

    def mean_u(amp):
        body = constant_twist_trajectory(jnp.array([amp, 0, 0, 0, 0, amp]), X0, jnp.eye(3), TS)
        return jnp.mean(view(rig, points_in_camera(rig, object_points(body, s)))[..., 0])

    g = jax.jit(jax.grad(mean_u))(0.2)
    np.testing.assert_allclose(g, central_difference(mean_u, 0.2, 1e-5), rtol=1e-7)
    amps = jnp.array([0.1, 0.2, 0.3])
    np.testing.assert_allclose(jax.vmap(mean_u)(amps), [mean_u(a) for a in amps], rtol=1e-12)
