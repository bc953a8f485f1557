"""The velocity estimator of Chitrakaran et al. on a scene that is not the paper's: six
irregular coplanar features (origin off their plane), a skewed camera, a sinusoidal motion
on all six degrees of freedom, depth from one known length, and 5% feature dropouts."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import RESULTS
from visjax.estimators import (
    FixedCamera,
    SaveAt,
    VelocityEstimator,
    WindowRMS,
    fixed_camera,
    run,
    velocity_measurements,
    velocity_stream,
)
from visjax.geometry import euclidean_reconstruction, so3_exp
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63
from visjax.sim import (
    CameraRig,
    Sampler,
    intrinsics,
    object_points,
    planar_features,
    points_in_camera,
    sinusoidal_trajectory,
)

DURATION = 3.0
WINDOW = (1.5, 3.0)


def _scene(dropout, seed=0):
    s = planar_features(6, size=0.3, normal=(0.1, 0.2, 1.0), offset=0.04, seed=seed)
    R0 = so3_exp(jnp.array([np.pi, 0.0, 0.0])) @ so3_exp(jnp.array([0.2, -0.1, 0.3]))
    x0 = jnp.array([0.05, -0.03, 1.5])
    sampler = Sampler(rate_hz=1000.0, dropout=dropout)
    ts = sampler.times(DURATION)
    body = sinusoidal_trajectory(
        jnp.array([0.1, 0.08, 0.05, 0.3, 0.2, 0.25]),
        jnp.array([0.3, 0.2, 0.25, 0.15, 0.35, 0.2]),
        x0,
        R0,
        ts,
    )
    rig = CameraRig(
        A=intrinsics(900.0, cx=512.0, cy=384.0, skew_angle_deg=90.5), image_size=(1024, 768)
    )
    pixels, seen = sampler.record(
        rig, points_in_camera(rig, object_points(body, s)), jax.random.key(seed)
    )
    return ts, pixels, seen, rig, body, s


@pytest.fixture(scope="module")
def runs():
    out = {}
    for dropout in (0.0, 0.05):
        ts, pixels, seen, rig, body, s = _scene(dropout)
        L = jnp.linalg.norm(s[1] - s[3])
        camera = fixed_camera(
            pixels, rig.A, body.R[0], s[0], known_length=(1, 3, L), dropped="hold"
        )
        stream = velocity_stream(ts, pixels, camera, dropped="hold", truth=body.twist)
        z1 = camera.z1_star
        sol = run(
            VelocityEstimator(K=K_EQ63, rho=RHO_EQ63),
            stream,
            saveat=SaveAt(outputs=False),
            reducer=WindowRMS(*WINDOW, field="v_hat"),
        )
        out[dropout] = dict(
            sol=sol, z1=z1, z1_true=(body.x[0] + body.R[0] @ s[0])[2], seen=seen, stream=stream
        )
    return out


def test_known_length_depth_and_convergence(runs):
    r = runs[0.0]
    np.testing.assert_allclose(r["z1"], r["z1_true"], rtol=1e-9)
    assert r["sol"].result == RESULTS.successful
    rms = np.asarray(r["sol"].summary.rms)
    # the paper's gains on this scene: linear within 4 cm/s (v_z is the weakest), angular
    # within 1.5e-2 rad/s, against amplitudes 5-10 cm/s and 0.2-0.3 rad/s
    assert np.all(rms[:3] < 0.04) and np.all(rms[3:] < 0.015), rms


def test_five_percent_dropouts_same_accuracy_within_20_percent(runs):
    r = runs[0.05]
    seen = np.asarray(r["seen"])
    assert 0.04 < 1.0 - seen.mean() < 0.06  # 5% of the feature observations are missing
    assert (~seen.all(-1)).mean() > 0.2  # in about a quarter of the frames
    assert r["sol"].result == RESULTS.successful
    a = np.linalg.norm(np.asarray(runs[0.0]["sol"].summary.rms))
    b = np.linalg.norm(np.asarray(r["sol"].summary.rms))
    assert abs(b / a - 1.0) < 0.2, (a, b)
    np.testing.assert_allclose(r["z1"], runs[0.0]["z1"], rtol=1e-9)


def test_masked_homography_equals_the_homography_of_the_seen_features():
    ts, pixels, seen, rig, body, s = _scene(0.05)
    k = int(np.argmax(~np.asarray(seen).all(-1) & np.asarray(seen)[:, 0]))
    vis = seen[k]
    assert 4 <= int(vis.sum()) < 6
    idx = jnp.flatnonzero(vis, size=int(vis.sum()))
    full = jax.jit(lambda p, v: euclidean_reconstruction(pixels[0], p, rig.A, visible=v))(
        pixels[k], vis
    )
    sub = jax.jit(euclidean_reconstruction)(pixels[0][idx], pixels[k][idx], rig.A)
    np.testing.assert_allclose(full.H, sub.H, atol=1e-12)
    np.testing.assert_allclose(full.alpha[idx], sub.alpha, rtol=1e-12)
    # a missing feature 1: its pixel follows from the homography of the others
    p_cur = pixels[k].at[0].set(jnp.nan)
    vis1 = vis.at[0].set(False)
    n_star = full.n_star
    measure = jax.jit(
        lambda p, v: velocity_measurements(
            FixedCamera(pixels[0], rig.A, body.R[0], s[0], n_star, 1.5), p, visible=v
        )
    )
    m = measure(p_cur, vis1)
    ref = measure(pixels[k], vis1.at[0].set(True))
    np.testing.assert_allclose(m.e, ref.e, atol=1e-7)


def test_too_few_features_drop_the_frame_and_the_first_must_be_seen(no_jaxtyping):
    ts, pixels, seen, rig, body, s = _scene(0.0)
    bad = pixels.at[50, :3].set(jnp.nan)  # 3 of 6 left: frame 50 cannot be measured
    camera = fixed_camera(bad, rig.A, body.R[0], s[0], known_length=(1, 3, 0.2), dropped="hold")
    stream = velocity_stream(ts, bad, camera, dropped="hold", truth=body.twist)
    assert not bool(stream.present[50]) and bool(stream.present[51])
    with pytest.raises(ValueError, match="reference"):
        fixed_camera(
            pixels.at[0, 2].set(jnp.nan), rig.A, body.R[0], s[0], known_length=(1, 3, 0.2),
            dropped="hold",
        )  # fmt: skip
    with pytest.raises(ValueError, match="visible"):
        euclidean_reconstruction(pixels[0], pixels[1], rig.A, visible=jnp.ones(5, bool))


def test_consistent_frames_against_a_transcription():
    """`consistent_frames`: a frame is used when it sees the features in use; a new set
    is taken once seen in `settle` consecutive frames (a loop written out by hand)."""
    from visjax.estimators._velocity import consistent_frames

    rng = np.random.default_rng(3)
    visible = rng.random((300, 5)) > 0.1
    visible[150:, 2] = False  # feature 3 leaves the view for good
    measurable = rng.random(300) > 0.05
    measurable[0] = True
    for settle in (1, 4, 10):
        current, last, count, want = visible[0], visible[0], 0, []
        for vis, ok in zip(visible, measurable):
            count = count + 1 if np.array_equal(vis, last) else 1
            switch = ok and count >= settle
            want.append(bool(ok and (np.array_equal(vis, current) or switch)))
            current = vis if switch else current
            last = vis
        got = np.asarray(consistent_frames(visible, measurable, settle))
        np.testing.assert_array_equal(got, want)
    assert np.asarray(consistent_frames(visible, measurable, 10))[200:].any()  # switched


def test_a_missing_feature_does_not_change_the_features_behind_e(runs):
    """Issue 44: with pixel noise, the homography of 5 of 6 features differs from that of
    6, so a frame measured from a subset makes e jump and the sign-based law reads a
    velocity. Held instead (`settle` frames before a new set is used), 5% dropouts at
    0.01 px give the accuracy of the same noisy frames with none missing; measuring every
    frame from the features it sees (`settle=1`) is several times worse."""
    ts, pixels, seen, rig, body, s = _scene(0.05)
    noise = 0.01 * jax.random.normal(jax.random.key(7), pixels.shape)
    noisy = pixels + noise
    full = jnp.asarray(_scene(0.0)[1]) + noise
    camera = runs[0.05]["stream"].measure.camera
    est = VelocityEstimator(K=K_EQ63, rho=RHO_EQ63)

    def rms(frames, settle, dropped="hold"):
        stream = velocity_stream(
            ts, frames, camera, dropped=dropped, truth=body.twist, settle=settle
        )
        sol = run(
            est, stream, saveat=SaveAt(outputs=False), reducer=WindowRMS(*WINDOW, field="v_hat")
        )
        assert sol.result == RESULTS.successful
        return np.linalg.norm(np.asarray(sol.summary.rms))

    clean, held, mixed = rms(full, 10), rms(noisy, 10), rms(noisy, 1)
    assert abs(held / clean - 1.0) < 0.1, (held, clean)
    assert mixed > 2.0 * held, (mixed, held)


@pytest.mark.slow  # the unit tier's time: three 10 s runs (the innovation's unit tests: the
# moving-point estimator's, the homography problem's, the command line's)
def test_innovation_gates_a_lagging_estimator_without_the_truth(runs):
    """Issue 44 (item 1, without the truth): the estimator's output error e - e_hat against
    the noise its frames imply (`velocity_innovation`). The paper's gains track their
    measurements (ratio about 1 at 0.1 px, below 1 noise-free: the chatter floor); gains
    100 times smaller lag them (ratio past `INNOVATION_GATE`), and their velocity is
    indeed worse. `innovation` against a NumPy transcription."""
    from visjax.estimators import innovation, velocity_innovation
    from visjax.studies import INNOVATION_GATE

    ts, pixels, seen, rig, body, s = _scene(0.0)
    camera = runs[0.0]["stream"].measure.camera
    noisy = pixels + 0.1 * jax.random.normal(jax.random.key(3), pixels.shape)
    ratios = {}
    for name, frames, scale in [
        ("clean", pixels, 1.0),
        ("paper", noisy, 1.0),
        ("slow", noisy, 0.01),
    ]:
        stream = velocity_stream(ts, frames, camera)
        est = VelocityEstimator(K=jnp.asarray(K_EQ63) * scale, rho=jnp.asarray(RHO_EQ63) * scale)
        sol = run(est, stream, saveat=SaveAt(diagnostics=True))
        inn = velocity_innovation(stream, sol, est, t_start=WINDOW[0])
        ratios[name] = float(inn.ratio)
        late = np.asarray(ts) >= WINDOW[0]
        # the transcription: RMS of e_tilde over the window, noise from e's changes / sqrt 2
        e = np.asarray(stream.measured().ys.e)[late]
        e_tilde = np.asarray(sol.diagnostics.e_tilde)[late]
        noise = np.sqrt(np.mean(np.diff(e, axis=0) ** 2, axis=0) / 2)
        floor = 4 / np.pi * np.asarray(RHO_EQ63) * scale * 1e-3 / (np.asarray(K_EQ63) * scale + 1)
        want = np.max(np.sqrt(np.mean(e_tilde**2, axis=0)) / np.maximum(noise, floor))
        np.testing.assert_allclose(ratios[name], want, rtol=1e-9)
    assert ratios["clean"] < 1.0 and ratios["paper"] < 1.5, ratios
    assert ratios["slow"] > INNOVATION_GATE, ratios
    # pure JAX: jit, vmap, grad
    y = jax.random.normal(jax.random.key(0), (3, 50, 2))
    err = 0.5 * y
    batched = jax.jit(jax.vmap(innovation))(y, err)
    np.testing.assert_allclose(batched.ratio[1], innovation(y[1], err[1]).ratio, rtol=1e-12)
    g = jax.grad(lambda a: innovation(y[0], a * err[0]).ratio)(1.0)
    np.testing.assert_allclose(g, innovation(y[0], err[0]).ratio, rtol=1e-9)  # linear in a
