"""The three estimation problems as comparisons: the paper's estimator, its batch
baselines (all frames, sliding window) and its EKF, on identical noisy inputs, from a
paper's scenario or from a user's data file (`visjax.io`). `studies.compare` runs them."""

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Problem:
    """A comparison set up for `studies.compare`.

    **Fields:** `name`; `methods` (name -> pure function of the inputs, returning a
    `Solution` with a result code); `inputs` (`key -> (inputs, truth)`, noise added to
    the pixels); `score` (`(method, solution, truth) -> dict` of the estimator's own
    accuracy keys, `None` for a failed run); `updates` (estimate updates per call, for the
    latency); `accuracy` (record -> the headline number of the figure) and its `label`;
    `settings` (every stated setting: gains, windows, bandwidths, noise models).
    """

    name: str
    methods: dict
    inputs: Any
    score: Any
    updates: dict
    accuracy: Any
    label: str
    settings: dict = field(default_factory=dict)


def structure_observer_for_data(data):
    """The unknown input observer of Jang's thesis for a `StructureData` file, and the
    camera velocities at the frame times.

    The camera velocities are interpolated (linearly) to the frame times; the observer's
    $A(u)$ is the thesis' matrix of the camera velocities (`THESIS_A_U`), and its gains
    are designed by `visjax.design.design_uio_for_motion` for the velocity range of the
    file (10% margin) and the measured velocities (up to the first 250 frames), with
    $D$ the file's unknown-input direction. The design takes $\\bar f = 0$ (Lipschitz
    bound 0): exact for a camera that translates parallel to its image plane and turns
    about its optical axis; other motion ($v_{cz}$, $\\omega_x$, $\\omega_y$) is returned
    as `unmodelled_motion`.

    **Returns:** `(observer, u, info)`: `u` (N, 6) the velocities at the frame times and
    `info` a dict (`depth_guess_m`, `D`, `design`, `unmodelled_motion`).
    """
    from ..design import design_uio_for_motion
    from ..estimators import UnknownInputObserver

    t = np.asarray(data.t, float)
    u = np.stack(
        [np.interp(t, data.camera_t, data.camera_velocity[:, j]) for j in range(6)], axis=1
    )
    lo, hi = u.min(axis=0), u.max(axis=0)
    mid, half_width = (lo + hi) / 2, (hi - lo) / 2
    u_range = (mid - 1.1 * half_width, mid + 1.1 * half_width)
    D = np.asarray(data.D, float) / np.linalg.norm(data.D)
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    frame_dt = float(np.median(np.diff(t)))
    design, rate = design_uio_for_motion(np.zeros((3, 3)), C, D, u_range, u[:250], frame_dt)
    depth_guess = 1.0 if data.depth_guess is None else float(data.depth_guess)
    observer = UnknownInputObserver(
        A=np.zeros((3, 3)), D=D, x3_guess=1.0 / depth_guess, **design.observer_fields()
    )
    info = {
        "depth_guess_m": depth_guess,
        "D": [float(x) for x in D],
        "design": {
            "method": "design_uio_for_motion",
            "alpha": float(design.alpha),
            "convergence_rate_per_s": float(rate),
        },
        "unmodelled_motion": float(np.max(np.abs(u[:, [2, 3, 4]]))),
    }
    return observer, u, info


def _noisy(key, pixels, noise_px):
    """The pixels plus i.i.d. Gaussian noise (sigma `noise_px`); NaN (not seen) stays NaN."""
    import jax.numpy as jnp

    from ..sim import add_pixel_noise

    if noise_px == 0:
        return jnp.asarray(pixels)
    return add_pixel_noise(key, jnp.asarray(pixels), noise_px)


def _held(sample_ts, values, t):
    """`values` (at `sample_ts`) held at the times `t`: the last sample at or before each."""
    k = np.searchsorted(np.asarray(sample_ts), np.asarray(t) + 1e-9, side="right") - 1
    return np.asarray(values)[np.clip(k, 0, len(sample_ts) - 1)]


def _last_half(t):
    t = np.asarray(t)
    return t >= t[0] + 0.5 * (t[-1] - t[0])


