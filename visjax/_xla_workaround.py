"""Two XLA options for the CPU backend, set on import.

1. A deadlock. With jaxlib 0.10 on CPU, a compiled program that holds several batched
   LAPACK calls (an inverse, `eigvalsh`) can hang forever, at 0% CPU, once the batch
   reaches a few hundred: two `jnp.linalg.inv` of (1000, 16, 16) and (1000, 4, 4, 4) in
   one `jit` hang within a few calls on a 2-core machine; so does a `vmap` of 300-1000
   runs of the adaptive estimator of Nath et al. (its vector field inverts two
   information matrices). XLA's concurrency-optimized scheduler is what overlaps the
   calls; with `--xla_cpu_enable_concurrency_optimized_scheduler=false` the same programs
   finish.
2. Speed (jaxlib 0.10 only, where the option exists). XLA's CPU backend hands fusions of
   elementwise work to the YNNPACK library; on the code visjax runs under `vmap` (3x3
   algebra per frame or per trajectory, a few hundred flops each) its fusions are slower
   than XLA's own: with `--xla_cpu_experimental_ynn_fusion_type=` (no YNNPACK fusions)
   the homography, reconstruction, $e$ and $J$ of a frame take 1.3-1.6x less time
   (`benchmarks/monte_carlo.py`), with the same results.

On import, visjax appends each option to `XLA_FLAGS` unless the variable already names
it, or `VISJAX_KEEP_XLA_FLAGS` is set. XLA reads `XLA_FLAGS` when its CPU backend starts:
if JAX computed anything before `import visjax`, the options do not apply, so import
visjax first (or set the options yourself).
"""

import importlib.metadata
import os

OPTION = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
FUSION_OPTION = "--xla_cpu_experimental_ynn_fusion_type="


def _jaxlib_0_10() -> bool:
    try:
        return importlib.metadata.version("jaxlib").startswith("0.10.")
    except importlib.metadata.PackageNotFoundError:
        return False


if not os.environ.get("VISJAX_KEEP_XLA_FLAGS"):
    _flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_enable_concurrency_optimized_scheduler" not in _flags:
        _flags = f"{_flags} {OPTION}".strip()
    if "xla_cpu_experimental_ynn_fusion_type" not in _flags and _jaxlib_0_10():
        _flags = f"{_flags} {FUSION_OPTION}".strip()
    os.environ["XLA_FLAGS"] = _flags
