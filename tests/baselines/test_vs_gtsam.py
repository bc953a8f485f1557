"""GTSAM as the reference of the batch baselines (issue 30, item 1): the same structure
problems posed as GTSAM factor graphs and solved by its Levenberg-Marquardt, from the same
initial values, give the same solutions (1e-6 relative) and the same final costs.

- The static points of Nath et al. (`bundle_adjustment`), the camera uncalibrated
  (`intrinsics="fit"`: a `Cal3_S2` variable) and calibrated (`intrinsics="known"`: a
  constant `Cal3_S2`), on three scenes of the catalogue (`papers.nath.scenario`,
  `sim.tilted_platform_scene`, `sim.side_looking_platform_scene`), 40 frames each, at 0,
  0.5 and 1 px of pixel noise.
- The moving point's triangulation refined to the reprojection minimum
  (`triangulate_point(..., refine=True)`) on the moving-target scenes
  (`sim.sideways_camera_scene`, `sim.circling_camera_scene`) and a static point seen by a
  turning camera, 60 frames, every full window of 20, at 0, 0.5 and 1 px.

The GTSAM side is an independent transcription (`gtsam_static_points`,
`gtsam_triangulation`): GTSAM computes every residual and Jacobian itself (`Pose3.compose`,
`PinholeCameraCal3_S2.project`, `TriangulationFactorCal3_S2`); visjax gives it only the
data and the initial values. Unit noise models: GTSAM's graph error is
$\\frac12\\sum\\|r\\|^2$, the cost optimistix's Levenberg-Marquardt minimises. Each visjax
program is compiled once, every scene and noise level in one vmapped call (the scenes
trimmed to the same shapes: 4 unknown and 6 known features).
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import sim
from visjax._results import RESULTS
from visjax.baselines import (
    bundle_adjustment,
    camera_poses,
    triangulate_point,
    triangulation_residuals,
)
from visjax.estimators import StaticPointsEstimator, moving_point_stream, static_points_stream
from visjax.papers import nath

gtsam = pytest.importorskip("gtsam")

# A peer library's agreement, run in CI's slow tier: the unit tier keeps visjax's own
# oracles of these baselines (exact on noise-free data, the reprojection minimum's
# gradient: tests/baselines/test_bundle.py, test_point_fit.py, test_triangulation_robust.py).
pytestmark = pytest.mark.slow

NOISE_PX = (0.0, 0.5, 1.0)
# optimistix's Levenberg-Marquardt stops after an accepted step below rtol and atol (in the
# unknowns and in the residuals): the baselines' defaults, its last step 1e-9 (static
# points) and 1e-8 (points) relative, the solution's error far below after it. A step is
# accepted on the decrease of the cost, which rounding blurs below ~1e-16 of the cost:
# steps below ~sqrt(1e-16 cost / curvature), ~1e-10 along a weak direction, are accepted
# at random, and a tolerance there can end in `max_steps` (measured: 1e-10 on a 15-frame
# window). GTSAM stops on the cost itself (relative and absolute decrease below 1e-14).
BUNDLE_TOL = dict(rtol=1e-9, atol=1e-9)
POINT_TOL = dict(rtol=1e-8, atol=1e-10)
N_UNKNOWN, N_KNOWN = 4, 6  # every static-points scene trimmed to these
WINDOW = 20  # frames per triangulation window
TRIANGULATION_FRAMES = 60
QUANTITIES = ("A", "R_c", "x_c", "omega_s")  # the solved quantities of the static points
SOLUTION_RTOL = 1e-6
COST_RTOL, COST_ATOL = 1e-6, 1e-12  # costs in px^2 (static points), normalised^2 (points)


# --- GTSAM: the reference ----------------------------------------------------------------


def _lm_params(max_iterations: int = 200):
    """GTSAM's Levenberg-Marquardt, converged to the last digits."""
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    params.setMaxIterations(max_iterations)
    return params


