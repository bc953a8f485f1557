"""Where a sweep's chunks run: this process (`sweep`'s default) or the workers of a Ray
cluster (`RayExecutor`). An executor's `map_chunks(task, todo)` yields `(chunk, outputs)`
as chunks finish, in any order; `sweep` writes each as a part as it arrives."""

from collections.abc import Iterator, Sequence
from typing import Any


class RayExecutor:
    """The chunks of a sweep as Ray tasks: each task computes one chunk in a worker process
    (which compiles the chunk's program once and reuses it for its later chunks), a task
    lost with its worker is retried (`max_retries`), and the results stream back to the
    calling process as they finish, where `sweep` writes them as parts.

    **Arguments:** `address`: a running cluster's address (`"auto"` for the one this
    machine belongs to), or `None` for a local Ray instance started here (and stopped by
    `shutdown`); `num_cpus`: the local instance's CPUs (default: all); `max_retries`: the
    retries of a task whose worker died; `cpus_per_task`: the CPUs a chunk reserves (JAX
    uses the cores it is given; 1 runs one chunk per CPU); `connect_timeout_s`: how long
    a cluster's address (`host:port`, `ray://host:port`) may take to answer a TCP
    connection before it is refused (default 10 s).

    **Raises:** `ConnectionError` (one line: the address, the wait) when nothing answers at
    the address, or Ray cannot connect to it.

    Ray is an optional dependency (`pip install visjax[ray]`), imported when an executor is
    made. The problem and the parameter points are sent once (`ray.put`); the workers
    compute in the caller's 64-bit mode of the moment the executor is made.
    """

    def __init__(
        self,
        address: str | None = None,
        *,
        num_cpus: int | None = None,
        max_retries: int = 3,
        cpus_per_task: float = 1.0,
        connect_timeout_s: float = 10.0,
    ):
        try:
            import ray
        except ImportError:
            raise ImportError(
                "the Ray executor needs Ray: pip install 'visjax[ray]' (or ray[default])"
            ) from None
        self.ray = ray
        self.max_retries = int(max_retries)
        self.cpus_per_task = float(cpus_per_task)
        self.started_here = False
        import jax

        self.x64 = bool(jax.config.jax_enable_x64)
        if not ray.is_initialized():
            import os

            import jax

            # the workers run XLA with the caller's options (`apply_xla_cpu_workarounds`)
            # and JAX's 64-bit mode as the caller (set before a task's arrays are unpickled)
            env = {"XLA_FLAGS": os.environ["XLA_FLAGS"]} if "XLA_FLAGS" in os.environ else {}
            env["JAX_ENABLE_X64"] = "1" if jax.config.jax_enable_x64 else "0"
            kwargs: dict[str, Any] = {
                "include_dashboard": False,
                "log_to_driver": False,
                "runtime_env": {"env_vars": env},
            }
            if address is None:
                if num_cpus is not None:
                    kwargs["num_cpus"] = int(num_cpus)
                ray.init(**kwargs)
                self.started_here = True
            else:
                _reachable(address, float(connect_timeout_s))
                try:
                    ray.init(address=address, **kwargs)
                except (ConnectionError, RuntimeError, ValueError) as e:
                    first = next((ln for ln in str(e).splitlines() if ln.strip()), "")
                    raise ConnectionError(
                        f"--ray {address}: Ray could not connect ({type(e).__name__}: {first})"
                    ) from None

    def map_chunks(self, task, todo: Sequence) -> Iterator[tuple[int, Any]]:
        """Run `task(idx)` for every `(chunk, idx)` of `todo` on the cluster; yield
        `(chunk, outputs)` as each finishes. A task that fails for good raises here."""
        ray = self.ray
        if task.x64 != self.x64:
            raise ValueError(
                "JAX's 64-bit mode changed since the Ray executor was made (its workers "
                "compute in the mode of that moment): make the executor after "
                "`jax.config.update('jax_enable_x64', ...)`."
            )
        remote = ray.remote(_run_task).options(
            num_cpus=self.cpus_per_task, max_retries=self.max_retries, retry_exceptions=False
        )
        shared = ray.put(task)
        pending = {remote.remote(shared, idx): c for c, idx in todo}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                c = pending.pop(ref)
                yield c, ray.get(ref)

    def shutdown(self) -> None:
        """Stop the local Ray instance this executor started (nothing for a cluster)."""
        if self.started_here and self.ray.is_initialized():
            self.ray.shutdown()
            self.started_here = False


def _run_task(task, idx):
    """A chunk on a Ray worker (whose 64-bit mode is the caller's, from its environment)."""
    return task(idx)


def _reachable(address: str, timeout_s: float) -> None:
    """A cluster's `host:port` (or `ray://host:port`) answers a TCP connection within
    `timeout_s`; other forms (`"auto"`) are left to Ray. **Raises:** `ConnectionError`."""
    import socket

    text = address.split("://", 1)[-1]
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        return
    host = host.strip("[]") or "127.0.0.1"
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as e:
        reason = "no answer" if isinstance(e, TimeoutError) else (e.strerror or str(e))
        raise ConnectionError(
            f"--ray {address}: nothing answers at {host}:{port} within {timeout_s:g} s "
            f"({reason}): start the cluster's head there (`ray start --head`), or run "
            "--ray without an address for a local instance"
        ) from None
