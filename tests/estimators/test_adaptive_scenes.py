"""The uncalibrated-camera structure estimator of Nath, Dawson, Tatlicioglu beyond its own
scenario (issue 10, item 5): built from nominal values only, the camera recovered from its
estimate (the paper's footnote 3), features that drop out of view, gains derived from the
scene's scale, and the tilted scene of `benchmarks/scenes_euclidean.py`
(`visjax.sim.tilted_platform_scene`, its parameters fixed in `visjax.sim`'s catalogue)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.helpers import central_difference
from visjax import RESULTS
from visjax.estimators import (
    SaveAt,
    StaticPointsEstimator,
    platform_measurements,
    run,
    static_points_stream,
)
from visjax.geometry import camera_parameters
from visjax.papers import nath
from visjax.sim import tilted_platform_scene

SAVE = SaveAt(every=1000)  # one compiled run for every project-scenario test below


def _errors(omega_s, truth):
    return np.linalg.norm(np.asarray(omega_s) - np.asarray(truth), axis=-1)


def _angle_deg(R):
    """The rotation angle of `R` (..., 3, 3), degrees."""
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _true_theta(est, A, R_c, x_c):
    """The camera parameters of the truth in the estimator's normalised pixels."""
    t1, t2 = camera_parameters(est.N @ A, R_c, x_c)
    return jnp.concatenate([t1, t2])


@pytest.fixture(scope="module")
def project():
    """The project's scenario, 10 s at 1 kHz, and its estimator from the nominal camera."""
    sc = nath.scenario(10.0)
    stream = nath.stream(sc)
    A0, R0, x0 = nath.nominal_camera()
    return sc, StaticPointsEstimator.from_nominal(stream, A0, R0, x0), stream


@pytest.fixture(scope="module")
def project_run(project):
    _, est, stream = project
    return run(est, stream, saveat=SAVE)


# --- from nominal values only -------------------------------------------------------------


