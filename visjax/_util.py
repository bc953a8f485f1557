"""Input checks shared by every package (run before tracing, on static shapes)."""

import difflib
from collections.abc import Iterable

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree


def did_you_mean(name, choices: Iterable, *, ignore_case: bool = False) -> str:
    """`" (did you mean 'x'?)"` naming the choice closest to `name` (difflib's ratio at
    least 0.6), or `""` when none is close: the hint of every "unknown name" error."""
    choices = [str(c) for c in choices]
    if ignore_case:
        lower = {c.lower(): c for c in choices}
        close = difflib.get_close_matches(str(name).lower(), list(lower), n=1)
        close = [lower[c] for c in close]
    else:
        close = difflib.get_close_matches(str(name), choices, n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def median_interval(ts) -> jax.Array:
    """The median interval of the sample times `ts` (n,). Concrete times (also a constant
    inside `jit`) are reduced once in NumPy: left to XLA, a constant's median is
    constant-folded as a sort of every interval at each compile (seconds, and XLA's
    "slow operation" warning, for a 10,000-sample trajectory). Traced times take
    `jnp.median` (`jit`, `vmap` and `grad` as usual)."""
    if isinstance(ts, jax.core.Tracer):
        return jnp.median(jnp.diff(ts))
    with jax.ensure_compile_time_eval():
        return jnp.asarray(np.median(np.diff(np.asarray(ts))), jnp.result_type(ts))


def as_float(x):
    """`x` as a JAX array of a floating dtype (integers promote to the default float).

    A value that is not traced stays concrete, also inside `jit` (so that a stream built
    inside `jit` from NumPy times still has concrete times for `run(..., dt=...)`)."""
    if isinstance(x, jax.core.Tracer):
        return _as_float(x)
    with jax.ensure_compile_time_eval():
        return _as_float(x)


def _as_float(x):
    if isinstance(x, np.ndarray) and x.dtype == jax.dtypes.canonicalize_dtype(x.dtype):
        # `device_put` copies a NumPy array once or, when its memory is aligned, shares it
        # (a read-only memory map then costs no copy); `jnp.asarray` of a large unaligned
        # array held two copies at its peak. A writable array is copied first, so that
        # changing it afterwards never changes the JAX array (aliasing depended on where
        # the allocator put it).
        x = jax.device_put(x.copy() if x.flags.writeable else x)
    else:
        x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.result_type(float))
    return x


def check_shape(x, shape, name: str) -> None:
    """Raise `ValueError` unless `x.shape == shape` (`None` entries match any size)."""
    ok = x.ndim == len(shape) and all(s is None or s == d for s, d in zip(shape, x.shape))
    if not ok:
        want = str(tuple("n" if s is None else s for s in shape)).replace("'", "")
        raise ValueError(f"`{name}` must have shape {want}; got shape {tuple(x.shape)}.")


def check_points(p, name: str, min_points: int = 4):
    """`p` as a float array of shape (n, 2) with n >= `min_points`, else `ValueError`."""
    p = as_float(p)
    if p.ndim != 2 or p.shape[-1] != 2:
        raise ValueError(
            f"`{name}` must be an array of pixel coordinates of shape (n, 2); "
            f"got shape {tuple(p.shape)}."
        )
    if p.shape[0] < min_points:
        raise ValueError(
            f"`{name}` has {p.shape[0]} points; at least {min_points} are needed "
            "(a homography has 8 degrees of freedom, two equations per point)."
        )
    return p


def common_dtype(*xs):
    """The floating dtype the arguments promote to."""
    return jnp.result_type(*xs)


def positive_finite(x):
    """True (a traced bool) when every entry of `x` is finite and positive (NaN fails)."""
    x = jnp.asarray(x)
    return jnp.all(jnp.isfinite(x) & (x > 0))