def _cal3_s2(A):
    """GTSAM's `Cal3_S2(fx, fy, s, u0, v0)` of an upper-triangular $A$ (eq. (4) of Nath
    et al.: $A_{11} = f_x$, $A_{12} = s$, $A_{13} = u_0$, $A_{22} = f_y$, $A_{23} = v_0$)."""
    return gtsam.Cal3_S2(A[0, 0], A[1, 1], A[0, 1], A[0, 2], A[1, 2])


def gtsam_static_points(
    R_b, x_b, p_s, p_c, omega_c, A0, R_c0, x_c0, omega_s0, *, calibrated, iterations=200
):
    """The static-points problem of Nath et al. as a GTSAM factor graph, solved by its
    Levenberg-Marquardt.

    Variables: the mounting $M$ = `Pose3(R_c, x_c)` (the camera's pose in the platform
    frame: eq. (5) maps a platform point $q$ to $R_c^T(q - x_c)$), a `Point3` per unknown
    feature, and (uncalibrated) the calibration `Cal3_S2`; calibrated, the calibration is
    the constant `A0`. A factor per seen pixel (NaN: no factor): the camera of frame $k$ is
    `Pose3(R_b[k], x_b[k]).compose(M)` and the predicted pixel
    `PinholeCameraCal3_S2(pose, K).project(point)` (the known features constants), its
    Jacobians GTSAM's own, chained; unit noise.

    **Returns:** a dict: `A`, `R_c`, `x_c`, `omega_s` at the solution, `cost` (GTSAM's
    graph error, $\\frac12\\sum\\|r\\|^2$), `iterations`, and `error_at(A, R_c, x_c,
    omega_s)`, the graph's error at any other values.
    """
    R_b, x_b, p_s, p_c, omega_c = (np.asarray(a, np.float64) for a in (R_b, x_b, p_s, p_c, omega_c))
    graph = gtsam.NonlinearFactorGraph()
    unit = gtsam.noiseModel.Unit.Create(2)
    k_mount, k_cal = gtsam.symbol("m", 0), gtsam.symbol("k", 0)
    K_fixed = _cal3_s2(np.asarray(A0))

    def factor(body, measured, point_key=None, point=None):
        keys = [k_mount] + ([] if calibrated else [k_cal])
        keys += [] if point_key is None else [point_key]

        def error(this, values, H):
            mount = values.atPose3(k_mount)
            cal = K_fixed if calibrated else values.atCal3_S2(k_cal)
            w = point if point_key is None else values.atPoint3(point_key)
            d_mount = np.zeros((6, 6), order="F")
            pose = body.compose(mount, None, d_mount)
            d_pose = np.zeros((2, 6), order="F")
            d_point = np.zeros((2, 3), order="F")
            d_cal = np.zeros((2, 5), order="F")
            uv = gtsam.PinholeCameraCal3_S2(pose, cal).project(w, d_pose, d_point, d_cal)
            if H is not None:
                H[0] = d_pose @ d_mount
                if not calibrated:
                    H[1] = d_cal
                if point_key is not None:
                    H[len(keys) - 1] = d_point
            return uv - measured

        return gtsam.CustomFactor(unit, keys, error)

    for k in range(R_b.shape[0]):
        body = gtsam.Pose3(gtsam.Rot3(R_b[k]), x_b[k])
        for i in range(p_s.shape[1]):
            if np.all(np.isfinite(p_s[k, i])):
                graph.add(factor(body, p_s[k, i], point_key=gtsam.symbol("l", i)))
        for j in range(p_c.shape[1]):
            if np.all(np.isfinite(p_c[k, j])):
                graph.add(factor(body, p_c[k, j], point=omega_c[j]))

    def values_of(A, R_c, x_c, omega_s):
        values = gtsam.Values()
        values.insert(k_mount, gtsam.Pose3(gtsam.Rot3(np.asarray(R_c)), np.asarray(x_c)))
        if not calibrated:
            values.insert(k_cal, _cal3_s2(np.asarray(A)))
        for i, w in enumerate(np.asarray(omega_s)):
            values.insert(gtsam.symbol("l", i), w)
        return values

    optimizer = gtsam.LevenbergMarquardtOptimizer(
        graph, values_of(A0, R_c0, x_c0, omega_s0), _lm_params(iterations)
    )
    result = optimizer.optimize()
    mount = result.atPose3(k_mount)
    n = np.asarray(omega_s0).shape[0]
    return {
        "A": K_fixed.K() if calibrated else result.atCal3_S2(k_cal).K(),
        "R_c": mount.rotation().matrix(),
        "x_c": mount.translation(),
        "omega_s": np.stack([result.atPoint3(gtsam.symbol("l", i)) for i in range(n)]),
        "cost": graph.error(result),
        "iterations": optimizer.iterations(),
        "error_at": lambda *camera: graph.error(values_of(*camera)),
    }


