"""Two XLA options set on import: one avoids a deadlock of XLA's CPU runtime, one halves
its compile times and memory.

1. With jaxlib 0.10 on CPU, a compiled program that holds several batched LAPACK calls (an
inverse, `eigvalsh`) can hang forever, at 0% CPU, once the batch reaches a few hundred:
two `jnp.linalg.inv` of (1000, 16, 16) and (1000, 4, 4, 4) in one `jit` hang within a
few calls on a 2-core machine; so does a `vmap` of 300-1000 runs of the adaptive estimator
of Nath et al. (its vector field inverts two information matrices). XLA's
concurrency-optimized scheduler is what overlaps the calls; with
`--xla_cpu_enable_concurrency_optimized_scheduler=false` the same programs finish.

2. `--xla_cpu_use_fusion_emitters=false` (jaxlib 0.10 only): XLA's CPU backend then
generates its loop fusions with its older elemental emitter instead of the MLIR fusion
emitters. Measured on jaxlib 0.10.2, 2 cores: the fused run of the velocity estimator
compiles in 1.6 s instead of 2.4 s and its compile's peak memory is 90 MB instead of 260
MB above the process's; the per-frame result pass 1.15 s instead of 2.1 s; the same run
times (the Monte-Carlo study 16% faster). It is set only for jaxlib 0.10.x, on which it
was measured (an option a later XLA drops would abort its start).

On import, visjax appends each option to `XLA_FLAGS` unless the variable already names
it, or `VISJAX_KEEP_XLA_FLAGS` is set. XLA reads `XLA_FLAGS` when its CPU backend starts:
if JAX computed anything before `import visjax`, the options do not apply, so import
visjax first (or set the options yourself).
"""

import importlib.metadata
import os

OPTION = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
EMITTERS = "--xla_cpu_use_fusion_emitters=false"


def _jaxlib_minor():
    try:
        return tuple(int(v) for v in importlib.metadata.version("jaxlib").split(".")[:2])
    except (importlib.metadata.PackageNotFoundError, ValueError):
        return None


def _options():
    yield OPTION
    if _jaxlib_minor() == (0, 10):
        yield EMITTERS


if not os.environ.get("VISJAX_KEEP_XLA_FLAGS"):
    for _option in _options():
        _flags = os.environ.get("XLA_FLAGS", "")
        if _option.split("=")[0] not in _flags:
            os.environ["XLA_FLAGS"] = f"{_flags} {_option}".strip()

# Not set: `--xla_cpu_experimental_ynn_fusion_type=` (XLA's own loop fusions instead of
# YNNPACK's) made the vmapped per-frame work 1.3-1.6x faster on jaxlib 0.10 before that work
# was unrolled, but with it a test worker crashed in XLA's CPU compiler in two full runs of
# the suite (without it, about once per full run too; the cause is unknown); users may set
# it in `XLA_FLAGS` themselves.