def test_from_nominal_never_reads_the_truth(project):
    """The scenario's truth replaced by NaN: the same estimator, every leaf finite; theta_c0
    is the nominal camera (its recovered camera is the nominal one, 1e-12), and each unknown
    feature starts on its nominal ray at the known features' median depth."""
    sc, est, stream = project
    blind = eqx.tree_at(
        lambda s: (s.omega_s, s.A, s.R_c, s.x_c, s.theta_c1, s.theta_c2),
        sc,
        replace_fn=lambda x: jnp.full_like(x, jnp.nan),
    )
    np.testing.assert_array_equal(nath.initial_estimator(sc).eta0, est.eta0)
    est_blind = nath.initial_estimator(blind)
    for a, b in zip(jax.tree_util.tree_leaves(est), jax.tree_util.tree_leaves(est_blind)):
        assert np.all(np.isfinite(b))
        np.testing.assert_array_equal(a, b)
    A0, R0, x0 = nath.nominal_camera()
    A, R_c, x_c = est.camera(est.init(jax.tree_util.tree_map(lambda x: x[0], stream.ys)))
    np.testing.assert_allclose(A, A0, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(R_c, R0, atol=1e-12)
    np.testing.assert_allclose(x_c, x0, atol=1e-12)
    # the guesses: projected by the nominal camera at sample 0 onto the measured pixels
    q = (est.theta_s0[:, :3] - sc.x_b[0][None, :]) @ sc.R_b[0]  # platform: R_b^T (w - x_b)
    m = (q - x0[None, :]) @ R0  # camera frame (eq. (5))
    p = m @ A0.T
    np.testing.assert_allclose(p[:, :2] / p[:, 2:], sc.p_s[0], atol=1e-8)
    depth_c = (sc.omega_c - sc.x_b[0][None, :]) @ sc.R_b[0] @ R0[:, 2] - x0 @ R0[:, 2]
    np.testing.assert_allclose(m[:, 2], np.median(depth_c), rtol=1e-12)


def test_scale_derived_gains(project):
    """The rule of `from_nominal`: alpha = 20 z_bar, the fastest initial rate h r0 = 1 for
    both laws, eta1 = eta0 / 100, the largest D entry 1, margins 0.2 z_min; an override of
    alpha_c is followed by eta0 (their product is fixed); a mis-specified camera gives other
    gains."""
    sc, est, stream = project
    y0 = jax.tree_util.tree_map(lambda x: x[0], stream.ys)
    _, W_c, _, W_bar, _, depth_c, depth_s = est._signals(est.init(y0), y0)
    z = np.asarray(depth_c)
    np.testing.assert_allclose(est.alpha_c, 20.0 * np.median(z), rtol=1e-12)
    np.testing.assert_allclose(est.alpha, est.alpha_c, rtol=1e-12)
    np.testing.assert_allclose(est.eps_c, 0.2 * z.min(), rtol=1e-12)
    np.testing.assert_allclose(est.eta1, est.eta0 / 100.0, rtol=1e-12)
    np.testing.assert_allclose(np.max(est.D), 1.0, rtol=1e-12)
    h = 1e-3
    WD = np.asarray(W_c) * np.asarray(est.D)[None, :]
    r_c = float(est.alpha_c * est.eta0) * np.linalg.eigvalsh(WD.T @ (WD / np.repeat(z, 3)[:, None]))
    np.testing.assert_allclose(h * r_c[-1], 1.0, rtol=1e-9)
    info = np.einsum("nki,nkj->nij", W_bar, W_bar) / np.asarray(depth_s)[:, None, None]
    r_s = float(est.alpha * est.gamma_s0) * np.linalg.eigvalsh(info)[:, -1].max()
    np.testing.assert_allclose(h * r_s, 1.0, rtol=1e-9)
    assert float(est.max_stable_dt(y0)) >= h
    faster = nath.initial_estimator(sc, {"alpha_c": 2.0 * float(est.alpha_c)})
    np.testing.assert_allclose(faster.eta0, est.eta0 / 2.0, rtol=1e-12)
    np.testing.assert_allclose(faster.gamma_s0, est.gamma_s0, rtol=1e-12)
    A0, R0, x0 = nath.nominal_camera()
    other = StaticPointsEstimator.from_nominal(stream, A0, R0, x0 + 0.5)
    assert abs(float(other.alpha_c) / float(est.alpha_c) - 1.0) > 0.05


def test_from_nominal_refuses_wrong_arguments(project, no_jaxtyping):
    sc, est, stream = project
    A0, R0, x0 = nath.nominal_camera()
    with pytest.raises(ValueError, match="`A_nominal`"):
        StaticPointsEstimator.from_nominal(stream, A0[:2], R0, x0)
    with pytest.raises(ValueError, match="`x_c_nominal`"):
        StaticPointsEstimator.from_nominal(stream, A0, R0, x0[:2])
    with pytest.raises(ValueError, match="`omega_s_guess`"):
        StaticPointsEstimator.from_nominal(stream, A0, R0, x0, omega_s_guess=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="`depth_guess`"):
        StaticPointsEstimator.from_nominal(stream, A0, R0, x0, depth_guess=np.ones(7))
    with pytest.raises(ValueError, match="unknown names"):
        StaticPointsEstimator.from_nominal(stream, A0, R0, x0, gains={"alpha_s": 1.0})
    with pytest.raises(ValueError, match="`stream`"):
        StaticPointsEstimator.from_nominal(stream.ys, A0, R0, x0)
    with pytest.raises(ValueError, match="`N`"):
        StaticPointsEstimator(**{**vars(est), "N": np.eye(2)})
    skewed = eqx.tree_at(lambda e: e.N, est, est.N.at[2, 0].set(1e-3))
    with pytest.raises(ValueError, match="pixel normalisation `N`"):
        run(skewed, stream)


# --- the recovered camera (footnote 3) ------------------------------------------------------


def test_recovered_camera_exact_at_the_truth(project):
    """theta_c = the truth (at any scale): A, R_c, x_c back to 1e-9."""
    sc, est, stream = project
    y0 = jax.tree_util.tree_map(lambda x: x[0], stream.ys)
    theta = _true_theta(est, sc.A, sc.R_c, sc.x_c)
    for scale in (1.0, 3.7, 0.02):
        state = eqx.tree_at(lambda s: s.theta_c, est.init(y0), scale * theta)
        out = est.output(0.0, state, y0)
        np.testing.assert_allclose(out.A, sc.A, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(out.R_c, sc.R_c, atol=1e-12)
        np.testing.assert_allclose(out.x_c, sc.x_c, atol=1e-12)


def test_recovered_camera_approaches_the_truth(project, project_run):
    """Over 10 s of the project's scenario the recovered camera's errors shrink from the
    nominal camera's: A from 80 px to below 20 (measured 12 at 9 s), R_c from 3 deg to
    below 1 (0.54), x_c from 3.5 cm to below 2.5 (1.5-2)."""
    sc, _, stream = project
    out = project_run.outputs
    A_err = np.abs(np.asarray(out.A) - np.asarray(sc.A)[None]).max(axis=(1, 2))
    R_err = _angle_deg(np.asarray(out.R_c) @ np.asarray(sc.R_c).T[None])
    x_err = np.linalg.norm(np.asarray(out.x_c) - np.asarray(sc.x_c)[None], axis=-1)
    assert A_err[0] > 50 and R_err[0] > 2.5 and x_err[0] > 0.03
    assert A_err[-1] < 20 and R_err[-1] < 1.0 and x_err[-1] < 0.025
    assert A_err[-1] < 0.25 * A_err[0] and R_err[-1] < 0.2 * R_err[0]


# --- dropouts ---------------------------------------------------------------------------------


def test_nan_pixels_become_a_mask(project):
    """A NaN pixel: a 0/1 flag and a zero pixel, every leaf finite. A NaN platform pose is
    still a non-finite measurement that stops the run."""
    sc, est, stream = project
    p_s = np.asarray(sc.p_s).copy()
    p_c = np.asarray(sc.p_c).copy()
    p_s[3, 1, 0] = np.nan
    p_c[5, 2, 1] = np.nan
    y = platform_measurements(sc.R_b[:10], sc.x_b[:10], p_s[:10], p_c[:10], sc.omega_c)
    assert float(y.visible_s[3, 1]) == 0.0 and float(np.sum(y.visible_s)) == 10 * 4 - 1
    assert float(y.visible_c[5, 2]) == 0.0 and float(np.sum(y.visible_c)) == 10 * 6 - 1
    np.testing.assert_array_equal(y.p_s[3, 1], [0.0, 0.0, 1.0])
    assert all(np.all(np.isfinite(leaf)) for leaf in jax.tree_util.tree_leaves(y))
    x_b = np.asarray(sc.x_b).copy()
    x_b[4, 0] = np.nan
    with pytest.raises(RuntimeError, match="static_points_stream: sample 4"):
        static_points_stream(sc.ts, sc.R_b, x_b, p_s, p_c, sc.omega_c)
    stream = static_points_stream(sc.ts, sc.R_b, x_b, p_s, p_c, sc.omega_c, throw=False)
    with pytest.raises(RuntimeError, match="measurement sample is not finite"):
        run(est, stream, saveat=SAVE)


def test_five_percent_dropouts_reach_the_same_accuracy(project, project_run):
    """5% of the feature pixels (known and unknown) missing at random: the final accuracy
    within 20% of the dropout-free run's (the issue's must-show)."""
    sc, est, stream = project
    rng = np.random.default_rng(0)
    p_s = np.where(rng.random(sc.p_s.shape[:2])[..., None] < 0.05, np.nan, sc.p_s)
    p_c = np.where(rng.random(sc.p_c.shape[:2])[..., None] < 0.05, np.nan, sc.p_c)
    p_s[0], p_c[0] = sc.p_s[0], sc.p_c[0]  # the same initial guesses for the comparison
    stream = static_points_stream(sc.ts, sc.R_b, sc.x_b, p_s, p_c, sc.omega_c)
    missing = 1.0 - float(np.mean(stream.ys.visible_s))
    assert 0.04 < missing < 0.06
    sol = run(est, stream, saveat=SAVE)
    free = _errors(project_run.outputs.omega_s[-1], sc.omega_s)
    dropped = _errors(sol.outputs.omega_s[-1], sc.omega_s)
    assert np.all(free < 5e-3) and free.max() > 1e-4  # converging, not converged
    # the run's accuracy: its largest and its RMS error (measured +10% and +8%; feature by
    # feature after 10 s the differences are -6% to +40%, both ways)
    assert abs(dropped.max() / free.max() - 1.0) < 0.2, (free, dropped)
    rms = [np.sqrt(np.mean(e**2)) for e in (free, dropped)]
    assert abs(rms[1] / rms[0] - 1.0) < 0.2, (free, dropped)


def test_a_hidden_feature_is_held_then_goes_on(project, project_run):
    """Unknown feature 2 out of view for t in [2, 6) s and known feature 0 for [1, 3) s:
    feature 2's estimate is held exactly over its interval while the others move; it goes
    on afterwards (its error at 10 s below half its error when it vanished), and the others
    end as accurate as without the gaps (within 25%)."""
    sc, est, stream = project
    ts = np.asarray(sc.ts)
    p_s, p_c = np.asarray(sc.p_s).copy(), np.asarray(sc.p_c).copy()
    p_s[(ts >= 2.0) & (ts < 6.0), 2] = np.nan
    p_c[(ts >= 1.0) & (ts < 3.0), 0] = np.nan
    stream = static_points_stream(sc.ts, sc.R_b, sc.x_b, p_s, p_c, sc.omega_c)
    sol = run(est, stream, saveat=SAVE)
    omega = np.asarray(sol.outputs.omega_s)  # at t = 0, 1, ..., 9 s
    np.testing.assert_array_equal(omega[3, 2], omega[6, 2])  # held from 2 s to 6 s
    assert np.abs(omega[6, [0, 1, 3]] - omega[3, [0, 1, 3]]).max() > 1e-4
    err = _errors(omega[:, 2], np.asarray(sc.omega_s[2])[None])
    assert err[-1] < 0.5 * err[6], err
    free = _errors(project_run.outputs.omega_s[-1], sc.omega_s)
    final = _errors(omega[-1], sc.omega_s)
    others = [0, 1, 3]
    assert np.all(final[others] < 1.25 * free[others] + 1e-4), (final, free)


def test_a_feature_unseen_at_first_starts_on_its_first_ray(project):
    sc, _, stream = project
    p_s = np.asarray(sc.p_s).copy()
    p_s[:100, 1] = np.nan  # first seen at sample 100
    stream = static_points_stream(sc.ts, sc.R_b, sc.x_b, p_s, sc.p_c, sc.omega_c)
    A0, R0, x0 = nath.nominal_camera()
    est = StaticPointsEstimator.from_nominal(stream, A0, R0, x0)
    q = (est.theta_s0[1, :3] - sc.x_b[100]) @ sc.R_b[100]
    p = A0 @ ((q - x0) @ R0)
    np.testing.assert_allclose(p[:2] / p[2], sc.p_s[100, 1], atol=1e-8)


# --- the tilted scene of issue 10 ----------------------------------------------------------


@pytest.mark.slow  # 40 s at 1 kHz: product scale
def test_the_tilted_scene_converges():
    """The scene that stalled at 4-47 mm with version 1's gains: 40 s noise-free, every
    unknown feature within 0.5 mm (measured 0.03-0.18 mm; the issue's aim 5 mm) from
    initial errors of 10-52 cm, the camera recovered within 2 px, 0.1 deg and 5 mm."""
    sc = tilted_platform_scene(40.0)
    stream = static_points_stream(
        sc["ts"], sc["R_b"], sc["x_b"], sc["p_s"], sc["p_c"], sc["omega_c"]
    )
    est = StaticPointsEstimator.from_nominal(stream, *sc["nominal"])
    sol = run(est, stream, saveat=SaveAt(outputs=False))
    assert sol.result == RESULTS.successful
    err0 = _errors(est.theta_s0[:, :3], sc["omega_s"])
    out = est.output(sc["ts"][-1], sol.final_state, None)
    err = _errors(out.omega_s, sc["omega_s"])
    assert err0.min() > 0.09 and err0.max() > 0.5
    assert np.all(err < 5e-4), err
    assert np.abs(np.asarray(out.A - sc["A"])).max() < 2.0
    assert _angle_deg(np.asarray(out.R_c) @ np.asarray(sc["R_c"]).T) < 0.1
    assert np.linalg.norm(np.asarray(out.x_c - sc["x_c"])) < 5e-3


# --- jit, vmap, grad of the new public functions -----------------------------------------


def test_camera_jit_vmap_grad(project):
    sc, est, stream = project
    y0 = jax.tree_util.tree_map(lambda x: x[0], stream.ys)
    state = est.init(y0)
    theta = _true_theta(est, sc.A, sc.R_c, sc.x_c)
    thetas = theta[None, :] + 1e-3 * jax.random.normal(jax.random.key(1), (3, 16))

    def camera(th):
        return est.camera(eqx.tree_at(lambda s: s.theta_c, state, th))

    batched = jax.jit(jax.vmap(camera))(thetas)
    for i in range(3):
        for a, b in zip(batched, camera(thetas[i])):
            np.testing.assert_allclose(a[i], b, rtol=1e-12, atol=1e-12)

    def flat(th):
        A, R_c, x_c = camera(th)
        return jnp.concatenate([A.reshape(-1), R_c.reshape(-1), x_c])

    jac = jax.jit(jax.jacfwd(flat))(thetas[0])
    np.testing.assert_allclose(jac, central_difference(flat, thetas[0], 1e-6), atol=1e-5)


def test_from_nominal_jit_vmap_grad(project):
    """`from_nominal` is traceable: under jit and vmap over the nominal offset it matches
    the eager build, and its initial estimates and gains differentiate (against central
    differences) in the nominal offset and the depth guess (on the first 50 samples)."""
    sc, _, stream = project
    stream = static_points_stream(
        sc.ts[:50], sc.R_b[:50], sc.x_b[:50], sc.p_s[:50], sc.p_c[:50], sc.omega_c
    )
    A0, R0, x0 = nath.nominal_camera()

    def build(x_c, depth):
        est = StaticPointsEstimator.from_nominal(stream, A0, R0, x_c, depth_guess=depth)
        return jnp.concatenate([est.theta_s0.reshape(-1), est.theta_c0, est.eta0[None]])

    xs = x0[None, :] + jnp.array([[0.0, 0.0, 0.0], [0.01, -0.02, 0.005]])
    batched = jax.jit(jax.vmap(build, in_axes=(0, None)))(xs, 1.4)
    np.testing.assert_allclose(batched[1], jax.jit(build)(xs[1], 1.4), rtol=1e-10)
    args = jnp.concatenate([x0, jnp.array([1.4])])

    def f(v):
        return build(v[:3], v[3])

    jac = jax.jit(jax.jacfwd(f))(args)
    fd = central_difference(f, args, 1e-6)
    np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())
    assert np.abs(jac[:, 3]).max() > 0.1  # the guesses move with the depth guess
