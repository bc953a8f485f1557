"""XLA options for JAX's CPU backend, applied only when asked for.

`import visjax` changes nothing in the process (no environment variable, no JAX config).
The command line and the test suite call `apply_xla_cpu_workarounds()` themselves; a
library user who runs large batches on a CPU calls it once, before JAX computes anything.

The two options:

1. `--xla_cpu_enable_concurrency_optimized_scheduler=false`. With jaxlib 0.10 on CPU, a
   compiled program that holds several batched LAPACK calls (an inverse, `eigvalsh`) can
   hang forever, at 0% CPU, once the batch reaches a few hundred: two `jnp.linalg.inv` of
   (1000, 16, 16) and (1000, 4, 4, 4) in one `jit` hang within a few calls on a 2-core
   machine; so does a `vmap` of 300-1000 runs of the adaptive estimator of Nath et al.
   (its vector field inverts two information matrices); so did the velocity problem's
   batch fits evaluated over five seeds at once (`tune_methods`; 1 s at 1 kHz, one run in
   three), where a native stack showed both threads of XLA's pool inside batched LAPACK
   triangular solves, each waiting for the chunks it had queued to the same pool. XLA's
   concurrency-optimized scheduler is what overlaps the calls; with this option the same
   programs finish (the velocity fits: 6 runs of 6).

2. `--xla_cpu_use_fusion_emitters=false` (jaxlib 0.10 only): XLA's CPU backend then
   generates its loop fusions with its older elemental emitter instead of the MLIR fusion
   emitters. Measured on jaxlib 0.10.2, 2 cores: the fused run of the velocity estimator
   compiles in 1.6 s instead of 2.4 s and its compile's peak memory is 90 MB instead of
   260 MB above the process's; the same run times (the Monte-Carlo study 16% faster). Set
   only for jaxlib 0.10.x, on which it was measured (an option a later XLA drops would
   abort its start).

Not set: `--xla_cpu_experimental_ynn_fusion_type=` (XLA's own loop fusions instead of
YNNPACK's) made the vmapped per-frame work 1.3-1.6x faster on jaxlib 0.10 before that work
was unrolled, but with it a test worker crashed in XLA's CPU compiler in two full runs of
the suite; users may set it in `XLA_FLAGS` themselves.
"""

import importlib.metadata
import os
import warnings

SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
EMITTERS = "--xla_cpu_use_fusion_emitters=false"


def _jaxlib_minor() -> tuple[int, ...] | None:
    try:
        return tuple(int(v) for v in importlib.metadata.version("jaxlib").split(".")[:2])
    except (importlib.metadata.PackageNotFoundError, ValueError):
        return None


def xla_cpu_options() -> tuple[str, ...]:
    """The XLA options `apply_xla_cpu_workarounds` sets for the installed jaxlib."""
    return (SCHEDULER, EMITTERS) if _jaxlib_minor() == (0, 10) else (SCHEDULER,)


def _backend_started() -> bool:
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # a JAX without the query: assume not
        return False


def apply_xla_cpu_workarounds() -> str:
    """Append visjax's XLA options for the CPU backend to `XLA_FLAGS` (those the variable
    does not name already): one avoids a hang of batched LAPACK calls in XLA's CPU runtime
    (jaxlib 0.10), one makes compiles faster and smaller (jaxlib 0.10 only).

    Call it once, before JAX computes anything: XLA reads `XLA_FLAGS` when its backend
    starts. Called after that, it changes nothing and warns. The `visjax` command line and
    the test suite call it themselves; `import visjax` does not.

    **Returns:** the value of `XLA_FLAGS` afterwards.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    missing = [o for o in xla_cpu_options() if o.split("=")[0] not in flags]
    if not missing:
        return flags
    if _backend_started():
        warnings.warn(
            "visjax.apply_xla_cpu_workarounds() was called after JAX's backend started; "
            "XLA_FLAGS is read only at start, so it has no effect. Call it before any JAX "
            "computation.",
            stacklevel=2,
        )
        return flags
    flags = " ".join([flags, *missing]).strip()
    os.environ["XLA_FLAGS"] = flags
    return flags


_warned = False


def warn_if_hang_prone() -> None:
    """Warn once if this process runs jaxlib 0.10 on the CPU without the scheduler option
    (batched LAPACK calls in one program can then hang: see `apply_xla_cpu_workarounds`).
    Cheap: reads an environment variable and JAX's default backend."""
    global _warned
    if _warned or _jaxlib_minor() != (0, 10):
        return
    if SCHEDULER.split("=")[0] in os.environ.get("XLA_FLAGS", ""):
        return
    import jax

    if jax.default_backend() != "cpu":
        return
    _warned = True
    warnings.warn(
        "large batches on the CPU with jaxlib 0.10 can hang in XLA's scheduler (several "
        "batched matrix inverses in one program); call visjax.apply_xla_cpu_workarounds() "
        "at the start of the program, before any JAX computation.",
        stacklevel=3,
    )