def chunked_map(f, xs, batch_size: int):
    """`jax.vmap(f)` over the leading axis of `xs`, `batch_size` entries at a time (a
    `lax.scan` over chunks, so that only one chunk's intermediates exist at once).

    Unlike `jax.lax.map(..., batch_size=...)` a length that is not a multiple of
    `batch_size` does not compile `f` a second time for the remainder: the last chunk is
    the last `batch_size` entries (overlapping the one before), and the overlap is dropped.
    """
    n = jax.tree_util.tree_leaves(xs)[0].shape[0]
    b = max(1, min(int(batch_size), n))
    nb = -(-n // b)

    def body(_, i):
        start = jnp.minimum(i * b, n - b)
        part = jax.tree_util.tree_map(lambda x: jax.lax.dynamic_slice_in_dim(x, start, b), xs)
        return None, jax.vmap(f)(part)

    _, ys = jax.lax.scan(body, None, jnp.arange(nb))
    head = (nb - 1) * b

    def assemble(y):
        flat = y[:-1].reshape((head,) + y.shape[2:])
        return jnp.concatenate([flat, y[-1, b - (n - head) :]])

    return jax.tree_util.tree_map(assemble, ys)


def solver_tolerance(tol: float, dtype) -> float:
    """A nonlinear solver's convergence tolerance `tol`, at least 1000 eps of `dtype`.

    An iterative solver stops when successive iterates differ by less than
    `atol + rtol |y|`; near the solution they still differ by the rounding of a step, the
    residuals' rounding (a pixel of ~300 carries 2e-5 px in float32) carried through the
    problem's conditioning. 1e-9, chosen for float64 (eps 2.2e-16), is below float32's
    eps (1.2e-7): a float32 solve then never converges and reports
    `nonlinear_max_steps_reached` (measured: every run of the velocity problem's batch
    fits and EKF, whose frame poses are such solves). 1000 eps (1.2e-4 in float32) is met
    on every frame of the section-6 scene (100 eps left some frames unconverged) and
    leaves float64's 1e-9 as it is."""
    return max(float(tol), 1000.0 * float(jnp.finfo(dtype).eps))


def covariance(residuals, y, args, count) -> tuple:
    """The covariance of the estimate `y` (a pytree) of `residuals(y, args)` (any shape;
    the rows of unseen data zero), `count` the number of residual components that carry
    data: $\\hat\\sigma^2 (J^T J)^{-1}$ (`visjax.baselines`' losses module: the Gauss-Newton
    approximation of the inverse Hessian), in the order of `y`'s flattened
    leaves.

    **Returns:** `(cov (p, p), sigma2)`; NaN when there are not more residuals than
    unknowns or $J^T J$ is singular."""
    flat, unravel = ravel_pytree(y)
    fun = lambda v: jnp.ravel(residuals(unravel(v), args))  # noqa: E731
    J = jax.jacfwd(fun)(flat)
    r = fun(flat)
    p = flat.shape[0]
    dof = jnp.asarray(count, r.dtype) - p
    sigma2 = jnp.where(dof > 0, jnp.sum(r * r) / jnp.maximum(dof, 1.0), jnp.nan)
    JTJ = J.T @ J
    # scaled to unit diagonal before inverting (unknowns of different units)
    d = jnp.sqrt(jnp.maximum(jnp.diag(JTJ), jnp.finfo(r.dtype).tiny))
    inv = jnp.linalg.inv(JTJ / jnp.outer(d, d)) / jnp.outer(d, d)
    cov = sigma2 * 0.5 * (inv + inv.T)
    return cov, sigma2


def number_text(x, spec: str = "g") -> str:
    """A number for a title: `format(float(x), spec)`, or "traced" for a traced value (a
    problem's data parameter inside a sweep)."""
    try:
        return format(float(x), spec)
    except (TypeError, jax.errors.ConcretizationTypeError):
        return "traced"


class Frozen:
    """A NumPy array held as a static value (hashed by its bytes, equal by its values): a
    setting that fixes a compiled program's structure, such as the sample times a held
    integration step maps onto its steps. Two problems whose frozen values are equal share
    their compiled programs; `.array` is the (read-only) array."""

    __slots__ = ("array", "_hash")

    def __init__(self, array):
        a = np.array(array, copy=True)
        a.flags.writeable = False
        self.array = a
        self._hash = hash((a.dtype.str, a.shape, a.tobytes()))

    def __hash__(self):
        return self._hash

    def __eq__(self, other):
        return (
            isinstance(other, Frozen)
            and self._hash == other._hash
            and self.array.dtype == other.array.dtype
            and self.array.shape == other.array.shape
            and bool(np.array_equal(self.array, other.array, equal_nan=True))
        )

    def __repr__(self):
        return f"Frozen(shape={self.array.shape}, dtype={self.array.dtype})"


class Note(str):
    """Descriptive text held in a static field that does not key compilation (a problem's
    `source`, the name of its data file): two Notes compare equal whatever their text, so
    problems that differ only in their notes share compiled programs; against a plain
    `str` a Note compares as its text."""

    __slots__ = ()

    def __eq__(self, other):
        return True if isinstance(other, Note) else str.__eq__(self, other)

    def __ne__(self, other):
        return not self.__eq__(other)

    def __hash__(self):
        return 0


def renamed(module: str, names: dict[str, str], namespace: dict, moved=None):
    """A module's `__getattr__` that still gives each old name of `names` (old -> new) its
    new object, with a `FutureWarning` naming the new one (the old vocabulary, read on);
    a name of `moved` (old -> its new home in another package, which this one may not
    import) raises an `AttributeError` saying where it went."""
    import warnings

    def __getattr__(name: str):
        if moved and name in moved:
            raise AttributeError(f"{module}.{name} moved: it is now {moved[name]}")
        if name in names:
            warnings.warn(
                f"{module}.{name} is now {module}.{names[name]}: the old name will go",
                FutureWarning,
                stacklevel=2,
            )
            return namespace[names[name]]
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__
