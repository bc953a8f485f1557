import jax.numpy as jnp
import numpy as np
import pytest

from visjax.geometry import so3_exp
from visjax.papers.chitrakaran import section6_scenario as fixed_camera_scenario


def test_section6_pose_matches_closed_form():
    """For eq. (59) the pose has a closed form; the 8th-order solve reproduces it."""
    sc = fixed_camera_scenario(10.0, 100.0)
    t = np.asarray(sc.ts)
    c = 0.2 * (1.0 - np.cos(t))
    np.testing.assert_allclose(sc.x_f, np.asarray(sc.x_f_star) + c[:, None] * np.ones(3), atol=1e-9)
    R = np.stack([np.asarray(so3_exp(jnp.full(3, ci))) @ np.asarray(sc.R_star) for ci in c])
    np.testing.assert_allclose(sc.R, R, atol=1e-9)
    np.testing.assert_allclose(sc.velocity[:, 0], 0.2 * np.sin(t), rtol=1e-14)
    # z1* = (x_f* + R* s1)_z = 2 - 0.01 from the image-independent geometry
    np.testing.assert_allclose(sc.z1_star, 1.99, rtol=1e-15)
    # four coplanar features, the object origin on their plane
    normal = np.cross(sc.s[0], sc.s[1])
    np.testing.assert_allclose(np.asarray(sc.s) @ normal, 0.0, atol=1e-15)


def test_noise_and_errors():
    with pytest.raises(ValueError, match="key"):
        fixed_camera_scenario(0.01, 1000.0, noise_px=1.0)
    with pytest.raises(ValueError, match="at least 2 samples"):
        fixed_camera_scenario(0.0001, 1000.0)


def test_the_trivial_estimate_is_zero_velocity():
    """`VelocityProblem.trivial()` (issue 44's quality check): the RMS of the true
    velocity over the scoring window, the error of answering zero (a NumPy transcription)."""
    from visjax import papers

    p = papers.velocity_problem(noise_px=0.5, duration=0.2)  # the smoother tests' problem
    got = p.trivial()
    ts, truth = np.asarray(p.ts), np.asarray(p.truth)
    a, b = (float(ts[0]) + w for w in p.window)
    inside = (ts >= a) & (ts < b + 1e-9)
    want = np.sqrt(np.mean(truth[inside] ** 2, axis=0))
    np.testing.assert_allclose(np.asarray(got["rms"]), want, rtol=1e-12)
    assert float(got["rms_worst"]) == pytest.approx(want.max(), rel=1e-12)
    assert p.trivial_label == "zero velocity"