def window_cameras(R, c, k, window):
    """The poses of the `window` frames up to `k` in frame `k`'s coordinates, from the
    poses `(R, c)` of `camera_poses` ($m = R^T(P - c)$): $R_{kj} = R_k^TR_j$,
    $c_{kj} = R_k^T(c_j - c_k)$, so that a point $P$ of frame $k$ is at
    $R_{kj}^T(P - c_{kj})$ in frame $j$."""
    R, c = np.asarray(R), np.asarray(c)
    idx = np.arange(k - window + 1, k + 1)
    return np.einsum("ji,njk->nik", R[k], R[idx]), (c[idx] - c[k]) @ R[k]


def gtsam_triangulation(R_kj, c_kj, y, P0, iterations=100):
    """A static point from the normalised coordinates `y` (W, 2) of the frames at poses
    `(R_kj, c_kj)` (`window_cameras`) by GTSAM: one `TriangulationFactorCal3_S2` per seen
    frame (a fixed `PinholeCameraCal3_S2` with the identity calibration `Cal3_S2(1, 1, 0,
    0, 0)`, unit noise), Levenberg-Marquardt from `P0`.

    **Returns:** `(point, cost, error_at)`: the solution, GTSAM's graph error there
    ($\\frac12\\sum\\|r\\|^2$) and the graph's error at any point."""
    graph = gtsam.NonlinearFactorGraph()
    unit = gtsam.noiseModel.Unit.Create(2)
    identity = gtsam.Cal3_S2(1.0, 1.0, 0.0, 0.0, 0.0)
    key = gtsam.symbol("p", 0)
    for Rj, cj, yj in zip(R_kj, c_kj, np.asarray(y)):
        if np.all(np.isfinite(yj)):
            camera = gtsam.PinholeCameraCal3_S2(gtsam.Pose3(gtsam.Rot3(Rj), cj), identity)
            graph.add(gtsam.TriangulationFactorCal3_S2(camera, yj, unit, key))

    def values_of(P):
        values = gtsam.Values()
        values.insert(key, np.asarray(P, np.float64))
        return values

    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values_of(P0), _lm_params(iterations))
    result = optimizer.optimize()
    return result.atPoint3(key), graph.error(result), lambda P: graph.error(values_of(P))


def rel_diff(a, b):
    """The largest difference relative to the largest entry of the reference `b`."""
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def cost_diff(a, b):
    """|a - b| over the tolerance: relative `COST_RTOL`, absolute `COST_ATOL` near zero."""
    return abs(a - b) / (COST_ATOL + COST_RTOL * abs(b))


# --- the static points ---------------------------------------------------------------------


