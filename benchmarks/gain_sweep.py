"""The batched gain-tuning case: the velocity estimator of Chitrakaran et al. run by
`visjax.estimators.run` on one shared, prepared measurement stream (the section-6
simulation at 1 kHz, no per-run noise), `jax.vmap` over a batch of gains (K of eq. (63)
times log-normal factors), the windowed RMS reduced in the loop. Prints JSON.

Reported per batch: ns per trajectory-step after compilation (the median of `--repeats`
calls), its ratio against batch 1 measured in the same run, and the kernels of one loop
step: the operations of the compiled while loop's body that run as kernels of their own
on a CPU (fusions, copies, stand-alone arithmetic), each a launch per step whatever the
batch. The target of issue 29: <= 10 ns per trajectory-step at batch 1,024.

The reference measured in the same run, `bare_update`: the estimator's Euler step of
eqs. (39)-(40) written directly, vmapped over the same gains on the same measurements,
with nothing else (no output, no reducer, no finiteness or bound check, no freeze after a
failure): the least work any loop over this state does per step. Its final state is
checked against `run`'s (to 1e-9) before it is timed. `ratio_to_bare_update` is what
`run`'s loop costs over it.

Two more references, the same work as `run`'s loop at its least: the bare update plus the
output $\hat v = J^{-1}\hat\kappa$ (Theorem 2), the windowed squared error against the
truth, one bound test of the new state and the freeze of a failed run, written by hand
with no runner around it: `hand_fused` vmapped over the gains as `run` is (the batch first
in every array), `hand_fused_batch_last` on (6, batch) arrays with no `vmap` (the layout
XLA's CPU loops vectorise best). Their RMS is checked against `run`'s (to 1e-9) before
they are timed: what any XLA loop that computes this study's result costs on the machine.

    python benchmarks/gain_sweep.py [--batches 1 256 1024 16384] [--duration 1.0]
        [--dtype float64|float32]

The JSON records the device and the dtype (`_device.device_fields`).
"""

import argparse
import json
import platform
import re
import statistics
import time

import jax
import jax.numpy as jnp
from _device import add_dtype_option, device_fields, use_dtype

import visjax
from visjax.estimators import (
    SaveAt,
    VelocityEstimator,
    WindowRMS,
    fixed_camera,
    run,
    velocity_stream,
)
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63, section6_scenario

# the operations of a compiled program that run as kernels of their own on a CPU
KERNEL_OPS = {"fusion", "copy", "concatenate", "custom-call", "dynamic-slice", "reduce",
              "dynamic-update-slice", "transpose", "select", "add", "multiply", "divide",
              "subtract", "sqrt", "conditional", "while", "sort", "gather", "scatter"}  # fmt: skip


