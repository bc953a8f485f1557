"""Every EKF of visjax against dynamax's extended Kalman filter (an independent
implementation; dynamax is a test dependency only): the same model, run by both on the
same inputs, gives the same filtered means (to 1e-9) and covariances (to 5e-9).

Compared, each on a short noisy run (40 samples) of a scene the baselines' own tests use:
a hand-written pendulum (the generic `extended_kalman_filter`, non-uniform sample times,
missing components and a dropped sample), `static_points_ekf` (`_CameraFeaturesModel`,
Nath et al.'s scene), `moving_point_ekf` (`_InverseDepth`, Jang's thesis; `substeps=1`),
`velocity_ekf` (`_ConstantAcceleration`, Chitrakaran et al.'s target) and the point-depth
problem's EKF (`spica.InverseDepthModel`, each of its five points). For the three
baselines, the model and every input (`ts`, `zs`, `us`, `x0`, `P0`, `present`, `substeps`)
are recorded from the baseline's own call of `extended_kalman_filter`, so dynamax runs
exactly what the baseline runs; the point-depth problem calls the filter under `vmap`
(nothing concrete to record), so its construction (`PointDepthProblem._ekf`) is repeated
here and tied to the problem's own depths (1 / chi, to 1e-12). On dynamax's side the
model's `transition`, `measure`, `process_noise`, `measurement_noise` define its functions;
nothing else of visjax is used there.

Conventions matched (read in dynamax 1.0.3's `nonlinear_gaussian_ssm/inference_ekf.py`):

- dynamax's prior (`initial_mean`, `initial_covariance`) is at the first sample, before its
  update, and sample 0 gets no prediction: visjax's convention;
- dynamax's step `t` updates with `emissions[t]` under `inputs[t]`, then predicts to `t+1`
  with `f(x, inputs[t+1])` and `Q[t+1]`; visjax predicts to sample `k` under the input held
  from sample `k-1` over `dt_k = t_k - t_{k-1}` and updates under `u_k`. So dynamax's input
  row `k` carries `u_k` (for `h`), `u_{k-1}` and `dt_k` (for `f`), and the seen mask;
- `Q` and `R` are arrays in dynamax (time-varying: (N, n, n), (N, m, m)), functions of the
  state in visjax: `Q_k = process_noise(x0, u_{k-1}, dt_k)`, `R_k = measurement_noise(x0,
  u_k)`, exact because no model's noise depends on the state (asserted along each run);
- a missing component (NaN) or a dropped sample (`present`): zero innovation and a zero row
  of `H` (dynamax's `h` returns 0 there and its emission is 0) with a unit variance
  decoupled from the others in `R_k`: the same update as leaving the component out;
- dynamax updates the covariance as `P - K S K^T` (visjax: Joseph form) and solves with
  `S + 1e-9 I` (`psd_solve`'s `diagonal_boost`, a regularisation, no part of the EKF): the
  module sets that boost to 0 while its tests run (`test_pendulum` shows it matters);
- `substeps=1`: dynamax takes one transition per sample. visjax's `substeps` s > 1 is one
  transition (the composition, Jacobian `F_s ... F_1`) with the noise `Q_eff = sum_j
  (F_s ... F_{j+1}) Q_j (F_s ... F_{j+1})^T`, which depends on the state through the
  Jacobians of a nonlinear transition: dynamax's `Q` arrays, fixed before the run, cannot
  express it.

Tolerance, per sample and entry, relative to the filter's own scale: means
`|x - x_dmx| <= 1e-9 (|x| + sqrt(P_ii))`, covariances `|P - P_dmx|_ij <= 5e-9 sqrt(P_ii
P_jj)` (visjax's `P`; the two covariance updates round differently, `TOL_P`).
"""

import functools
import inspect

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import visjax.baselines._bundle as bundle_module
import visjax.baselines._point_fit as point_fit_module
import visjax.baselines._pose_fit as pose_fit_module
from visjax._results import RESULTS
from visjax.baselines import (
    AbstractEKFModel,
    extended_kalman_filter,
    moving_point_ekf,
    static_points_ekf,
    velocity_ekf,
)
from visjax.estimators import FixedCamera, moving_point_stream
from visjax.geometry import pixel_to_normalized
from visjax.kinematics import perspective_dynamics
from visjax.papers import chitrakaran as ch, nath, spica
from visjax.sim import (
    CameraRig,
    constant_twist_trajectory,
    object_points,
    points_in_camera,
    view,
)