def static_scenes():
    """Three scenes of the catalogue, 40 frames each, trimmed to 4 unknown and 6 known
    features: name, measurements and truth (the keys of `tilted_platform_scene`)."""
    tilted = sim.tilted_platform_scene(40.0, rate_hz=1.0)
    side = sim.side_looking_platform_scene(40.0, rate_hz=1.0)
    sc = nath.scenario(20.0, 2.0)
    project = {
        "name": "nath",
        **{k: getattr(sc, k) for k in ("ts", "R_b", "x_b", "p_s", "p_c", "omega_c")},
        **{k: getattr(sc, k) for k in ("omega_s", "A", "R_c", "x_c")},
        "nominal": nath.nominal_camera(),
    }
    scenes = []
    for s in (project, tilted, side):
        s = dict(s)
        s["p_s"], s["omega_s"] = s["p_s"][:, :N_UNKNOWN], s["omega_s"][:N_UNKNOWN]
        s["p_c"], s["omega_c"] = s["p_c"][:, :N_KNOWN], s["omega_c"][:N_KNOWN]
        scenes.append(s)
    return scenes


def _stack(trees):
    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *trees)


@eqx.filter_jit
def _initial_outputs(estimators, y0s):
    """Each estimator's initial estimate (its output at the first sample): what starts
    `bundle_adjustment`."""
    return jax.vmap(lambda e, y0: e.output(jnp.zeros(()), e.init(y0), y0))(estimators, y0s)


@functools.cache  # one program per setting
def _fit(intrinsics):
    def one(est, stream, omega_c):
        return bundle_adjustment(
            est, stream, omega_c, intrinsics=intrinsics, throw=False, **BUNDLE_TOL
        )

    return eqx.filter_jit(jax.vmap(one))


@pytest.fixture(scope="module")
def static_problems():
    """Every scene at every noise level (the noise of one seed per scene, scaled), and two
    estimators per problem, both from the measurements of the noise-free stream: from the
    scene's nominal camera (uncalibrated) and from its true intrinsics with the nominal
    mounting (calibrated)."""
    problems = []
    for seed, s in enumerate(static_scenes()):
        clean = static_points_stream(s["ts"], s["R_b"], s["x_b"], s["p_s"], s["p_c"], s["omega_c"])
        A0, R0, x0 = s["nominal"]
        nominal = StaticPointsEstimator.from_nominal(clean, A0, R0, x0)
        calibrated = StaticPointsEstimator.from_nominal(clean, s["A"], R0, x0)
        k1, k2 = jax.random.split(jax.random.key(seed))
        z_s = jax.random.normal(k1, s["p_s"].shape)
        z_c = jax.random.normal(k2, s["p_c"].shape)
        for noise in NOISE_PX:
            p_s, p_c = s["p_s"] + noise * z_s, s["p_c"] + noise * z_c
            stream = static_points_stream(s["ts"], s["R_b"], s["x_b"], p_s, p_c, s["omega_c"])
            problems.append(
                dict(
                    scene=s,
                    noise=noise,
                    p_s=p_s,
                    p_c=p_c,
                    stream=stream,
                    ests=(nominal, calibrated),
                )
            )
    return problems


def _solve_static(problems, intrinsics):
    """visjax (one vmapped call) and GTSAM (a loop) on every problem, from the same
    initial values. **Returns:** a list of (problem, visjax solution, GTSAM solution,
    visjax result code, visjax cost, the initial values), the solutions and initial values
    dicts of `A`, `R_c`, `x_c`, `omega_s`."""
    which = 0 if intrinsics == "fit" else 1
    ests = _stack([p["ests"][which] for p in problems])
    streams = _stack([p["stream"] for p in problems])
    omega_c = jnp.stack([p["scene"]["omega_c"] for p in problems])
    sols = _fit(intrinsics)(ests, streams, omega_c)
    y0s = jax.tree_util.tree_map(lambda x: x[:, 0], streams.ys)
    init = _initial_outputs(ests, y0s)
    rows = []
    for i, p in enumerate(problems):
        s = p["scene"]
        out = {k: np.asarray(getattr(sols.outputs, k)[i, -1]) for k in QUANTITIES}
        start = [np.asarray(getattr(init, k)[i]) for k in QUANTITIES]
        ref = gtsam_static_points(
            s["R_b"], s["x_b"], p["p_s"], p["p_c"], s["omega_c"], *start,
            calibrated=intrinsics == "known",
        )  # fmt: skip
        # visjax's cost from its own residuals: RMS^2 x the seen pixels (2 coordinates each)
        seen = np.prod(p["p_s"].shape[:2]) + np.prod(p["p_c"].shape[:2])
        cost = float(sols.diagnostics.rms_px[i, 0]) ** 2 * seen
        rows.append((p, out, ref, sols.result._value[i], cost, dict(zip(QUANTITIES, start))))
    return rows


