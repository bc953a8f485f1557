"""Avoid a deadlock of XLA's CPU runtime, by setting one XLA option on import.

With jaxlib 0.10 on CPU, a compiled program that holds several batched LAPACK calls (an
inverse, `eigvalsh`) can hang forever, at 0% CPU, once the batch reaches a few hundred:
two `jnp.linalg.inv` of (1000, 16, 16) and (1000, 4, 4, 4) in one `jit` hang within a
few calls on a 2-core machine; so does a `vmap` of 300-1000 runs of the adaptive estimator
of Nath et al. (its vector field inverts two information matrices). XLA's
concurrency-optimized scheduler is what overlaps the calls; with
`--xla_cpu_enable_concurrency_optimized_scheduler=false` the same programs finish.

On import, visjax appends that option to `XLA_FLAGS` unless the variable already names
it, or `VISJAX_KEEP_XLA_FLAGS` is set. XLA reads `XLA_FLAGS` when its CPU backend starts:
if JAX computed anything before `import visjax`, the option does not apply, so import
visjax first (or set the option yourself) for large CPU batches.
"""

import os

OPTION = "--xla_cpu_enable_concurrency_optimized_scheduler=false"

if not os.environ.get("VISJAX_KEEP_XLA_FLAGS"):
    _flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_enable_concurrency_optimized_scheduler" not in _flags:
        os.environ["XLA_FLAGS"] = f"{_flags} {OPTION}".strip()

# Not set: `--xla_cpu_experimental_ynn_fusion_type=` (XLA's own loop fusions instead of
# YNNPACK's) made the vmapped per-frame work 1.3-1.6x faster on jaxlib 0.10 before that work
# was unrolled, but with it a test worker crashed in XLA's CPU compiler in two full runs of
# the suite (without it, about once per full run too; the cause is unknown); users may set
# it in `XLA_FLAGS` themselves.