def _ok(sol) -> bool:
    from .._results import result_names

    return result_names(sol.result) == "successful"


def _rms_last_half(sol, field, truth_ts, truth, scale=1.0):
    """RMS per component over the second half of the run, of `sol.outputs.<field>` (times
    `scale`) against the truth held at the solution's times; `None` for a failed run."""
    if truth is None or not _ok(sol):
        return None
    t = np.asarray(sol.ts)
    est = np.asarray(getattr(sol.outputs, field)) * scale
    err = est - _held(truth_ts, truth, t)
    err = err[_last_half(t)]
    return [float(x) for x in np.sqrt(np.mean(err.reshape(err.shape[0], -1) ** 2, axis=0))]


def velocity_observer_bandwidth_hz(K) -> list[float]:
    """The -3 dB bandwidth per degree of freedom of the linear part of the velocity
    estimator of Chitrakaran et al. (eqs. (39)-(40) without the sign term): from $e$ to
    $\\hat\\kappa$ per axis, $\\hat\\kappa = s\\,T(s)\\,e$ with
    $T(s) = (k+1)(s+1)/(s^2 + (k+1)s + (k+1))$; the frequency where $|T| = 1/\\sqrt2$.
    (The sign term $\\rho\\,\\mathrm{sgn}(\\tilde e)$ adds gain at small errors, so this is
    the bandwidth for errors large against $\\rho/(k+1)$.)"""
    out = []
    w = np.geomspace(1e-4, 1e6, 400_001)
    for k in np.asarray(K, float):
        s = 1j * w
        T = (k + 1) * (s + 1) / (s**2 + (k + 1) * s + (k + 1))
        out.append(float(w[np.nonzero(np.abs(T) < 1 / np.sqrt(2))[0][0]] / (2 * np.pi)))
    return out


@dataclass(frozen=True)
class VelocitySource:
    """The inputs of the velocity problem: times, noise-free pixels, camera, reference
    gains, the once-measured $n^*$ and $z_1^*$, and where they came from."""

    ts: Any
    clean: Any
    A: Any
    R_star: Any
    s1: Any
    truth: Any
    K: Any
    rho: Any
    reference_pixels: Any
    dropouts: bool
    n_star: Any
    z1_star: Any
    source: str


def velocity_source(data, duration: float, rate_hz: float) -> VelocitySource:
    """The section-6 simulation of Chitrakaran et al. (`duration` at `rate_hz`) with the
    gains of eq. (63), or a `VelocityData` file with its gains (eq. (63) if none); $n^*$
    and $z_1^*$ measured once from the noise-free pixels (the calibration before a run)."""
    import jax.numpy as jnp

    from ..estimators import fixed_camera_stream
    from ..papers.chitrakaran import K_EQ63, RHO_EQ63, section6_scenario

    if data is None:
        sc = section6_scenario(duration, rate_hz)
        ts, clean, A, R_star, s1 = sc.ts, sc.pixels, sc.A, sc.R_star, sc.s[0]
        truth, known_length, p_ref, K, rho = sc.velocity, None, None, K_EQ63, RHO_EQ63
        source = f"section-6 simulation, {duration:g} s at {rate_hz:g} Hz"
    else:
        from ..io import VelocityData

        d = VelocityData.load(data)
        ts, clean, A, R_star, s1 = (
            jnp.asarray(x, float) for x in (d.t, d.pixels, d.A, d.R_star, d.s1)
        )
        truth, known_length = d.velocity, d.length
        p_ref = None if d.reference_pixels is None else jnp.asarray(d.reference_pixels)
        K = K_EQ63 if d.K is None else d.K
        rho = RHO_EQ63 if d.rho is None else d.rho
        source = str(data)
    dropouts = bool(np.any(~np.isfinite(np.asarray(clean))))
    _, n_star, z1_star = fixed_camera_stream(
        ts,
        clean,
        A,
        R_star,
        s1,
        known_length=known_length,
        reference_pixels=p_ref,
        dropouts=dropouts,
    )
    return VelocitySource(
        ts, clean, A, R_star, s1, truth, K, rho, p_ref, dropouts, n_star, z1_star, source
    )