@pytest.fixture(scope="module")
def uncalibrated(static_problems):
    return _solve_static(static_problems, "fit")


@pytest.fixture(scope="module")
def calibrated(static_problems):
    return _solve_static(static_problems, "known")


def _check_static(rows):
    for p, out, ref, code, cost, _ in rows:
        where = f"{p['scene']['name']} at {p['noise']} px"
        assert code == RESULTS.successful._value, where
        for k in QUANTITIES:
            assert rel_diff(out[k], ref[k]) < SOLUTION_RTOL, (where, k, rel_diff(out[k], ref[k]))
        # the same cost function (GTSAM's graph at visjax's solution) and the same minimum
        at_visjax = ref["error_at"](out["A"], out["R_c"], out["x_c"], out["omega_s"])
        assert cost_diff(cost, at_visjax) < 1e-3, (where, cost, at_visjax)
        assert cost_diff(cost, ref["cost"]) < 1.0, (where, cost, ref["cost"])
        # the problem is not trivial: GTSAM iterated, and the noisy costs are the noise's
        assert ref["iterations"] >= 2, where
        seen = np.prod(p["p_s"].shape[:2]) + np.prod(p["p_c"].shape[:2])
        if p["noise"] > 0:
            assert 0.3 < 2 * ref["cost"] / (2 * seen * p["noise"] ** 2) < 1.2, (where, ref["cost"])


@pytest.mark.slow  # the unit tier's time: the calibrated case stays there
def test_uncalibrated_static_points_equal_gtsam(uncalibrated):
    """Intrinsics, mounting and unknown features equal GTSAM's to 1e-6 relative, and the
    costs agree, on three scenes at 0, 0.5 and 1 px; noise-free both find the truth."""
    _check_static(uncalibrated)
    for p, out, ref, _, cost, _ in uncalibrated:
        s = p["scene"]
        if p["noise"] == 0:
            assert (
                rel_diff(out["A"], s["A"]) < 1e-9 and rel_diff(out["omega_s"], s["omega_s"]) < 1e-9
            )
            assert cost < 1e-12 and ref["cost"] < 1e-12


def test_calibrated_static_points_equal_gtsam_and_are_exact(calibrated):
    """`intrinsics="known"`: the intrinsics held at the estimator's initial ones (here the
    true ones), never moved; the mounting and the features equal GTSAM's with a constant
    `Cal3_S2`, and noise-free they are the truth (from a mounting 2-3 degrees and 1-5 cm
    off, features more than 1 cm off)."""
    _check_static(calibrated)
    for p, out, _, _, cost, start in calibrated:
        s = p["scene"]
        np.testing.assert_allclose(out["A"], s["A"], rtol=1e-11)
        if p["noise"] == 0:
            start_error = np.linalg.norm(start["omega_s"] - np.asarray(s["omega_s"]), axis=-1)
            assert start_error.min() > 0.01 and np.abs(start["x_c"] - s["x_c"]).max() > 0.009
            assert np.abs(out["omega_s"] - np.asarray(s["omega_s"])).max() < 1e-8
            np.testing.assert_allclose(out["R_c"], s["R_c"], atol=1e-10)
            np.testing.assert_allclose(out["x_c"], s["x_c"], atol=1e-9)
            assert cost < 1e-12


def test_bad_intrinsics_argument(static_problems):
    p = static_problems[0]
    with pytest.raises(ValueError, match="intrinsics"):
        bundle_adjustment(p["ests"][0], p["stream"], p["scene"]["omega_c"], intrinsics="fixed")


# --- the moving point's triangulation ------------------------------------------------------