TOL = 1e-9
# covariances: dynamax's standard update `P - K S K^T` and visjax's Joseph form round
# differently, more so as the filter grows confident: 3e-10 on the static-points filter
# with jax 0.4, 1.3e-9 with jax 0.10 (XLA's CPU fusions changed); means stay within TOL
TOL_P = 5e-9
N = 40

# A peer library's agreement, run in CI's slow tier: the unit tier keeps visjax's own
# oracles of these filters (tests/baselines/test_ekf.py, the baselines' exactness and
# convergence tests), and dynamax (with TensorFlow Probability's JAX substrate, a second
# of import) is imported only when these tests run, not when the suite is collected.
pytestmark = pytest.mark.slow

dynamax_ekf = ParamsNLGSSM = psd_solve = None  # dynamax's, bound by `no_diagonal_boost`


@pytest.fixture(scope="module", autouse=True)
def no_diagonal_boost():
    """dynamax's solve without its 1e-9 I added to S (module docstring); dynamax imported
    here, when the module's tests run."""
    global dynamax_ekf, ParamsNLGSSM, psd_solve
    import dynamax.nonlinear_gaussian_ssm.inference_ekf as dynamax_ekf
    from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM
    from dynamax.utils.utils import psd_solve

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(dynamax_ekf, "psd_solve", functools.partial(psd_solve, diagonal_boost=0.0))
        yield


