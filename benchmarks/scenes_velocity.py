"""The velocity estimator of Chitrakaran et al. on scenes that are not the paper's, built
with `visjax.sim`; the paper's gains of eq. (63), depth from one known length, RMS error
per degree of freedom over the second half of each run. Prints JSON.

Scenes (fixed before any run; their full descriptions are in `visjax.sim`'s catalogue):

- `plate`: `visjax.sim.sinusoidal_plate_scene`, six irregular coplanar features on a 0.3 m
  plate 1.5 m away, sinusoidal twist on all six axes; 1 kHz; optional 5% dropouts.
- `spline`: `visjax.sim.spline_board_scene`, eight features on a 0.5 m board 2.5 m away
  through five key poses on a natural cubic spline; 1 kHz frames with 0.2 ms jitter.
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
    fixed_camera,
    lowpass,
    run,
    velocity_stream,
)
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63  # noqa: E402


def evaluate(name, scene, dt=None, filter_hz=None, **info):
    ts, pixels, A, body, s = (scene[k] for k in ("ts", "pixels", "A", "body", "features"))
    i, j = scene["known_pair"]
    L = jnp.linalg.norm(s[i] - s[j])
    camera = fixed_camera(pixels, A, body.R[0], s[0], known_length=(i, j, L), dropped="hold")
    stream = velocity_stream(ts, pixels, camera, dropped="hold")
    z1 = camera.z1_star
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
    plate, spline = sim.sinusoidal_plate_scene, sim.spline_board_scene
    rows = [
        evaluate("plate", plate(T), noise_px=0.0, dropout=0.0),
        evaluate("plate", plate(T, dropout=0.05), noise_px=0.0, dropout=0.05),
        evaluate("plate", plate(T, noise_px=0.1), noise_px=0.1, dropout=0.0),
        evaluate("plate", plate(T, noise_px=0.1), filter_hz=2.0, noise_px=0.1, dropout=0.0),
        evaluate("spline", spline(T), noise_px=0.0, dropout=0.0),
        evaluate("spline", spline(T, noise_px=0.1), filter_hz=2.0, noise_px=0.1, dropout=0.0),
        evaluate("slow camera", plate(T, rate_hz=100.0), dt=1e-3, noise_px=0.0, dropout=0.0),
    ]
    print(json.dumps({"duration_s": T, "order": "vx vy vz wx wy wz", "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