def velocity_problem(
    *,
    data=None,
    noise_px: float = 0.1,
    duration: float = 10.0,
    rate_hz: float = 1000.0,
    max_jerk: float | None = None,
) -> Problem:
    """The velocity problem of Chitrakaran et al.: the sign-based estimator (eqs. (39)-(40),
    the gains of eq. (63) or the file's), the local least-squares fit of the pose
    trajectory (`batch`: centred, all frames around $t$; `batch_window`: causal) at the
    estimator's own bandwidth per degree of freedom (`velocity_observer_bandwidth_hz`),
    and the constant-acceleration EKF (`velocity_ekf`), on the section-6 simulation
    (`duration`, `rate_hz`) or a `VelocityData` file, with `noise_px` of Gaussian pixel
    noise added per seed.

    Stated settings: $n^*$ and $z_1^*$ are measured once from the noise-free pixels (the
    calibration before the run; for a file, from its pixels) and shared by every method;
    the EKF assumes the pixel noise `r_px = max(noise_px, 0.05)` and the largest jerk
    `max_jerk` (default: 0.2 m/s^3 and rad/s^3 for the paper's scenario, whose velocity is
    0.2 sin t; 1.0 for a file).
    """
    import jax.numpy as jnp

    from .._results import RESULTS, first_failure
    from ..baselines import frame_poses, velocity_ekf, velocity_smoother
    from ..estimators import VelocityEstimator, fixed_camera_stream, run

    v = velocity_source(data, duration, rate_hz)
    ts, clean, A, R_star, s1, truth = v.ts, v.clean, v.A, v.R_star, v.s1, v.truth
    p_ref_given, K, rho, dropouts = v.reference_pixels, v.K, v.rho, v.dropouts
    n_star, z1_star, source = v.n_star, v.z1_star, v.source
    jerk = (0.2 if data is None else 1.0) if max_jerk is None else max_jerk
    bandwidths = velocity_observer_bandwidth_hz(K)
    sample_interval = float(np.median(np.diff(np.asarray(ts))))
    estimator = VelocityEstimator(K=K, rho=rho)
    r_px = max(noise_px, 0.05)

    def constants(d):
        return (d["pixels"], A, R_star, s1, n_star, z1_star)

    def estimate(d):
        stream, _, _ = fixed_camera_stream(
            ts,
            d["pixels"],
            A,
            R_star,
            s1,
            n_star=n_star,
            z1_star=z1_star,
            reference_pixels=p_ref_given,
            dropouts=dropouts,
            throw=False,
        )
        return run(estimator, stream, throw=False)

    def fit(causal):
        def method(d):
            args = constants(d)
            poses = frame_poses(*args, reference_pixels=p_ref_given)
            sols = {
                bw: velocity_smoother(
                    ts,
                    *args,
                    bandwidth_hz=bw,
                    causal=causal,
                    sample_interval=sample_interval,
                    reference_pixels=p_ref_given,
                    poses=poses,
                    throw=False,
                )
                for bw in sorted(set(bandwidths))
            }
            # each degree of freedom from the fit at its own bandwidth
            v_hat, v_object = (
                jnp.stack(
                    [getattr(sols[bw].outputs, f)[:, i] for i, bw in enumerate(bandwidths)], 1
                )
                for f in ("v_hat", "v_object")
            )
            result, failed = RESULTS.successful, jnp.array(-1)
            for sol in sols.values():  # the first failure of any of the fits
                result, failed = first_failure(result, failed, sol.result, sol.failed_sample)
            return _with_velocity(sols[bandwidths[0]], v_hat, v_object, result, failed)

        return method

    def ekf(d):
        return velocity_ekf(
            ts,
            *constants(d),
            r_px=r_px,
            max_jerk=jerk,
            max_angular_jerk=jerk,
            reference_pixels=p_ref_given,
            throw=False,
        )

    def inputs(key):
        return {"pixels": _noisy(key, clean, noise_px)}, truth

    def score(name, sol, truth):
        return {"rms_last_half": _rms_last_half(sol, "v_hat", ts, truth)}

    n = int(np.asarray(ts).shape[0])
    return Problem(
        name=f"velocity (Chitrakaran et al.), {source}",
        methods={"estimator": estimate, "batch": fit(False), "batch_window": fit(True), "ekf": ekf},
        inputs=inputs,
        score=score,
        updates={"estimator": n, "batch": 1, "batch_window": n, "ekf": n},
        accuracy=lambda r: max(r["rms_last_half"]) if r["rms_last_half"] else float("nan"),
        label="worst-axis RMS, last half (m/s, rad/s)",
        settings={
            "source": source,
            "K": [float(k) for k in np.asarray(K)],
            "rho": [float(r) for r in np.asarray(rho)],
            "estimator_bandwidth_hz": bandwidths,
            "fit_bandwidth_hz": bandwidths,
            "fit_degree": 2,
            "ekf_r_px": r_px,
            "ekf_max_jerk": jerk,
            "n_star": [float(x) for x in np.asarray(n_star)],
            "z1_star": float(z1_star),
            "constants_from": "the noise-free pixels (calibration), shared by all methods",
            "latency": "batch: one fit over all frames per call; others: per sample",
        },
    )