def _rows(tree, n):
    """A pytree of leading size n as (n, d) float rows, and its inverse."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    shapes = [jnp.shape(leaf)[1:] for leaf in leaves]
    sizes = [int(np.prod(s)) for s in shapes]
    flat = [jnp.reshape(jnp.asarray(leaf, float), (n, -1)) for leaf in leaves]
    rows = jnp.concatenate(flat, axis=1) if flat else jnp.zeros((n, 0))

    def unflatten(row):
        parts, start = [], 0
        for shape, size in zip(shapes, sizes, strict=True):
            parts.append(row[start : start + size].reshape(shape))
            start += size
        return jax.tree_util.tree_unflatten(treedef, parts)

    return rows, unflatten


def _at(tree, k):
    return jax.tree_util.tree_map(lambda leaf: jnp.asarray(leaf)[k], tree)


def _noises(model, x0, ts, us):
    """`Q_k = process_noise(x0, u_{k-1}, dt_k)` (Q_0 at dt = 0, unused) and
    `R_k = measurement_noise(x0, u_k)`."""
    n_samples = ts.shape[0]
    dts = jnp.concatenate([jnp.zeros(1), jnp.diff(ts)])
    prev = jnp.maximum(jnp.arange(n_samples) - 1, 0)
    Q = jax.vmap(lambda k: model.process_noise(x0, _at(us, prev[k]), dts[k]))(jnp.arange(n_samples))
    R = jax.vmap(lambda k: model.measurement_noise(x0, _at(us, k)))(jnp.arange(n_samples))
    return Q, R


def dynamax_filter(model, ts, zs, us, x0, P0, present):
    """dynamax's EKF on visjax's `model` and stream (module docstring): the filtered means
    (N, n) and covariances (N, n, n)."""
    n_samples = ts.shape[0]
    seen = ~jnp.isnan(zs) & present[:, None]
    m = zs.shape[1]
    urows, unflatten = _rows(us, n_samples)
    d = urows.shape[1]
    dts = jnp.concatenate([jnp.zeros(1), jnp.diff(ts)])
    prev = jnp.concatenate([urows[:1], urows[:-1]])
    inputs = jnp.concatenate([urows, prev, seen.astype(float), dts[:, None]], axis=1)
    Q, R = _noises(model, x0, ts, us)
    both = seen[:, :, None] & seen[:, None, :]
    R = jnp.where(both, R, jnp.eye(m))

    def f(x, row):
        return model.transition(x, unflatten(row[d : 2 * d]), row[-1])

    def h(x, row):
        return jnp.where(row[2 * d : 2 * d + m] > 0.5, model.measure(x, unflatten(row[:d])), 0.0)

    params = ParamsNLGSSM(
        initial_mean=x0,
        initial_covariance=P0,
        dynamics_function=f,
        dynamics_covariance=Q,
        emission_function=h,
        emission_covariance=R,
    )
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        post = dynamax_ekf.extended_kalman_filter(
            params,
            jnp.where(seen, zs, 0.0),
            inputs=inputs,
            output_fields=["filtered_means", "filtered_covariances"],
        )
    return post.filtered_means, post.filtered_covariances


@eqx.filter_jit
def dynamax_side(model, ts, zs, us, x0, P0, present, x):
    """`dynamax_filter`, and the largest change of `Q_k`, `R_k` when evaluated at visjax's
    filtered means `x` (N, n) instead of `x0` (0: the noises do not depend on the state)."""
    x_d, P_d = dynamax_filter(model, ts, zs, us, x0, P0, present)
    Q0, R0 = _noises(model, x0, ts, us)
    dts = jnp.concatenate([jnp.zeros(1), jnp.diff(ts)])
    ks = jnp.arange(1, ts.shape[0])
    Q = jax.vmap(lambda k: model.process_noise(x[k - 1], _at(us, k - 1), dts[k]))(ks)
    R = jax.vmap(lambda k: model.measurement_noise(x[k], _at(us, k)))(jnp.arange(ts.shape[0]))
    return x_d, P_d, jnp.max(jnp.abs(Q - Q0[1:])), jnp.max(jnp.abs(R - R0))


def scaled_differences(x, P, x_d, P_d):
    """The largest scaled differences of the means and of the covariances (tolerance form
    of the module docstring), and the largest raw ones."""
    x, P, x_d, P_d = (np.asarray(a) for a in (x, P, x_d, P_d))
    sd = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
    dx = np.abs(x - x_d)
    dP = np.abs(P - P_d)
    return (
        float(np.max(dx / (np.abs(x) + sd))),
        float(np.max(dP / (sd[:, :, None] * sd[:, None, :]))),
        float(dx.max()),
        float(dP.max()),
    )


def assert_same(name, model, ts, zs, us, x0, P0, present, x, P):
    """dynamax's filter on the same model and inputs equals visjax's `x`, `P` (N, n), (N,
    n, n); the noises are state-independent along the run; the run is not trivial."""
    ts, zs, x0, P0 = (jnp.asarray(a, float) for a in (ts, zs, x0, P0))
    us = jax.tree_util.tree_map(jnp.asarray, us)
    present = jnp.ones(ts.shape[0], bool) if present is None else jnp.asarray(present)
    x_d, P_d, dQ, dR = dynamax_side(model, ts, zs, us, x0, P0, present, x)
    ex, eP, raw_x, raw_P = scaled_differences(x, P, x_d, P_d)
    print(f"\n{name}: means {ex:.1e} (raw {raw_x:.1e}), covariances {eP:.1e} (raw {raw_P:.1e})")
    assert ex <= TOL and eP <= TOL_P, (ex, eP)
    assert dQ == 0.0 and dR == 0.0, (dQ, dR)
    # the run is not trivial: the means and covariances move far more than the tolerance
    sd0 = np.sqrt(np.diag(np.asarray(P0)))
    assert np.max(np.abs(np.asarray(x[-1]) - np.asarray(x0)) / sd0) > 1e-2
    assert np.max(np.abs(np.asarray(P[-1]) - np.asarray(P0)) / np.outer(sd0, sd0)) > 1e-2


def run_recorded(module, baseline, *args, **kwargs):
    """Run a baseline (compiled) and return its one call of `extended_kalman_filter`: the
    arguments by name (defaults included) and the solution."""
    calls = []
    real = module.extended_kalman_filter
    signature = inspect.signature(real)

    def record(*a, **kw):
        sol = real(*a, **kw)
        bound = signature.bind(*a, **kw)
        bound.apply_defaults()
        calls.append((dict(bound.arguments), sol))
        return sol

    @eqx.filter_jit
    def go(args, kwargs):
        baseline(*args, **kwargs)
        assert len(calls) == 1
        return calls[0]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(module, "extended_kalman_filter", record)
        return go(args, kwargs)


def assert_baseline_same(name, module, baseline, *args, **kwargs):
    """dynamax on the model and inputs of a baseline's filter."""
    a, sol = run_recorded(module, baseline, *args, **kwargs)
    assert a["substeps"] == 1 and a.get("gate") is None, a
    assert sol.result == RESULTS.successful
    assert np.all(np.isfinite(np.asarray(a["zs"])))  # fully observed
    inputs = (a[k] for k in ("model", "ts", "zs", "us", "x0", "P0", "present"))
    assert_same(name, *inputs, sol.outputs.x, sol.outputs.P)


# ---------------------------------------------------------------------------------------
# the generic filter: a hand-written pendulum


