"""What pixel noise does to the velocity estimator of Chitrakaran et al., and what helps.

For the paper's section-6 simulation and for a scene that is not the paper's (six irregular
coplanar features, `examples/make_example_data.py`), at several pixel noise levels and 4
noise seeds each: the worst-axis RMS error over the second half of the run (linear m/s,
angular rad/s), (a) with the paper's gains of eq. (63), (b) the same estimate through the
causal low-pass filter `visjax.estimators.lowpass` at several bandwidths (its delay
stated), (c) with the gains scaled down. The grids are fixed in advance (no value chosen
to match anything); prints JSON (docs/papers/velocity.md).

    python benchmarks/velocity_noise.py [--duration 10] [--seeds 4]
"""

import argparse
import json
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).parents[1] / "examples"))
from make_example_data import velocity_example  # noqa: E402

import visjax  # noqa: E402
from visjax import RESULTS  # noqa: E402
from visjax.estimators import (  # noqa: E402
    VelocityEstimator,
    fixed_camera,
    lowpass,
    lowpass_delay,
    run,
    velocity_stream,
)
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63, section6_scenario  # noqa: E402

NOISE = (0.0, 0.1, 0.5)
FILTERS_HZ = (1.0, 2.0, 5.0)
GAIN_SCALES = ((1.0, 1.0), (0.1, 0.1), (0.01, 0.1))  # (K x, rho x)


def _scenes(duration):
    sc = section6_scenario(duration)
    yield (
        "paper section 6 (4 features, square)",
        dict(
            ts=sc.ts,
            clean=sc.pixels,
            A=sc.A,
            R_star=sc.R_star,
            s1=sc.s[0],
            truth=sc.velocity,
            known_length=(0, 2, float(jnp.linalg.norm(sc.s[0] - sc.s[2]))),
        ),
    )
    ex = velocity_example(duration)
    # the example's pixels carry noise and dropouts; rebuild them clean here
    ex_clean = velocity_example_clean(duration)
    yield (
        "plate, 6 irregular features, skewed camera",
        dict(
            ts=jnp.asarray(ex.t),
            clean=ex_clean,
            A=jnp.asarray(ex.A),
            R_star=jnp.asarray(ex.R_star),
            s1=jnp.asarray(ex.s1),
            truth=jnp.asarray(ex.velocity),
            known_length=(1, 3, float(ex.known_length[2])),
        ),
    )


def velocity_example_clean(duration):
    from visjax import sim
    from visjax.geometry import so3_exp

    s = sim.planar_features(6, size=0.3, normal=(0.1, 0.2, 1.0), offset=0.04, seed=0)
    R0 = so3_exp(jnp.array([np.pi, 0.0, 0.0])) @ so3_exp(jnp.array([0.2, -0.1, 0.3]))
    ts = sim.Sampler(rate_hz=1000.0).times(duration)
    body = sim.sinusoidal_trajectory(
        jnp.array([0.1, 0.08, 0.05, 0.3, 0.2, 0.25]),
        jnp.array([0.3, 0.2, 0.25, 0.15, 0.35, 0.2]),
        jnp.array([0.05, -0.03, 1.5]),
        R0,
        ts,
    )
    rig = sim.CameraRig(
        A=sim.intrinsics(900.0, cx=512.0, cy=384.0, skew_angle_deg=90.5), image_size=(1024, 768)
    )
    return sim.view(rig, sim.points_in_camera(rig, sim.object_points(body, s)))


def study(duration: float, seeds: int) -> dict:
    rows = []
    for name, sc in _scenes(duration):
        camera = fixed_camera(
            sc["clean"], sc["A"], sc["R_star"], sc["s1"], known_length=sc["known_length"]
        )
        n_star, z1_star = camera.n_star, camera.z1_star
        half = np.asarray(sc["ts"]) >= duration / 2

        @jax.jit
        def estimates(key, sigma, K, rho, sc=sc, n_star=n_star, z1_star=z1_star):
            pixels = sc["clean"] + sigma * jax.random.normal(key, sc["clean"].shape)
            camera = fixed_camera(
                pixels, sc["A"], sc["R_star"], sc["s1"], n_star=n_star, z1_star=z1_star
            )
            stream = velocity_stream(sc["ts"], pixels, camera)
            sol = run(VelocityEstimator(K=K, rho=rho), stream, throw=False)
            return sol.outputs.v_hat, sol.result

        keys = jax.random.split(jax.random.key(1), seeds)
        for sigma in NOISE:
            for ks, rs in GAIN_SCALES:
                K = jnp.asarray(K_EQ63) * ks
                rho = jnp.asarray(RHO_EQ63) * rs
                v_hat, result = jax.vmap(estimates, in_axes=(0, None, None, None))(
                    keys, jnp.asarray(sigma), K, rho
                )
                ok = bool(jnp.all(result == RESULTS.successful))
                variants = [("none", v_hat)]
                if (ks, rs) == (1.0, 1.0):
                    variants += [
                        (f"{f:g} Hz", jax.vmap(lambda v, f=f: lowpass(sc["ts"], v, f))(v_hat))
                        for f in FILTERS_HZ
                    ]
                for label, v in variants:
                    err = np.asarray(v)[:, half] - np.asarray(sc["truth"])[None, half]
                    rms = np.sqrt(np.mean(err**2, axis=1))  # (seeds, 6)
                    worst = rms.reshape(seeds, 2, 3).max(axis=2)  # linear, angular
                    rows.append(
                        {
                            "scene": name,
                            "noise_px": sigma,
                            "K_scale": ks,
                            "rho_scale": rs,
                            "filter": label,
                            "filter_delay_s": None
                            if label == "none"
                            else lowpass_delay(float(label.split()[0])),
                            "successful": ok,
                            "worst_linear_rms_mps_mean": float(worst[:, 0].mean()),
                            "worst_linear_rms_mps_max": float(worst[:, 0].max()),
                            "worst_angular_rms_radps_mean": float(worst[:, 1].mean()),
                            "worst_angular_rms_radps_max": float(worst[:, 1].max()),
                        }
                    )
    return {"duration_s": duration, "seeds": seeds, "rows": rows}


def main(argv=None):
    visjax.apply_xla_cpu_workarounds()  # as the command line does (jaxlib 0.10's CPU options)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=10.0)
    p.add_argument("--seeds", type=int, default=4)
    a = p.parse_args(argv)
    print(json.dumps(study(a.duration, a.seeds), indent=1))


if __name__ == "__main__":
    main()
