"""`import visjax` changes no global state; `visjax.apply_xla_cpu_workarounds()` sets the
XLA options the command line and the tests use, and only when called."""

import importlib.metadata
import json
import os
import subprocess
import sys

import pytest

SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
EMITTERS = "--xla_cpu_use_fusion_emitters=false"
ON_010 = importlib.metadata.version("jaxlib").startswith("0.10.")


def _python(code: str, xla_flags: str | None = None, timeout: int = 300) -> str:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS" and not k.startswith("JAX_")}
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=timeout
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


@pytest.mark.parametrize(
    "preset",
    [None, pytest.param("--xla_force_host_platform_device_count=2", marks=pytest.mark.slow)],
)
def test_import_leaves_xla_flags_and_jax_config_unchanged(preset):
    code = (
        "import os, json, jax\n"
        "before = (os.environ.get('XLA_FLAGS'), {k: v for k, v in os.environ.items()})\n"
        "names = ('jax_enable_x64', 'jax_numpy_dtype_promotion', "
        "'jax_compilation_cache_dir', 'jax_default_matmul_precision')\n"
        "config = {k: getattr(jax.config, k) for k in names}\n"
        "import visjax, visjax.cli, visjax.report, visjax.plots\n"
        "after = {k: getattr(jax.config, k) for k in config}\n"
        "print(json.dumps([before[0], os.environ.get('XLA_FLAGS'), before[1] == dict(os.environ), "
        "config == after]))\n"
    )
    flags_before, flags_after, env_same, config_same = json.loads(_python(code, preset))
    assert flags_before == preset and flags_after == preset
    assert env_same and config_same


@pytest.mark.parametrize(
    "preset", ["", pytest.param("--xla_cpu_use_fusion_emitters=true", marks=pytest.mark.slow)]
)
def test_apply_appends_the_missing_options_and_the_backend_starts(preset):
    code = (
        "import visjax, jax, jax.numpy as jnp, os\n"
        "returned = visjax.apply_xla_cpu_workarounds()\n"
        "assert float(jax.jit(lambda x: x + 1.0)(jnp.ones(3))[0]) == 2.0\n"
        "assert returned == os.environ['XLA_FLAGS']\n"
        "print(os.environ['XLA_FLAGS'])\n"
    )
    flags = _python(code, preset).split()
    if preset:  # an option the user set is kept, not appended a second time
        assert flags == [preset, SCHEDULER]
    else:
        assert flags == [SCHEDULER] + ([EMITTERS] if ON_010 else [])


def test_apply_after_the_backend_started_warns_and_changes_nothing():
    code = (
        "import warnings, os, jax, jax.numpy as jnp, visjax\n"
        "jnp.ones(2).block_until_ready()\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    visjax.apply_xla_cpu_workarounds()\n"
        "said = 'before any JAX computation' in str(w[0].message)\n"
        "print(os.environ.get('XLA_FLAGS'), len(w), said)\n"
    )
    assert _python(code).split() == ["None", "1", "True"]


@pytest.mark.slow  # a subprocess batched sweep: the second command (.ci/run)
def test_sweep_warns_when_the_configuration_can_hang():
    """On jaxlib 0.10 on the CPU without the scheduler option, a batched sweep warns once."""
    code = (
        "import warnings, jax, jax.numpy as jnp, numpy as np, visjax\n"
        "from visjax import studies, RESULTS\n"
        "import equinox as eqx\n"
        "class Sol(eqx.Module):\n"
        "    result: object\n"
        "    x: object\n"
        "f = lambda p, k: Sol(RESULTS.successful, p['a'] + jax.random.normal(k))\n"
        "fp = studies.FunctionProblem(f, lambda s: {'x': s.x})\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    studies.sweep(fp, {'a': np.arange(3.0)}, np.arange(2))\n"
        "    studies.sweep(fp, {'a': np.arange(3.0)}, np.arange(2))\n"
        "print(sum('apply_xla_cpu_workarounds' in str(x.message) for x in w))\n"
    )
    assert _python(code).strip() == ("1" if ON_010 else "0")
    assert _python("import visjax; visjax.apply_xla_cpu_workarounds()\n" + code).strip() == "0"


@pytest.mark.slow  # a subprocess hang check: the second command (.ci/run)
def test_no_xla_cpu_deadlock_with_several_batched_lapack_calls():
    """Two batched inverses in one program hang XLA's CPU runtime (jaxlib 0.10) within a
    few calls at batch 1,000 unless the scheduler option is set; with
    `apply_xla_cpu_workarounds()` they finish."""
    code = (
        "import visjax; visjax.apply_xla_cpu_workarounds()\n"
        "import jax, jax.numpy as jnp, numpy as np\n"
        "f = jax.jit(lambda a, b: (jnp.linalg.inv(a), jnp.linalg.inv(b)))\n"
        "a = np.random.rand(1000, 16, 16) + 16 * np.eye(16)\n"
        "b = np.random.rand(1000, 4, 4, 4) + 4 * np.eye(4)\n"
        "for _ in range(40): jax.block_until_ready(f(a, b))\n"
        "import os; print(os.environ['XLA_FLAGS'])\n"
    )
    assert SCHEDULER in _python(code)