class Pendulum(AbstractEKFModel):
    """A pendulum under a known torque `u` (a scalar per sample), state [theta, omega]:
    one RK4 step of theta'' = -(g/L) sin(theta) - c omega + u, white angular acceleration
    of density `q`; measured: the bob's position (L sin theta, -L cos theta)."""

    q: jax.Array = eqx.field(converter=jnp.asarray)
    r: jax.Array = eqx.field(converter=jnp.asarray)
    length: float = 0.8
    damping: float = 0.3

    def transition(self, x, u, dt):
        def rate(z):
            acc = -9.81 / self.length * jnp.sin(z[0]) - self.damping * z[1] + u
            return jnp.stack([z[1], acc])

        k1 = rate(x)
        k2 = rate(x + 0.5 * dt * k1)
        k3 = rate(x + 0.5 * dt * k2)
        k4 = rate(x + dt * k3)
        return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

    def process_noise(self, x, u, dt):
        G = jnp.stack([0.5 * dt**2, dt])
        return self.q * jnp.outer(G, G)

    def measure(self, x, u):
        return self.length * jnp.stack([jnp.sin(x[0]), -jnp.cos(x[0])])

    def measurement_noise(self, x, u):
        return self.r * jnp.array([[1.0, 0.3], [0.3, 1.0]])


@pytest.fixture(scope="module")
def pendulum():
    rng = np.random.default_rng(5)
    ts = np.cumsum(np.r_[0.0, rng.uniform(0.03, 0.08, N - 1)])  # non-uniform rate
    us = 0.5 * np.sin(2.0 * ts)
    model = Pendulum(q=0.5, r=1e-4)
    # the truth: the model's own transition in fine steps, then measured with noise
    x, truth = np.array([1.0, 0.0]), []
    for k in range(N):
        truth.append(x)
        if k + 1 < N:
            for _ in range(10):
                x = np.asarray(model.transition(jnp.asarray(x), us[k], (ts[k + 1] - ts[k]) / 10))
    zs = np.asarray(jax.vmap(lambda s: model.measure(s, None))(jnp.asarray(np.array(truth))))
    zs = zs + 0.01 * rng.normal(size=zs.shape)
    zs[7, 0] = np.nan  # a missing component
    zs[12] = np.nan  # a missing sample
    present = np.ones(N, bool)
    present[25] = False  # a dropped sample
    x0, P0 = np.array([0.7, 0.5]), np.diag([0.2**2, 1.0])
    return model, ts, zs, us, x0, P0, present


def test_pendulum(pendulum):
    model, ts, zs, us, x0, P0, present = pendulum
    sol = jax.jit(extended_kalman_filter, static_argnames=("throw",))(
        model, ts, zs, us, x0, P0, present=present, throw=False
    )
    assert sol.result == RESULTS.successful
    assert_same("pendulum", model, ts, zs, us, x0, P0, present, sol.outputs.x, sol.outputs.P)
    # dynamax's default 1e-9 I on S (here ~1e-4): a difference the tolerance sees
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(dynamax_ekf, "psd_solve", psd_solve)
        args = (jnp.asarray(a, float) for a in (ts, zs, us, x0, P0))
        x_d, P_d = jax.jit(dynamax_filter)(model, *args, jnp.asarray(present))
    ex, eP, _, _ = scaled_differences(sol.outputs.x, sol.outputs.P, x_d, P_d)
    print(f"pendulum, dynamax's own boost: means {ex:.1e}, covariances {eP:.1e}")
    assert max(ex, eP) > 100 * TOL, (ex, eP)


# ---------------------------------------------------------------------------------------
# the baselines, each on a short noisy run of its tests' scene


def test_static_points_ekf():
    """`_CameraFeaturesModel` (23 states, 20 pixels) on Nath et al.'s scene at 100 Hz."""
    sc = nath.scenario(N / 100.0, 100.0, noise_px=0.5, key=jax.random.key(4))
    est = nath.initial_estimator(nath.scenario(N / 100.0, 100.0))
    stream = nath.stream(sc)
    assert_baseline_same(
        "static_points_ekf", bundle_module, static_points_ekf, est, stream, sc.omega_c, r_px=0.5
    )


@jax.jit
def moving_point(us, v_p, x0, dt):
    """The point's state at the samples (eq. (2.11), the camera velocity `us` (N, 6) held
    over each interval `dt`): 20 RK4 steps per interval (the scene of the baselines' own
    tests, integrated here without an adaptive solver's compile)."""

    def interval(x, u):
        def step(z, _):
            def f(w):
                return perspective_dynamics(w, u, v_p)

            h = dt / 20.0
            k1 = f(z)
            k2 = f(z + 0.5 * h * k1)
            k3 = f(z + 0.5 * h * k2)
            k4 = f(z + h * k3)
            return z + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4), None

        return jax.lax.scan(step, x, None, length=20)[0], x

    return jax.lax.scan(interval, x0, us)[1]


