"""Reverse-mode gradient memory through `visjax.estimators.run`: DirectAdjoint vs
CheckpointAdjoint. Prints JSON.

The velocity estimator of Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving
object's velocity with a fixed camera*, on the paper's section-6 scenario at 1 kHz. The loss
is the sum over the six degrees of freedom of the windowed RMS velocity error
(`WindowRMS(a, b, field="v_hat")`, the paper's 5-10 s window shrunk into shorter runs),
reduced in the loop (nothing saved per step); its gradient with respect to the gain `K` is
taken with `jax.grad`, once per adjoint, for each duration.

Memory is XLA's own buffer assignment of the compiled gradient,
`jax.jit(jax.grad(loss)).lower(K, stream).compile().memory_analysis()`: `temp_size_in_bytes`
(the intermediates, where the stored trajectory lives), with argument and output sizes (the
measurement stream is an argument, not a constant folded into the program) and their sum
`total_bytes`; the ratios checkpoint/direct are of `temp_size_in_bytes` and `total_bytes`
(`peak_memory_in_bytes` is reported as the backend gives it, not compared). For reference,
`forward_only` is the same measure of the loss without its gradient: the runner's own
per-sample bookkeeping, which no adjoint removes. The gradients
of the two adjoints must agree (same arithmetic, recomputed): their max relative difference
is reported, and the script exits with status 1 if it exceeds `--rtol`. With `--batch B > 1`
the gradient is vmapped over B gain settings (the paper's gains, then random perturbations).

    python benchmarks/gradient_memory.py [--durations "1 3 10 30"] [--batch 1]
"""

import argparse
import functools
import json
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import visjax  # noqa: E402
from visjax.estimators import (  # noqa: E402
    CheckpointAdjoint,
    DirectAdjoint,
    SaveAt,
    VelocityEstimator,
    WindowRMS,
    fixed_camera,
    run,
    velocity_stream,
)
from visjax.papers import chitrakaran  # noqa: E402

RATE_HZ = 1000.0
ADJOINTS = {"direct": DirectAdjoint(), "checkpoint": CheckpointAdjoint()}
MEMORY_FIELDS = (
    "temp_size_in_bytes",
    "argument_size_in_bytes",
    "output_size_in_bytes",
    "alias_size_in_bytes",
    "generated_code_size_in_bytes",
    "peak_memory_in_bytes",
)


def memory(compiled) -> dict:
    """The fields of `memory_analysis()` this backend reports (ints), `{}` if none."""
    stats = compiled.memory_analysis()
    if stats is None:
        return {}
    out = {}
    for name in MEMORY_FIELDS:
        value = getattr(stats, name, None)
        if value is not None:
            out[name] = int(value)
    parts = ("temp_size_in_bytes", "argument_size_in_bytes", "output_size_in_bytes")
    if all(p in out for p in parts):
        # what the executable holds at once, at most: its buffers, less the aliased ones
        out["total_bytes"] = sum(out[p] for p in parts) - out.get("alias_size_in_bytes", 0)
    return out


def gains(batch: int):
    """The paper's K (eq. (63)); for a batch, it and `batch - 1` perturbations of it."""
    K = jnp.asarray(chitrakaran.K_EQ63)
    if batch == 1:
        return K
    noise = jax.random.normal(jax.random.key(0), (batch - 1, K.shape[0]))
    return jnp.concatenate([K[None], K * jnp.exp(0.2 * noise)])


def one_duration(duration: float, batch: int) -> dict:
    sc = chitrakaran.section6_scenario(duration, RATE_HZ)
    camera = fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0])
    stream = velocity_stream(sc.ts, sc.pixels, camera, truth=sc.velocity)
    a, b = chitrakaran.window(duration)
    reducer = WindowRMS(a, b, field="v_hat")
    rho = jnp.asarray(chitrakaran.RHO_EQ63)
    K = gains(batch)
    stream_bytes = sum(x.nbytes for x in jax.tree_util.tree_leaves(stream))

    out = {
        "duration_s": duration,
        "steps": int(sc.ts.shape[0]),
        "window_s": [a, b],
        "stream_bytes": int(stream_bytes),
    }

    def loss(K, stream, adjoint=DirectAdjoint()):
        sol = run(
            VelocityEstimator(K=K, rho=rho),
            stream,
            saveat=SaveAt(outputs=False),
            reducer=reducer,
            adjoint=adjoint,
        )
        return jnp.sum(sol.summary.rms)

    # the loss alone, no gradient: what the run itself holds (the baseline)
    forward = jax.vmap(loss, in_axes=(0, None)) if batch > 1 else loss
    out["forward_only"] = {"memory": memory(jax.jit(forward).lower(K, stream).compile())}
    grads = {}
    for name, adjoint in ADJOINTS.items():
        grad = jax.grad(functools.partial(loss, adjoint=adjoint))
        if batch > 1:
            grad = jax.vmap(grad, in_axes=(0, None))
        t0 = time.perf_counter()
        compiled = jax.jit(grad).lower(K, stream).compile()
        compile_s = time.perf_counter() - t0
        g = jax.block_until_ready(compiled(K, stream))
        t0 = time.perf_counter()
        g = jax.block_until_ready(compiled(K, stream))
        run_s = time.perf_counter() - t0
        grads[name] = np.asarray(g)
        out[name] = {
            "memory": memory(compiled),
            "compile_s": round(compile_s, 2),
            "run_s": round(run_s, 4),
            "grad_K": grads[name].tolist(),
        }
    d, c = grads["direct"], grads["checkpoint"]
    out["max_rel_diff"] = float(np.max(np.abs(c - d) / np.maximum(np.abs(d), 1e-300)))
    for base in ("direct", "forward_only"):
        ratios = {}
        for field in ("temp_size_in_bytes", "total_bytes"):
            below, checkpoint = out[base]["memory"], out["checkpoint"]["memory"]
            if below.get(field) and field in checkpoint:
                ratios[field] = round(checkpoint[field] / below[field], 4)
        out[f"ratio_checkpoint_over_{base}"] = ratios
    return out


def main():
    visjax.apply_xla_cpu_workarounds()  # as the command line does (jaxlib 0.10's CPU options)
    parser = argparse.ArgumentParser()
    parser.add_argument("--durations", default="1 3 10 30", help="seconds, space-separated")
    parser.add_argument("--batch", type=int, default=1, help="gain settings vmapped")
    parser.add_argument("--rtol", type=float, default=1e-8, help="allowed gradient mismatch")
    args = parser.parse_args()
    if args.batch < 1:
        parser.error("--batch must be >= 1")
    durations = [float(x) for x in args.durations.replace(",", " ").split()]

    results = [one_duration(duration, args.batch) for duration in durations]
    agree = all(r["max_rel_diff"] <= args.rtol for r in results)
    print(
        json.dumps(
            {
                "benchmark": "gradient_memory_velocity_estimator",
                "loss": "sum of windowed RMS velocity errors, d/dK",
                "rate_hz": RATE_HZ,
                "batch": args.batch,
                "dtype": "float64",
                "machine": f"{platform.machine()}, {jax.devices()[0].platform}",
                "jax": jax.__version__,
                "gradients_agree": agree,
                "rtol": args.rtol,
                "durations": results,
            },
            indent=2,
        )
    )
    if not agree:
        sys.exit(1)


if __name__ == "__main__":
    main()
