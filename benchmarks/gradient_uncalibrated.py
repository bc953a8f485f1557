"""Reverse-mode gradients through the adaptive estimator of Nath, Dawson, Tatlicioglu,
*Euclidean position estimation of static features using a moving uncalibrated camera*:
memory for many gain settings over a long run. Prints JSON.

The loss is `papers.static_points_problem`'s (the worst final position error of the unknown
features, 0.1 px of pixel noise, the project's scene sampled and integrated at 1 kHz); its
gradient with respect to the two adaptation multipliers (`alpha`, `gamma`) is vmapped
over `--batch` gain settings (log-uniform in [0.5, 2]) and run, under `CheckpointAdjoint`
(one state stored per ~sqrt(steps) steps, each block recomputed).

Reported: XLA's buffer assignment of the compiled gradient (`memory_analysis()`, bytes) for
`CheckpointAdjoint` and, compiled only (its buffers would not fit), `DirectAdjoint`, their
ratio; the peak resident memory of this process while the checkpointed gradient runs
(`VmHWM`, see `_memory.py`), against the same process's peak after the forward run alone (the
reference measured in the same run); wall times; and whether every gradient is finite.

    python benchmarks/gradient_uncalibrated.py [--duration 30] [--batch 256]
"""

import argparse
import json
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from _memory import peak_rss_mb  # noqa: E402

import visjax  # noqa: E402
from visjax import papers  # noqa: E402
from visjax.estimators import CheckpointAdjoint, DirectAdjoint  # noqa: E402


def rss_mb():
    return peak_rss_mb()


def xla_bytes(compiled):
    stats = compiled.memory_analysis()
    if stats is None:
        return None
    return {
        "temp_size_in_bytes": int(stats.temp_size_in_bytes),
        "argument_size_in_bytes": int(stats.argument_size_in_bytes),
        "output_size_in_bytes": int(stats.output_size_in_bytes),
    }


def main():
    visjax.apply_xla_cpu_workarounds()  # as the command line does (jaxlib 0.10's CPU options)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="seconds at 1 kHz")
    parser.add_argument("--batch", type=int, default=256, help="gain settings vmapped")
    args = parser.parse_args()

    u = jax.random.uniform(jax.random.key(0), (2, args.batch), minval=-1.0, maxval=1.0)
    params = {"alpha_scale": 2.0 ** u[0], "gamma_scale": 2.0 ** u[1]}
    key = jax.random.key(7)
    out = {
        "benchmark": "gradient_memory_uncalibrated_estimator",
        "duration_s": args.duration,
        "rate_hz": 1000,
        "batch": args.batch,
        "dtype": "float64",
        "jax": jax.__version__,
    }

    def loss_fn(adjoint):
        setup = papers.static_points_problem(
            noise_px=0.1, duration=args.duration, rate_hz=1000.0, adjoint=adjoint
        )

        def loss(p):
            sol = setup.solve("estimator", setup.resolve(p), setup.inputs(key))
            return setup.metrics("estimator", sol)[setup.metric]

        return loss

    forward = jax.jit(jax.vmap(loss_fn(CheckpointAdjoint())))
    t0 = time.perf_counter()
    jax.block_until_ready(forward(params))
    out["forward_s_with_compile"] = time.perf_counter() - t0
    out["rss_after_forward_mb"] = rss_mb()

    for name, adjoint in (("direct", DirectAdjoint()), ("checkpoint", CheckpointAdjoint())):
        grad = jax.jit(jax.vmap(jax.grad(loss_fn(adjoint))))
        t0 = time.perf_counter()
        compiled = grad.lower(params).compile()
        out[f"{name}_compile_s"] = time.perf_counter() - t0
        out[f"{name}_xla"] = xla_bytes(compiled)
        if name == "checkpoint":
            t0 = time.perf_counter()
            g = jax.block_until_ready(compiled(params))
            out["checkpoint_run_s"] = time.perf_counter() - t0
            out["gradients_finite"] = bool(
                all(np.all(np.isfinite(np.asarray(v))) for v in g.values())
            )
            out["grad_alpha_median"] = float(np.median(np.asarray(g["alpha_scale"])))
    out["rss_peak_mb"] = rss_mb()
    out["rss_peak_over_forward"] = out["rss_peak_mb"] / out["rss_after_forward_mb"]
    d, c = out["direct_xla"], out["checkpoint_xla"]
    if d and c:
        out["temp_checkpoint_over_direct"] = c["temp_size_in_bytes"] / d["temp_size_in_bytes"]
        out["direct_temp_bytes_per_step_and_setting"] = d["temp_size_in_bytes"] / (
            args.batch * (round(args.duration * 1000) + 1)
        )
    out["target"] = {"rss_peak_mb": "< 4096 at 30 s and 256 settings"}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
