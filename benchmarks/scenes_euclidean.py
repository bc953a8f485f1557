"""The uncalibrated-camera structure estimator of Nath, Dawson, Tatlicioglu, *Euclidean
position estimation of static features using a moving uncalibrated camera*, on scenes that
are not the paper's (nor the project's). Prints a JSON table.

Each scene was fixed before any run, from its description (now in `visjax.sim`'s catalogue:
their docstrings give every parameter); the estimator is built with
`StaticPointsEstimator.from_nominal` from the nominal camera and the measurements only,
its gains derived by the documented rule (nothing tuned per scene). For each scene, noise-free
and with 0.5 px of pixel noise (seed 0): the final position error of each unknown feature
(mm) after the run, the recovered camera's errors, the final camera prediction error (px),
and the numbers that explain what limits the accuracy: the condition number of the camera
law's normalised information over a window (its one null direction, the common scale of the
camera parameters, left out) and the PE measure of eq. (49) per unknown feature.

- `tilted`: `visjax.sim.tilted_platform_scene`, a camera 27 deg down from a slow platform,
  its skewed intrinsics and 2 deg tilt unknown to the nominal camera; 1 kHz.
- `side`: `visjax.sim.side_looking_platform_scene`, a camera looking sideways from a slow
  ground vehicle at features 4-6 m away, logged at 100 Hz and integrated at 1 ms.

    python benchmarks/scenes_euclidean.py [--duration 40]
"""

import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

import visjax
from visjax.estimators import (
    SaveAt,
    StaticPointsEstimator,
    pe_measure,
    run,
    static_points_stream,
)
from visjax.geometry import camera_parameters, so3_log
from visjax.sim import add_pixel_noise, side_looking_platform_scene, tilted_platform_scene

DEG = np.pi / 180.0


def camera_conditioning(est, stream, window: float, every: int = 10) -> float:
    """The condition number of $\\sum D W_c^T\\Lambda^{-1} W_c D$ (eqs. (36), (39)) over the
    first `window` seconds (every `every`-th sample) at the estimator's initial camera (give
    it the true one), its smallest eigenvalue left out: the common scale of the camera
    parameters, a null direction by construction."""
    ts = np.asarray(stream.ts)
    k = int(np.searchsorted(ts, ts[0] + window))
    ys = jax.tree_util.tree_map(lambda x: x[:k:every], stream.ys)

    def info(y):
        _, W_c, _, _, _, depth_c, _ = est._signals(est.init(y), y)
        WD = W_c * est.D[None, :]
        return WD.T @ (WD / jnp.repeat(depth_c, 3)[:, None])

    ev = np.linalg.eigvalsh(np.asarray(jnp.sum(jax.vmap(info)(ys), 0)))
    return float(ev[-1] / ev[1])


def run_scene(sc: dict, noise_px: float, seed: int = 0) -> dict:
    p_s, p_c = sc["p_s"], sc["p_c"]
    if noise_px > 0:
        k1, k2 = jax.random.split(jax.random.key(seed))
        p_s, p_c = add_pixel_noise(k1, p_s, noise_px), add_pixel_noise(k2, p_c, noise_px)
    stream = static_points_stream(sc["ts"], sc["R_b"], sc["x_b"], p_s, p_c, sc["omega_c"])
    est = StaticPointsEstimator.from_nominal(stream, *sc["nominal"], dt=sc["dt"])
    steps_per_s = 1000
    t0 = time.perf_counter()
    sol = run(est, stream, dt=sc["dt"], saveat=SaveAt(every=steps_per_s, diagnostics=True))
    jax.block_until_ready(sol.final_state)
    wall = time.perf_counter() - t0
    out, d = sol.outputs, sol.diagnostics
    err = np.linalg.norm(np.asarray(out.omega_s[-1] - sc["omega_s"]), axis=-1)
    err0 = np.linalg.norm(np.asarray(out.omega_s[0] - sc["omega_s"]), axis=-1)
    R_err = so3_log(out.R_c[-1] @ sc["R_c"].T).omega
    pe = np.asarray(pe_measure(d.info_rate_s, sol.ts, 5.0))
    t1, t2 = camera_parameters(est.N @ sc["A"], sc["R_c"], sc["x_c"])
    true_est = StaticPointsEstimator(
        **{k: getattr(est, k) for k in ("alpha_c", "alpha", "eta0", "eta1", "gamma_s0", "D")},
        eps_c=est.eps_c,
        eps_s=est.eps_s,
        theta_c0=jnp.concatenate([t1, t2]),
        theta_s0=est.theta_s0,
        N=est.N,
    )
    return {
        "scene": sc["name"],
        "noise_px": noise_px,
        "duration_s": round(float(sc["ts"][-1] - sc["ts"][0]), 3),
        "initial_error_mm": [round(float(e) * 1000, 1) for e in err0],
        "final_error_mm": [round(float(e) * 1000, 3) for e in err],
        "camera_A_error_px": round(float(np.abs(np.asarray(out.A[-1] - sc["A"])).max()), 3),
        "camera_R_c_error_deg": round(float(np.linalg.norm(R_err)) / DEG, 4),
        "camera_x_c_error_mm": round(float(np.linalg.norm(out.x_c[-1] - sc["x_c"])) * 1000, 2),
        "final_camera_prediction_error_px": round(float(np.nanmax(d.p_tilde_c[-1])), 4),
        "camera_information_condition_10s_at_truth": round(
            camera_conditioning(true_est, stream, 10.0), 1
        ),
        "pe_measure_median": [round(float(v), 5) for v in np.nanmedian(pe, axis=0)],
        "gains": {
            k: float(getattr(est, k))
            for k in ("alpha_c", "alpha", "eta0", "eta1", "gamma_s0", "eps_c", "eps_s")
        },
        "wall_s_including_compile": round(wall, 2),
    }


def main():
    visjax.apply_xla_cpu_workarounds()  # as the command line does (jaxlib 0.10's CPU options)
    jax.config.update("jax_enable_x64", True)
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=40.0)
    args = parser.parse_args()
    rows = []
    for build in (tilted_platform_scene, side_looking_platform_scene):
        sc = build(args.duration)
        for noise in (0.0, 0.5):
            rows.append(run_scene(sc, noise))
    print(json.dumps({"benchmark": "euclidean_structure_scenes", "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
