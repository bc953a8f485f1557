"""The velocity estimator of Chitrakaran et al. on scenes that are not the paper's, built
with `visjax.sim`; the paper's gains of eq. (63), depth from one known length, RMS error
per degree of freedom over the second half of each run. Prints JSON.

Scenes (fixed before any run):

- `plate`: six irregular coplanar features on a 0.3 m plate (object origin 4 cm off the
  plate), 1.5 m away, a camera with a 90.5 degree pixel grid; sinusoidal twist on all six
  axes (0.05-0.1 m/s, 0.2-0.3 rad/s, 0.15-0.35 Hz); 1 kHz; optional 5% dropouts.
- `spline`: eight features on a 0.5 m board, 2.5 m away, passing through five key poses
  (a 0.4 m sweep with 25 degrees of turn) on a natural cubic spline; 1 kHz frames with
  0.2 ms jitter.
- `slow camera`: the plate at 100 Hz frames, the estimator integrated at 1 kHz on held
  frames (`run(..., dt=1e-3)`).

    python benchmarks/scenes_velocity.py [--duration 10]
"""

import argparse
import json

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

from visjax import RESULTS, sim  # noqa: E402
from visjax.estimators import (  # noqa: E402
    SaveAt,
    VelocityEstimator,
    fixed_camera_stream,
    lowpass,
    run,
)
from visjax.geometry import so3_exp  # noqa: E402
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63  # noqa: E402

FLIP = so3_exp(jnp.array([np.pi, 0.0, 0.0]))  # the object faces the camera


def plate(duration, rate_hz=1000.0, noise=0.0, dropout=0.0, seed=0):
    s = sim.planar_features(6, size=0.3, normal=(0.1, 0.2, 1.0), offset=0.04, seed=0)
    sampler = sim.Sampler(rate_hz=rate_hz, noise_px=noise, dropout=dropout)
    ts = sampler.times(duration)
    body = sim.sinusoidal_trajectory(
        jnp.array([0.1, 0.08, 0.05, 0.3, 0.2, 0.25]),
        jnp.array([0.3, 0.2, 0.25, 0.15, 0.35, 0.2]),
        jnp.array([0.05, -0.03, 1.5]),
        FLIP @ so3_exp(jnp.array([0.2, -0.1, 0.3])),
        ts,
    )
    rig = sim.CameraRig(
        A=sim.intrinsics(900.0, cx=512.0, cy=384.0, skew_angle_deg=90.5), image_size=(1024, 768)
    )
    key = jax.random.key(seed)
    pixels, _ = sampler.record(rig, sim.points_in_camera(rig, sim.object_points(body, s)), key)
    return ts, pixels, rig.A, body, s, (1, 3)


def spline(duration, noise=0.0, seed=0):
    s = sim.planar_features(8, size=0.5, normal=(0.0, 0.3, 1.0), offset=-0.05, seed=5)
    sampler = sim.Sampler(rate_hz=1000.0, jitter_s=2e-4, noise_px=noise)
    ts = sampler.times(duration, jax.random.key(seed + 100))
    knots = jnp.linspace(0.0, float(ts[-1]), 5)
    angles = jnp.deg2rad(jnp.array([0.0, 10.0, 25.0, 12.0, -5.0]))
    R_k = jnp.stack([FLIP @ so3_exp(jnp.array([0.3 * a, a, 0.5 * a])) for a in angles])
    x_k = jnp.array(
        [[-0.2, 0.0, 2.5], [-0.1, 0.05, 2.4], [0.0, 0.1, 2.6], [0.1, 0.0, 2.5], [0.2, -0.05, 2.45]]
    )
    body = sim.spline_trajectory(knots, R_k, x_k, ts)
    rig = sim.CameraRig(A=sim.intrinsics(1100.0, cx=640.0, cy=360.0), image_size=(1280, 720))
    key = jax.random.key(seed)
    pixels, _ = sampler.record(rig, sim.points_in_camera(rig, sim.object_points(body, s)), key)
    return ts, pixels, rig.A, body, s, (0, 5)


def evaluate(name, scene, dt=None, filter_hz=None, **info):
    ts, pixels, A, body, s, (i, j) = scene
    L = jnp.linalg.norm(s[i] - s[j])
    stream, n_star, z1 = fixed_camera_stream(
        ts, pixels, A, body.R[0], s[0], known_length=(i, j, L), dropouts=True
    )
    sol = run(VelocityEstimator(K=K_EQ63, rho=RHO_EQ63), stream, dt=dt, saveat=SaveAt())
    t = np.asarray(sol.ts)
    v = sol.outputs.v_hat
    if filter_hz is not None:
        v = lowpass(sol.ts, v, filter_hz)
    k = np.searchsorted(np.asarray(ts), t + 1e-9, side="right") - 1
    truth = np.asarray(body.twist)[k]
    half = t >= t[-1] / 2
    rms = np.sqrt(np.mean((np.asarray(v)[half] - truth[half]) ** 2, axis=0))
    z1_true = float((body.x[0] + body.R[0] @ s[0])[2])
    return {
        "scene": name,
        **info,
        "filter_hz": filter_hz,
        "successful": bool(sol.result == RESULTS.successful),
        "z1_star_rel_error": abs(float(z1) / z1_true - 1.0),
        "rms_last_half": [float(x) for x in rms],
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=10.0)
    T = p.parse_args(argv).duration
    rows = [
        evaluate("plate", plate(T), noise_px=0.0, dropout=0.0),
        evaluate("plate", plate(T, dropout=0.05), noise_px=0.0, dropout=0.05),
        evaluate("plate", plate(T, noise=0.1), noise_px=0.1, dropout=0.0),
        evaluate("plate", plate(T, noise=0.1), filter_hz=2.0, noise_px=0.1, dropout=0.0),
        evaluate("spline", spline(T), noise_px=0.0, dropout=0.0),
        evaluate("spline", spline(T, noise=0.1), filter_hz=2.0, noise_px=0.1, dropout=0.0),
        evaluate("slow camera", plate(T, rate_hz=100.0), dt=1e-3, noise_px=0.0, dropout=0.0),
    ]
    print(json.dumps({"duration_s": T, "order": "vx vy vz wx wy wz", "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