def _with_velocity(sol, v_hat, v_object, result, failed):
    """`sol` with new velocity outputs, result and failed sample."""
    import equinox as eqx

    return eqx.tree_at(
        lambda s: (s.outputs.v_hat, s.outputs.v_object, s.result, s.failed_sample),
        sol,
        (v_hat, v_object, result, failed),
    )


def euclidean_source(data, duration: float, rate_hz: float):
    """The inputs of the uncalibrated structure problem of Nath et al.: the project's scene
    (`papers.nath.scenario`, `duration` at `rate_hz`, the nominal camera of
    `nath.nominal_camera`) or a `EuclideanData` file.

    **Returns:** `(ts, R_b, x_b, omega_c, pixels, n_known, truth, nominal, source)`: the
    noise-free pixels with the known features first, `truth` the unknown features' world
    positions (`None` if the file has none), `nominal` `(A, R_c, x_c)`."""
    import jax.numpy as jnp

    from ..papers import nath

    if data is None:
        sc = nath.scenario(duration, rate_hz)
        pixels = jnp.concatenate([sc.p_c, sc.p_s], axis=1)
        source = f"the project's scene, {duration:g} s at {rate_hz:g} Hz"
        return (
            sc.ts,
            sc.R_b,
            sc.x_b,
            sc.omega_c,
            pixels,
            sc.p_c.shape[1],
            sc.omega_s,
            nath.nominal_camera(),
            source,
        )
    from ..io import EuclideanData

    d = EuclideanData.load(data)
    ts, R_b, x_b, omega_c = (
        jnp.asarray(x, float) for x in (d.t, d.platform_R, d.platform_x, d.known_features)
    )
    truth = None if d.features is None else jnp.asarray(d.features, float)
    nominal = (d.A_nominal, d.R_c_nominal, d.x_c_nominal)
    return ts, R_b, x_b, omega_c, jnp.asarray(d.pixels, float), d.n_known, truth, nominal, str(data)