def loop_kernels(compiled) -> int:
    """The kernels of the body of the compiled program's (first) while loop."""
    text = compiled.as_text()
    bodies = re.findall(r"while\(.*?\), condition=%?[\w.\-]+, body=%?([\w.\-]+)", text)
    if not bodies:
        return -1
    m = re.search(r"\n%?" + re.escape(bodies[0]) + r" .*?\n}\n", text, re.S)
    ops = re.findall(r"^\s*\S+ = (?:\([^)]*\)|\S+) ([\w-]+)\(", m.group(0), re.MULTILINE)
    return sum(op in KERNEL_OPS for op in ops)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 256, 1024, 16384])
    parser.add_argument("--duration", type=float, default=1.0, help="seconds at 1 kHz")
    parser.add_argument("--repeats", type=int, default=5)
    add_dtype_option(parser)
    args = parser.parse_args()
    visjax.apply_xla_cpu_workarounds()
    use_dtype(args.dtype)

    sc = section6_scenario(args.duration, 1000.0)
    camera = fixed_camera(sc.pixels, sc.A, sc.R_star, sc.s[0])
    prepared = velocity_stream(sc.ts, sc.pixels, camera).measured()
    prepared = type(prepared)(ts=prepared.ts, ys=prepared.ys, truth=sc.velocity)
    steps = int(prepared.ts.shape[0])
    reducer = WindowRMS(0.5 * args.duration, args.duration + 1e-9, field="v_hat")

    def loop(K):
        sol = run(
            VelocityEstimator(K=K, rho=RHO_EQ63), prepared, saveat=SaveAt(outputs=False),
            reducer=reducer, throw=False,
        )  # fmt: skip
        return sol.summary.rms

    study = jax.jit(jax.vmap(loop))

    e = prepared.ys.e
    h = jnp.diff(prepared.ts)
    rho = jnp.asarray(RHO_EQ63, e.dtype)

    def bare(K):
        def body(c, x):
            e_hat, eta = c
            e_k, h_k = x
            e_tilde = e_k - e_hat  # eq. (36)
            kappa = eta + (K + 1.0) * e_tilde  # eq. (40)
            d_eta = (K + 1.0) * e_tilde + rho * jnp.sign(e_tilde)
            return (e_hat + h_k * kappa, eta + h_k * d_eta), None  # eq. (39), Euler

        (e_hat, eta), _ = jax.lax.scan(body, (e[0], jnp.zeros_like(e[0])), (e[:-1], h))
        return e_hat, eta

    bare_study = jax.jit(jax.vmap(bare))

    ts, J_inv, v_true = prepared.ts, prepared.ys.J_inv, prepared.truth
    inside = (ts >= reducer.t_start) & (ts < reducer.t_end)
    bound = VelocityEstimator(K=K_EQ63, rho=RHO_EQ63).bound

    def hand_fused(K):
        # the output at each sample before the step, as `run` reads it
        def body(c, x):
            e_hat, eta, sumsq, failed = c
            e_k, h_k, Ji, v_k, in_k = x
            e_tilde = e_k - e_hat  # eq. (36)
            kappa = eta + (K + 1.0) * e_tilde  # eq. (40)
            v_hat = Ji @ kappa  # Theorem 2
            sumsq = sumsq + jnp.where(in_k, (v_hat - v_k) ** 2, 0.0)
            d_eta = (K + 1.0) * e_tilde + rho * jnp.sign(e_tilde)
            new = (e_hat + h_k * kappa, eta + h_k * d_eta)  # eq. (39), Euler
            ok = ~failed & jnp.all(jnp.abs(new[0]) < bound) & jnp.all(jnp.abs(new[1]) < bound)
            e_hat, eta = (jnp.where(ok, a, b) for a, b in zip(new, (e_hat, eta)))
            return (e_hat, eta, sumsq, ~ok), None

        c0 = (e[0], jnp.zeros_like(e[0]), jnp.zeros_like(e[0]), jnp.array(False))
        xs = (e[:-1], h, J_inv[:-1], v_true[:-1], inside[:-1])
        (e_hat, eta, sumsq, _), _ = jax.lax.scan(body, c0, xs)
        # the last sample is read (its output scored) but not integrated past
        kappa = eta + (K + 1.0) * (e[-1] - e_hat)
        sumsq = sumsq + jnp.where(inside[-1], (J_inv[-1] @ kappa - v_true[-1]) ** 2, 0.0)
        return jnp.sqrt(sumsq / jnp.sum(inside).astype(sumsq.dtype))

    def hand_fused_batch_last(K):  # K: (6, batch)
        def body(c, x):
            e_hat, eta, sumsq, failed = c
            e_k, h_k, Ji, v_k, in_k = x
            e_tilde = e_k[:, None] - e_hat  # eq. (36)
            kappa = eta + (K + 1.0) * e_tilde  # eq. (40)
            v_hat = Ji @ kappa  # Theorem 2
            sumsq = sumsq + jnp.where(in_k, (v_hat - v_k[:, None]) ** 2, 0.0)
            d_eta = (K + 1.0) * e_tilde + rho[:, None] * jnp.sign(e_tilde)
            new = (e_hat + h_k * kappa, eta + h_k * d_eta)  # eq. (39), Euler
            ok = jnp.all(jnp.abs(new[0]) < bound, axis=0) & jnp.all(jnp.abs(new[1]) < bound, axis=0)
            ok = ~failed & ok
            e_hat, eta = (jnp.where(ok, a, b) for a, b in zip(new, (e_hat, eta)))
            return (e_hat, eta, sumsq, ~ok), None

        zeros = jnp.zeros_like(K)
        c0 = (jnp.broadcast_to(e[0][:, None], K.shape), zeros, zeros, jnp.zeros(K.shape[1], bool))
        xs = (e[:-1], h, J_inv[:-1], v_true[:-1], inside[:-1])
        (e_hat, eta, sumsq, _), _ = jax.lax.scan(body, c0, xs)
        kappa = eta + (K + 1.0) * (e[-1][:, None] - e_hat)
        sumsq = sumsq + jnp.where(inside[-1], (J_inv[-1] @ kappa - v_true[-1][:, None]) ** 2, 0.0)
        return jnp.sqrt(sumsq / jnp.sum(inside).astype(sumsq.dtype)).T

    fused_study = jax.jit(jax.vmap(hand_fused))
    fused_last_study = jax.jit(hand_fused_batch_last)

    def final_state(K):
        sol = run(VelocityEstimator(K=K, rho=RHO_EQ63), prepared, saveat=SaveAt(outputs=False))
        return sol.final_state.e_hat, sol.final_state.eta

    # the references compute `run`'s arithmetic in another order: measured, a few eps apart
    # (3 eps in float64, 1 in float32); 1e4 eps leaves room for the rounding carried by
    # the recursion (2e-12 in float64, 1e-3 in float32), while a loop that computed
    # anything else would differ by order 1
    tol = 1e4 * float(jnp.finfo(prepared.ys.e.dtype).eps)
    K4 = jnp.asarray(K_EQ63) * jnp.exp(0.1 * jax.random.normal(jax.random.key(2), (4, 6)))
    for a, b in zip(jax.vmap(final_state)(K4), bare_study(K4)):
        gap = float(jnp.max(jnp.abs(a - b) / (1.0 + jnp.abs(a))))
        if not gap <= tol:
            raise SystemExit(f"the bare update is not the estimator's step: gap {gap:.2e}")
    rms_run = study(K4)
    for name, rms in (("hand_fused", fused_study(K4)), ("batch_last", fused_last_study(K4.T))):
        gap = float(jnp.max(jnp.abs(rms - rms_run) / jnp.abs(rms_run)))
        if not gap <= tol:
            raise SystemExit(f"the {name} loop does not compute `run`'s RMS: gap {gap:.2e}")

    def timed(compiled, Ks):
        jax.block_until_ready(compiled(Ks))
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(compiled(Ks))
            times.append(time.perf_counter() - t0)
        return statistics.median(times)

    rows = []
    for batch in args.batches:
        factors = jnp.exp(0.1 * jax.random.normal(jax.random.key(1), (batch, 6)))
        Ks = jnp.asarray(K_EQ63) * factors
        compiled = study.lower(Ks).compile()
        bare_compiled = bare_study.lower(Ks).compile()
        ns = 1e9 * timed(compiled, Ks) / (batch * steps)
        ns_bare = 1e9 * timed(bare_compiled, Ks) / (batch * steps)
        fused_compiled = fused_study.lower(Ks).compile()
        ns_fused = 1e9 * timed(fused_compiled, Ks) / (batch * steps)
        KsT = Ks.T
        last_compiled = fused_last_study.lower(KsT).compile()
        ns_last = 1e9 * timed(last_compiled, KsT) / (batch * steps)
        rows.append(
            {
                "batch": batch,
                "ns_per_trajectory_step": ns,
                "kernels_per_step": loop_kernels(compiled),
                "bare_update_ns_per_trajectory_step": ns_bare,
                "bare_update_kernels_per_step": loop_kernels(bare_compiled),
                "ratio_to_bare_update": ns / ns_bare,
                "hand_fused_ns_per_trajectory_step": ns_fused,
                "hand_fused_kernels_per_step": loop_kernels(fused_compiled),
                "hand_fused_batch_last_ns_per_trajectory_step": ns_last,
                "hand_fused_batch_last_kernels_per_step": loop_kernels(last_compiled),
                "ratio_to_hand_fused": ns / ns_fused,
            }
        )
    base = rows[0]["ns_per_trajectory_step"]
    for r in rows:
        r["ratio_to_first_batch"] = base / r["ns_per_trajectory_step"]
    print(
        json.dumps(
            {
                "benchmark": "gain_sweep_shared_stream_velocity",
                "machine": platform.machine(),
                "jax": jax.__version__,
                **device_fields(args.dtype),
                "steps_per_trajectory": steps,
                "batches": rows,
                "target": {"ns_per_trajectory_step": "<= 10 at batch 1024 (issue 29)"},
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
