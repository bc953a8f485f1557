"""Tests run in float64 with strict dtype promotion (no silent float32 -> float64)."""

import atexit
import os
import shutil
import sys
import tempfile

import jax
import pytest

import visjax

# the XLA options the command line also sets (the library sets none on import), before any
# JAX computation: subprocesses started by the tests inherit them
visjax.apply_xla_cpu_workarounds()
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")

# The suite is bound by XLA's compile time, not by run time: its programs are compiled at
# XLA's lowest optimisation level (a third less wall time on 2 cores). Floating-point
# semantics are the same at every level (no fast-math); the numbers differ from an
# optimised build in the last bits at most, inside every tolerance the tests state.
# Subprocesses started by the tests inherit it through JAX's environment variable; outside
# the tests (the command line, the benchmarks) nothing changes. VISJAX_TEST_OPTIMIZE=1
# runs the suite at the default level.
if not os.environ.get("VISJAX_TEST_OPTIMIZE"):
    os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"] = "1"
    jax.config.update("jax_disable_most_optimizations", True)

# One compilation cache on disk for the whole run: the first process (pytest itself, the
# controller of `-n 2`) makes the folder and removes it at exit; the xdist workers and every
# subprocess a test starts (the command line, float32 checks, multi-process sweeps, notebook
# kernels) inherit it through JAX's own environment variables, so a program compiled once
# (the same scene, the same estimator) is loaded from disk everywhere else. Every program
# is stored, small ones too (measured over the whole suite on 2 cores: 3% less CPU time
# than storing only those over half a second, 838 s against 867 s; about 5 MB). Every run
# starts empty, as CI does. VISJAX_TEST_NO_CACHE=1 turns it off.
if not os.environ.get("VISJAX_TEST_NO_CACHE"):
    if "VISJAX_TEST_JAX_CACHE" not in os.environ:
        _cache = tempfile.mkdtemp(prefix="visjax-test-jax-cache-")
        atexit.register(shutil.rmtree, _cache, ignore_errors=True)
        os.environ["VISJAX_TEST_JAX_CACHE"] = _cache
    os.environ["JAX_COMPILATION_CACHE_DIR"] = os.environ["VISJAX_TEST_JAX_CACHE"]
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
    os.environ["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "0"
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


@pytest.fixture
def getkey():
    """A fresh PRNG key per call, deterministic per test."""
    state = {"key": jax.random.key(0)}

    def _getkey():
        state["key"], sub = jax.random.split(state["key"])
        return sub

    return _getkey


@pytest.fixture
def no_jaxtyping():
    """The user's view for tests of the library's own shape errors: jaxtyping's runtime
    checks (on in CI's shape-checked run) off, so the `ValueError` naming the argument is
    tested."""
    from tests.helpers import without_jaxtyping

    with without_jaxtyping():
        yield


# `pytest -n 2 --dist loadfile` (the default options) runs each module in one worker, so a
# module's fixtures and programs are built once. The slowest modules run first, so that the
# short ones fill the gaps instead of the run ending on a long module in one worker.
_FIRST = (
    "test_cli.py",
    "test_uio.py",
    "test_runner.py",
    "test_adaptive_scenes.py",
    "test_reconstruction.py",
    "test_chunked.py",
    "test_settings.py",
    "test_plots.py",
)


def pytest_collection_modifyitems(config, items):
    def rank(item):
        name = item.path.name
        return _FIRST.index(name) if name in _FIRST else len(_FIRST)

    items.sort(key=rank)  # stable: the order within each group is kept


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """An xdist worker whose results are sent (its `workerfinished` event, after every
    fixture's teardown) ends at once: Python's finalisation of a worker that compiled a few
    hundred XLA programs took seconds while the run waited on it. The controller and a run
    without `-n` end as usual; VISJAX_TEST_FULL_EXIT=1 turns it off."""
    if hasattr(config, "workerinput") and not os.environ.get("VISJAX_TEST_FULL_EXIT"):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