def _turning_camera_point(n: int, rate_hz: float = 30.0):
    """A static point seen by a camera that turns and translates, its poses those of its
    held velocities (`camera_poses`): the pixels (focal length 800 px) and velocities."""
    ts = jnp.arange(float(n)) / rate_hz
    v = jnp.stack(
        [0.1 + 0.1 * jnp.sin(2 * ts), -0.05 + 0.08 * jnp.cos(1.5 * ts), jnp.full_like(ts, 0.02)], 1
    )
    u = jnp.concatenate([v, jnp.broadcast_to(jnp.array([0.05, -0.03, 0.1]), v.shape)], 1)
    R, c = camera_poses(ts, u)
    P = jnp.array([0.15, -0.08, 1.5])
    m = jnp.einsum("nji,nj->ni", R, P[None] - c)
    K = jnp.asarray(sim.MOVING_TARGET_K)
    pixels = (m[:, :2] / m[:, 2:]) @ K[:2, :2].T + K[:2, 2][None]
    return ts, pixels, u


def triangulation_scenes():
    """name, times, pixels, camera velocities (the frames of the 50 Hz camera of the
    moving-target scenes; the turning camera at 30 Hz), 60 frames each."""
    step = sim.MOVING_TARGET_RATE_HZ // sim.MOVING_TARGET_FRAME_HZ
    duration = TRIANGULATION_FRAMES / sim.MOVING_TARGET_FRAME_HZ
    scenes = []
    for name, build in (
        ("sideways", sim.sideways_camera_scene),
        ("circling", sim.circling_camera_scene),
    ):
        truth = build(duration)
        scenes.append((name, truth.ts[::step], truth.pixels[::step], truth.camera_velocity[::step]))
    scenes.append(("turning", *_turning_camera_point(TRIANGULATION_FRAMES)))
    return scenes


@pytest.fixture(scope="module")
def triangulations():
    """Every scene at every noise level: the linear and the refined triangulation (one
    vmapped call each), and GTSAM's from the linear solution at every full window."""
    problems = []
    for seed, (name, ts, pixels, u) in enumerate(triangulation_scenes()):
        z = jax.random.normal(jax.random.key(10 + seed), pixels.shape)
        for noise in NOISE_PX:
            stream = moving_point_stream(ts, pixels + noise * z, u, sim.MOVING_TARGET_K)
            problems.append(dict(name=name, noise=noise, stream=stream))
    streams = _stack([p["stream"] for p in problems])

    def both(stream):
        linear = triangulate_point(stream, window=WINDOW, throw=False)
        refined = triangulate_point(stream, window=WINDOW, refine=True, throw=False, **POINT_TOL)
        return linear, refined

    linear, refined = eqx.filter_jit(jax.vmap(both))(streams)
    for i, p in enumerate(problems):
        p["linear"] = jax.tree_util.tree_map(lambda x: np.asarray(x[i]), linear)
        p["refined"] = jax.tree_util.tree_map(lambda x: np.asarray(x[i]), refined)
        R, c = camera_poses(p["stream"].ts, p["stream"].ys.u)
        p["gtsam"] = []
        for k in range(WINDOW - 1, TRIANGULATION_FRAMES):
            R_kj, c_kj = window_cameras(R, c, k, WINDOW)
            y = np.asarray(p["stream"].ys.y)[k - WINDOW + 1 : k + 1]
            p["gtsam"].append(gtsam_triangulation(R_kj, c_kj, y, p["linear"].outputs.position[k]))
    return problems