def test_moving_point_ekf():
    """`_InverseDepth` (RK4 of eq. (2.11), 6 states) on a moving point seen at 30 Hz, the
    camera velocity of `tests/baselines/test_point_fit.py`, held between samples."""
    rate = 30.0
    ts = jnp.arange(float(N)) / rate
    K = jnp.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
    v = jnp.stack([0.1 + 0.1 * jnp.sin(2 * ts), -0.05 + 0.08 * jnp.cos(1.5 * ts), 0.02 + 0 * ts])
    us = jnp.concatenate([v.T, jnp.tile(jnp.array([0.05, -0.03, 0.1]), (N, 1))], axis=1)
    x = moving_point(us, jnp.array([0.02, 0.01, 0.0]), jnp.array([0.1, -0.05, 1 / 1.5]), 1 / rate)
    pixels = x[:, :2] @ K[:2, :2].T + K[:2, 2][None]
    pixels = pixels + 0.1 * jax.random.normal(jax.random.key(1), pixels.shape)
    stream = moving_point_stream(ts, pixels, us, K)
    assert_baseline_same(
        "moving_point_ekf",
        point_fit_module,
        moving_point_ekf,
        stream,
        r_norm=0.1 / 800.0,
        depth0=1.0,
        sigma_depth0=0.5,
        q_velocity=1e-4,
        sigma_velocity0=0.05,
        substeps=1,
    )


def test_velocity_ekf():
    """`_ConstantAcceleration` (18 states, 8 pixels) on the section-6 target at 1 kHz."""
    twist = jnp.array([0.05, -0.03, 0.02, 0.1, -0.05, 0.08])
    ts = jnp.arange(float(N)) / 1000.0
    body = constant_twist_trajectory(
        twist, jnp.array(ch.X_F_STAR_EQ60), jnp.array(ch.R_STAR_EQ61), ts
    )
    A = jnp.array(ch.A_EQ62)
    rig = CameraRig(A=A, image_size=None)
    clean = view(rig, points_in_camera(rig, object_points(body, jnp.array(ch.FEATURES))))
    # the reference frame's plane and depth (the scene's first pose), as `section6_scenario`
    R_star, x_f_star, s = (jnp.array(a) for a in (ch.R_STAR_EQ61, ch.X_F_STAR_EQ60, ch.FEATURES))
    n_star = R_star @ jnp.cross(s[0], s[1])
    m1_star = x_f_star + R_star @ s[0]
    n_star = jnp.sign(n_star @ m1_star) * n_star / jnp.linalg.norm(n_star)
    camera = FixedCamera(clean[0], A, R_star, s[0], n_star, m1_star[2])
    pixels = clean + 0.1 * jax.random.normal(jax.random.key(2), clean.shape)
    assert_baseline_same(
        "velocity_ekf",
        pose_fit_module,
        velocity_ekf,
        ts,
        pixels,
        camera,
        r_px=0.1,
        max_jerk=0.1,
        max_angular_jerk=0.1,
    )


def test_point_depth_ekf():
    """`spica.InverseDepthModel` (Euler step, 3 states) for each of the point-depth
    problem's five points, 40 samples at 50 Hz, 0.5 px: the problem's own `_ekf` inputs."""
    problem = spica.point_depth_problem(noise_px=0.5, duration=N / 50.0, rate_hz=50.0)
    sc = problem.scene
    pixels = problem.inputs(jax.random.key(3))
    params = problem.resolve()  # every default: the prior's spread 0.5 chi0, q 1e-8
    chi0, sd = problem.parameters()["chi0"].default, 0.5 * params["chi0"]
    depth = problem.solve("ekf", params, pixels).depth
    # the problem's construction (`PointDepthProblem._ekf`), one point at a time
    model = spica.InverseDepthModel(q_s=1e-8, q_chi=1e-8, r=(0.5 / sc.K[0, 0]) ** 2)
    run = jax.jit(extended_kalman_filter, static_argnames=("throw",))
    for i in range(pixels.shape[1]):
        m = pixel_to_normalized(pixels[:, i], sc.K)
        x0 = jnp.stack([m[0, 0], m[0, 1], jnp.asarray(chi0)])
        P0 = jnp.diag(jnp.stack([model.r, model.r, sd**2]))
        sol = run(model, sc.ts, m, sc.twists, x0, P0, throw=False)
        assert sol.result == RESULTS.successful
        # the same filter as the problem's (its depth is 1 / chi)
        np.testing.assert_allclose(1.0 / sol.outputs.x[:, 2], depth[:, i], rtol=1e-12)
        x, P = sol.outputs.x, sol.outputs.P
        assert_same(f"point-depth point {i}", model, sc.ts, m, sc.twists, x0, P0, None, x, P)