def euclidean_problem(
    *,
    data=None,
    noise_px: float = 0.1,
    duration: float = 20.0,
    rate_hz: float = 100.0,
    window_s: float = 2.0,
    every_s: float = 1.0,
) -> Problem:
    """The uncalibrated structure problem of Nath et al.: the adaptive least-squares
    estimator (eqs. (37)-(51), `from_nominal`: gains from the scene's scale, initial
    guesses from the nominal camera; integrated at 1 kHz on the held samples), bundle
    adjustment over all frames (`batch`) and over the last `window_s` seconds every
    `every_s` seconds (`batch_window`, causal), and the EKF (`euclidean_ekf`), all from
    the same initial guesses, on the project's scene (`papers.nath.scenario`, `duration`
    at `rate_hz`) or a `EuclideanData` file, with `noise_px` of pixel noise per seed. The
    EKF assumes the pixel noise `r_px = max(noise_px, 0.05)`; its prior spreads are those
    of `euclidean_ekf` (a nominal camera's uncertainty).
    """

    from ..baselines import bundle_adjustment, euclidean_ekf
    from ..estimators import (
        AdaptiveStructureEstimator,
        SaveAt,
        Stream,
        integration_step,
        platform_stream,
        run,
    )

    ts, R_b, x_b, omega_c, clean, k, truth, nominal, source = euclidean_source(
        data, duration, rate_hz
    )
    interval = float(np.max(np.diff(np.asarray(ts))))
    # 1 kHz on held samples; `from_nominal` derives its gains for that step (no bound here)
    dt = integration_step(Stream(ts=ts, ys=ts), max_step=1e-3)
    every_out = max(1, int(round(interval / (dt or interval))))
    window = max(2, int(round(window_s / interval)))
    every = max(1, int(round(every_s / interval)))
    r_px = max(noise_px, 0.05)

    def stream_of(pixels):
        return platform_stream(ts, R_b, x_b, pixels[:, k:], pixels[:, :k], omega_c)

    # the inputs carry the measurements; the times stay concrete (closed over), as the
    # runner's integration grid needs them
    def estimate(d):
        stream = Stream(ts=ts, ys=d["ys"])
        return run(d["estimator"], stream, dt=dt, saveat=SaveAt(every=every_out), throw=False)

    def batch(d):
        stream = Stream(ts=ts, ys=d["ys"])
        return bundle_adjustment(d["estimator"], stream, omega_c, throw=False)

    def batch_window(d):
        stream = Stream(ts=ts, ys=d["ys"])
        return bundle_adjustment(
            d["estimator"], stream, omega_c, window=window, every=every, throw=False
        )

    def ekf(d):
        stream = Stream(ts=ts, ys=d["ys"])
        return euclidean_ekf(d["estimator"], stream, omega_c, r_px=r_px, throw=False)

    def inputs(key):
        stream = stream_of(_noisy(key, clean, noise_px))
        estimator = AdaptiveStructureEstimator.from_nominal(stream, *nominal, dt=dt)
        return {"ys": stream.ys, "estimator": estimator}, truth

    def score(name, sol, truth):
        if truth is None or not _ok(sol):
            return {"final_position_error_m": None}
        err = np.linalg.norm(np.asarray(sol.outputs.omega_s[-1]) - np.asarray(truth), axis=-1)
        return {"final_position_error_m": [float(e) for e in err]}

    n = int(np.asarray(ts).shape[0])
    return Problem(
        name=f"uncalibrated structure (Nath et al.), {source}",
        methods={"estimator": estimate, "batch": batch, "batch_window": batch_window, "ekf": ekf},
        inputs=inputs,
        score=score,
        updates={"estimator": n, "batch": 1, "batch_window": -(-n // every), "ekf": n},
        accuracy=lambda r: (
            max(r["final_position_error_m"]) if r["final_position_error_m"] else float("nan")
        ),
        label="worst final position error (m)",
        settings={
            "source": source,
            "estimator": "from_nominal (gains from the scene's scale), 1 kHz on held samples",
            "integration_step_s": dt,
            "window_frames": window,
            "window_every_frames": every,
            "ekf_r_px": r_px,
            "latency": "batch: one fit over all frames per call; batch_window: per fit; "
            "others: per sample",
        },
    )


def structure_problem(
    *,
    data=None,
    noise_px: float = 0.1,
    duration: float = 20.0,
    set_name: str = "I.1",
    window_s: float = 1.0,
) -> Problem:
    """The moving-camera point of Jang's thesis: the unknown input observer (eq. (3.5),
    the thesis' gains for a set, or `structure_observer_for_data` for a file; 1 kHz on the
    held 30 Hz frames), triangulation over all frames up to $t$ (`batch`) and over the
    last `window_s` seconds (`batch_window`), both causal, with a static point model for
    a static set and a constant-velocity one for a moving set, and the inverse-depth EKF
    (`uio_ekf`, predicted at 1 ms), on the simulated analogue of a thesis set or a
    `StructureData` file, with `noise_px` of pixel noise per seed.

    Default: set I.1 (a static point). On the moving sets the camera's velocity is
    constant, and then the depth of a point moving in 3-D is not determined by the images
    (the family $(\\lambda P_0, \\lambda V + (1-\\lambda)v_c)$ fits them all): the
    triangulation reports `singular`; the observer resolves it with what it knows of the
    unknown input's direction $D$ (eq. (3.1)).

    EKF settings (the documented rule): `r_norm` = max(noise_px, 0.05) px over the focal
    length; the depth prior the observer's own guess with a 50% standard deviation; for a
    moving point, the velocity prior 2 units/s and the random walk of the acceleration
    1 unit/s^2 (q = 1 x the frame interval); for a static point, zero.
    """
    import jax.numpy as jnp

    from ..baselines import triangulate_point, uio_ekf
    from ..estimators import SaveAt, Stream, moving_camera_stream, run

    if data is None:
        from ..papers import jang

        if set_name not in jang.SETS:
            raise ValueError(f"unknown set {set_name!r}; choose from {list(jang.SETS)}.")
        sc = jang.scenario(set_name, duration)
        frame_ts, clean, u = sc.frame_ts, sc.frame_pixels, sc.frame_velocities
        K_c, observer = sc.Kc_observer, jang.observer(set_name)
        truth_ts, truth, to_m = sc.ts, sc.position, 0.01  # the thesis' units: cm
        moving = jang.SETS[set_name].moving
        source = f"thesis set {set_name} (simulated), {duration:g} s"
    else:
        from ..io import StructureData

        d = StructureData.load(data)
        observer, u, _ = structure_observer_for_data(d)
        frame_ts, clean, K_c = (jnp.asarray(x, float) for x in (d.t, d.pixels, d.A))
        u = jnp.asarray(u)
        truth_ts, truth, to_m, moving = frame_ts, d.position, 1.0, True
        source = str(data)
    n = int(frame_ts.shape[0])
    interval = float(np.median(np.diff(np.asarray(frame_ts))))
    window = max(2, int(round(window_s / interval)))
    substeps = max(1, int(round(interval / 1e-3)))
    order = 1 if moving else 0
    focal = float(np.asarray(K_c)[0, 0])
    r_norm = max(noise_px, 0.05) / focal
    depth0 = float(1.0 / observer.x3_guess)
    every = max(1, int(round(0.01 / 1e-3)))

    def stream_of(ys):
        return Stream(ts=frame_ts, ys=ys)

    def estimate(d):
        return run(observer, stream_of(d["ys"]), dt=1e-3, saveat=SaveAt(every=every), throw=False)

    def fit(w):
        def method(d):
            return triangulate_point(stream_of(d["ys"]), window=w, order=order, throw=False)

        return method

    def ekf(d):
        return uio_ekf(
            stream_of(d["ys"]),
            r_norm=r_norm,
            depth0=depth0,
            sigma_depth0=0.5 * depth0,
            q_velocity=interval if moving else 0.0,
            sigma_velocity0=2.0 if moving else 0.0,
            substeps=substeps,
            throw=False,
        )

    def inputs(key):
        pixels = _noisy(key, clean, noise_px)
        ys = moving_camera_stream(frame_ts, pixels, u, K_c, dropped="extrapolate").ys
        return {"ys": ys}, truth

    def score(name, sol, truth):
        return {"rms_last_half": _rms_last_half(sol, "position", truth_ts, truth, to_m)}

    return Problem(
        name=f"moving-camera point (Jang's thesis), {source}",
        methods={"estimator": estimate, "batch": fit(n), "batch_window": fit(window), "ekf": ekf},
        inputs=inputs,
        score=score,
        updates={"estimator": n, "batch": n, "batch_window": n, "ekf": n},
        accuracy=lambda r: max(r["rms_last_half"]) if r["rms_last_half"] else float("nan"),
        label="worst-axis RMS position, last half (m)",
        settings={
            "source": source,
            "observer_step_s": 1e-3,
            "point_model": "constant velocity" if moving else "static",
            "batch": "all frames up to t (causal)",
            "window_frames": window,
            "ekf_r_norm": r_norm,
            "ekf_depth0": depth0,
            "ekf_substeps": substeps,
            "latency": "per frame for every method (the batch fit re-solves each frame)",
        },
    )