def test_refined_triangulation_equals_gtsam(triangulations):
    """At every full window of three scenes at 0, 0.5 and 1 px, the refined point equals
    GTSAM's to 1e-6 relative, and the costs agree (GTSAM's graph at visjax's point, and
    visjax's `triangulation_residuals` at GTSAM's point)."""
    for p in triangulations:
        where = f"{p['name']} at {p['noise']} px"
        assert p["refined"].result._value == RESULTS.successful._value, where
        codes = p["refined"].diagnostics.codes._value[WINDOW - 1 :]
        assert np.all(codes == RESULTS.successful._value), where
        points = p["refined"].outputs.position[WINDOW - 1 :]
        for k, (P, ref, (point, cost, error_at)) in enumerate(zip(points, p["gtsam"], p["gtsam"])):
            assert rel_diff(P, point) < SOLUTION_RTOL, (where, k, rel_diff(P, point))
            assert cost_diff(error_at(P), cost) < 1.0, (where, k, error_at(P), cost)
        # the refinement moved the point off the linear solution, except where that is
        # exact (a static point, no noise)
        moved = np.abs(points - p["linear"].outputs.position[WINDOW - 1 :]).max()
        exact = p["name"] == "turning" and p["noise"] == 0
        assert (moved < 1e-9) if exact else (moved > 1e-6), (where, moved)
    # the same cost function: visjax's residuals at GTSAM's solution, a few windows
    for p in triangulations[::4]:
        for k in (WINDOW - 1, TRIANGULATION_FRAMES - 1):
            point, cost, _ = p["gtsam"][k - WINDOW + 1]
            r = triangulation_residuals(jnp.asarray(point), p["stream"], k, WINDOW)
            assert cost_diff(0.5 * float(jnp.sum(r**2)), cost) < 1e-3, (p["name"], k)


def test_refinement_is_exact_noise_free_and_lowers_the_cost(triangulations):
    """The turning camera's static point: exact noise-free. Under noise, at every window of
    every scene, the refined point's reprojection cost is below the linear solution's."""
    turning = [p for p in triangulations if p["name"] == "turning"]
    stream = turning[0]["stream"]
    R, c = camera_poses(stream.ts, stream.ys.u)
    true = np.einsum("nji,nj->ni", np.asarray(R), np.array([0.15, -0.08, 1.5])[None] - c)
    err = np.linalg.norm(turning[0]["refined"].outputs.position - true, axis=1)
    assert turning[0]["noise"] == 0 and err[WINDOW - 1 :].max() < 1e-9
    for p in triangulations:
        if p["noise"] == 0:
            continue
        linear = p["linear"].outputs.position[WINDOW - 1 :]
        refined = p["refined"].outputs.position[WINDOW - 1 :]
        for P_lin, P_ref, (_, _, error_at) in zip(linear, refined, p["gtsam"]):
            assert error_at(P_ref) < (1.0 - 1e-6) * error_at(P_lin), (p["name"], p["noise"])


def test_refine_needs_a_static_point(triangulations):
    with pytest.raises(ValueError, match="order=0"):
        triangulate_point(triangulations[0]["stream"], window=WINDOW, order=1, refine=True)


def test_gradient_through_the_refinement(triangulations):
    """`grad` of a refined point with respect to the measurements (the implicit function
    theorem at the minimum) equals central differences of the same program."""
    p = next(p for p in triangulations if p["name"] == "turning" and p["noise"] == 1.0)
    stream = p["stream"]
    k, j = TRIANGULATION_FRAMES - 1, TRIANGULATION_FRAMES - 5  # a frame inside the last window

    @jax.jit
    def depth(y):
        s = eqx.tree_at(lambda s: s.ys.y, stream, y)
        sol = triangulate_point(s, window=WINDOW, refine=True, **POINT_TOL)
        return sol.outputs.position[k, 2]

    g = jax.grad(depth)(stream.ys.y)
    assert np.all(np.isfinite(g)) and np.all(g[: k - WINDOW + 1] == 0.0)
    h = 1e-5  # the solver's own error (~1e-10) over h, and h^2, both below 1e-4
    for c in range(2):
        e = jnp.zeros_like(stream.ys.y).at[j, c].set(h)
        fd = (depth(stream.ys.y + e) - depth(stream.ys.y - e)) / (2 * h)
        np.testing.assert_allclose(g[j, c], fd, rtol=1e-4)
    assert np.abs(g[j]).max() > 0.1  # the depth depends on the measurement
