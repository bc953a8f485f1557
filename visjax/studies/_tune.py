"""`tune`: gradient-based gain tuning through the runner, in log parameters (gains stay
positive), with an optax optimiser or an optimistix minimiser."""

import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._results import RESULTS
from ._problem import AbstractProblem, FunctionProblem, check_values, component_names, runner
from ._study import Result, Study, study_of
from ._sweep import _key_data


@dataclass(frozen=True)
class TuneResult(Result):
    """What `tune` returns; `to_pandas()`: its `history`, one row per step.

    **Fields:** `params` (the best point met, name -> float or array), `loss` (its loss),
    `params0`, `loss0` (the start), `history` (one dict per step: `step`, `loss`, and the
    parameters; loads in pandas), `converged` (the optimistix minimiser's result was
    successful; always `True` for a fixed number of optax steps), `best_step` (the step
    of the best point met: 0 is the start).

    `improved` is `False` when no step's loss was below the start's: then `params` *is*
    `params0` (the best point met), and `tune` has said so with a `UserWarning`."""

    params: dict
    loss: float
    params0: dict
    loss0: float
    history: list = field(default_factory=list)
    converged: bool = True
    best_step: int = 0

    @property
    def improved(self) -> bool:
        """Whether the best point met is better than the start (its loss strictly lower)."""
        return self.best_step > 0 and self.loss < self.loss0

    def not_improved_line(self) -> str | None:
        """`None` after an improvement; else one sentence saying the tuning ended at its
        start, with the start's loss and the best loss any step reached."""
        if self.improved:
            return None
        later = [h["loss"] for h in self.history if h["step"] > 0]
        finite = [x for x in later if np.isfinite(x)]
        reached = f"the steps' best was {min(finite):.4g}" if finite else "every step failed"
        return (
            f"tuning did not improve on its start (training loss {self.loss0:.4g}; "
            f"{reached}): the tuned point is the start"
        )

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame(self.history)


def _function_problem(factory, loss, where):
    """The version-3 functional form `(factory, loss)` as a `FunctionProblem`, with a
    `FutureWarning`."""
    warnings.warn(
        f"`{where}(factory, params0, loss, keys)` is deprecated: pass "
        f"`{where}(FunctionProblem(factory, lambda s: {{'loss': loss(s)}}, metric='loss'), "
        "..., keys)`.",
        FutureWarning,
        stacklevel=3,
    )
    return FunctionProblem(factory, _LossMetric(loss), metric="loss")


class _LossMetric(eqx.Module):
    loss: Any

    def __call__(self, solution):
        return {"loss": self.loss(solution)}


def objective(
    problem,
    keys: Any,
    *old: Any,
    method: str | None = None,
    fixed: Mapping[str, Any] | None = None,
    mode: str = "forward",
) -> Callable[[dict], jax.Array]:
    """The tuning objective of one method of `problem` (default the estimator) as a
    function of the log parameters: `log_params -> mean over keys of the headline metric
    (`problem.metric`) of the run at exp(log_params)` (vmapped over the keys), the
    parameters not given (in `fixed`, or in the log parameters) at their defaults. A plain
    function joins as a `FunctionProblem`.

    A failed run (any result code but `successful`) makes the objective `inf`, so that no
    optimiser mistakes a frozen state's numbers for a good loss.

    `mode="forward"`: reverse-mode callers (`jax.grad`, optimistix) get the gradient by
    forward mode (`jax.jacfwd`) underneath: one tangent per parameter, memory independent
    of the trajectory's length; the right choice for a handful of gains. `mode="reverse"`:
    plain reverse mode; for many gains, with a factory that runs with
    `CheckpointAdjoint()` so the stored trajectory stays bounded.
    """
    if mode not in ("forward", "reverse"):
        raise ValueError(f"`mode` must be 'forward' or 'reverse'; got {mode!r}.")

    if not isinstance(problem, AbstractProblem):  # version 3: objective(factory, loss, keys)
        if len(old) != 1:
            raise ValueError("`objective(problem, keys)`: `problem` must be an AbstractProblem.")
        problem, keys = _function_problem(problem, keys, "objective"), old[0]
    elif old:
        raise ValueError("`objective(problem, keys)` takes two positional arguments.")
    factory, loss = _problem_loss(problem, method, fixed)

    kd = jnp.asarray(_key_data(keys))

    def one(log_params, k):
        params = jax.tree_util.tree_map(jnp.exp, log_params)
        sol = factory(params, jax.random.wrap_key_data(k))
        value = jnp.asarray(loss(sol))
        ok = (sol.result == RESULTS.successful) & jnp.isfinite(value)
        return jnp.where(ok, value, jnp.inf)

    def plain(log_params):
        return jnp.mean(jax.vmap(one, in_axes=(None, 0))(log_params, kd))

    if mode == "reverse":
        return plain

    @jax.custom_vjp
    def forward(log_params):
        return plain(log_params)

    def fwd(log_params):
        value = plain(log_params)
        grad = jax.jacfwd(plain)(log_params)
        return value, grad

    def bwd(grad, cotangent):
        return (jax.tree_util.tree_map(lambda g: cotangent * g, grad),)

    forward.defvjp(fwd, bwd)
    return forward


def tune(
    problem,
    params0: Mapping[str, Any],
    keys: Any,
    *old: Any,
    method: str | None = None,
    fixed: Mapping[str, Any] | None = None,
    optimiser: Any = None,
    steps: int = 40,
    mode: str = "forward",
    study: Study | None = None,
    progress: bool | None = None,
) -> TuneResult:
    """Tune positive parameters (gains) by gradient descent through the runner.

    `tune(problem, params0, keys, method=..., fixed=..., study=...)`: the parameters named
    in `params0` of one method (default: the estimator) of an `AbstractProblem`,
    minimising the mean of its headline metric (`problem.metric`) over `keys`; `fixed`
    sets other parameters, the rest keep their defaults. Only positive parameters can be
    tuned. A plain function joins as a `FunctionProblem` (its `metric` the loss).

    The parameters are optimised as their logarithms ($p = e^{z}$): they stay positive and
    a step is relative (a gain spread over decades is as easy to move at 0.01 as at 100).

    **Start from a sweep's best point** (`studies.best`). The sign-based laws of Chitrakaran
    et al. (the $\\rho\\,\\mathrm{sgn}(\\tilde e)$ term of eq. (40)) and the covariance
    resetting of Nath et al. make the loss piecewise smooth: within a piece the gradient is
    exact (tested against finite differences at a small step), but it says nothing about the
    jumps between pieces, so a gradient method refines a point whose basin a global sweep
    has found; it does not replace the sweep.

    **Arguments:**

    - `problem`: an `AbstractProblem` (a `FunctionProblem`: `params0` a dict of positive
        parameters).
    - `params0`: name -> positive float or array, the start.
    - `keys`: the training noise seeds (ints or typed keys). Report the tuned gains on
        other, held-out seeds (`held_out`).
    - `optimiser`: an `optax.GradientTransformation` (default `optax.adam(0.1)`: steps of
        about 10% in each gain), run for `steps` steps keeping the best point met; or an
        `optimistix.AbstractMinimiser` (e.g. `optimistix.BFGS(rtol=1e-4, atol=1e-6)`),
        run by `optimistix.minimise` with `max_steps=steps`.
    - `mode`: `"forward"` or `"reverse"` differentiation (see `objective`).
    - `study`: a `Study`; its `progress` shows a progress bar over the optax steps.

    **Returns:** a `TuneResult`: the best point met, which is the start when no step
    improved on it (`TuneResult.improved` is then `False`, and a `UserWarning` says so).
    """
    import optax
    import optimistix as optx

    study = study_of(study, "tune", progress=progress)
    if not isinstance(problem, AbstractProblem):  # version 3: tune(fn, ...)
        if len(old) != 1:
            raise ValueError(
                "`tune(problem, params0, keys)`: `problem` must be an AbstractProblem."
            )
        problem, keys = _function_problem(problem, keys, "tune"), old[0]
    elif old:
        raise ValueError("`tune(problem, params0, keys)` takes three positional arguments.")
    if method is not None or fixed is not None:
        if isinstance(problem, FunctionProblem):
            raise ValueError("`method` and `fixed` are for a problem with named parameters.")
    if not isinstance(problem, FunctionProblem):
        check_values(problem, params0, "tune")
        specs = problem.parameters()
        not_positive = [k for k in params0 if not specs[k].positive]
        if not_positive:
            raise ValueError(
                f"tune: parameters {not_positive} may be negative; tune works "
                "on the logarithms of positive parameters."
            )
    names = list(params0)
    p0 = {k: np.asarray(v, float) for k, v in params0.items()}
    for k, v in p0.items():
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise ValueError(f"`params0[{k!r}]` must be positive and finite; got {v}.")
    if steps < 1:
        raise ValueError(f"`steps` must be at least 1; got {steps}.")
    z0 = {k: jnp.log(jnp.asarray(v)) for k, v in p0.items()}
    fn = objective(problem, keys, method=method, fixed=fixed, mode=mode)

    def as_params(z):
        return {k: _to_py(np.exp(np.asarray(z[k]))) for k in names}

    not_finite = (
        "the loss at `params0` is not finite (a run failed or diverged): start from a "
        "point where every run succeeds, e.g. `studies.best` of a sweep."
    )
    if optimiser is not None and isinstance(optimiser, optx.AbstractMinimiser):
        value = eqx.filter_jit(fn)
        loss0 = float(value(z0))
        if not np.isfinite(loss0):
            raise ValueError(not_finite)
        sol = optx.minimise(lambda z, _: fn(z), optimiser, z0, max_steps=steps, throw=False)
        z_end = sol.value
        end = float(value(z_end))
        history = [
            {"step": 0, "loss": loss0, **_flat(as_params(z0), problem.columns)},
            {
                "step": int(sol.stats["num_steps"]),
                "loss": end,
                **_flat(as_params(z_end), problem.columns),
            },
        ]
        converged = bool(sol.result == optx.RESULTS.successful)
        best_z, best_loss, best_i = (z_end, end, 1) if end < loss0 else (z0, loss0, 0)
        return _finished(
            TuneResult(
                as_params(best_z), best_loss, as_params(z0), loss0, history, converged,
                history[best_i]["step"],
            )
        )  # fmt: skip
    opt = optax.adam(0.1) if optimiser is None else optimiser
    with jax.numpy_dtype_promotion("standard"):
        state = opt.init(z0)
    from tqdm import tqdm

    @eqx.filter_jit
    def step(z, state):
        value, grad = jax.value_and_grad(fn)(z)
        # a failed run gives an infinite loss and no usable gradient: stay put
        grad = jax.tree_util.tree_map(lambda g: jnp.where(jnp.isfinite(g), g, 0.0), grad)
        # optax mixes its int32 step count with floats: standard promotion for its update
        # (the caller may run with strict promotion, as the tests do)
        with jax.numpy_dtype_promotion("standard"):
            updates, state = opt.update(grad, state, z)
            z = optax.apply_updates(z, updates)
        return value, z, state

    # steps + 1 evaluations of one compiled step: the loss at z_0 ... z_steps (the last
    # update is not taken)
    history, z = [], z0
    best_z, best_loss, loss0, best_i = z0, np.inf, np.nan, 0
    for i in tqdm(range(steps + 1), desc="tune", unit="step", disable=not study.progress):
        value, z_next, state_next = step(z, state)
        value = float(value)
        if i == 0:
            if not np.isfinite(value):
                raise ValueError(not_finite)
            loss0 = value
        history.append({"step": i, "loss": value, **_flat(as_params(z), problem.columns)})
        if np.isfinite(value) and value < best_loss:
            best_z, best_loss, best_i = z, value, i
        z, state = z_next, state_next
    return _finished(
        TuneResult(as_params(best_z), best_loss, as_params(z0), loss0, history, True, best_i)
    )


def _finished(result: TuneResult) -> TuneResult:
    """`result`, with a `UserWarning` when the tuning ended where it started."""
    line = result.not_improved_line()
    if line is not None:
        warnings.warn(f"tune: {line}.", UserWarning, stacklevel=3)
    return result


def _problem_loss(problem, method, fixed):
    """`(factory, loss)` of one method of a problem: its headline metric as the loss."""

    if not problem.metric:
        raise ValueError(f"{problem.title}: tuning needs its headline metric (`metric=`).")
    factory = runner(problem, method, fixed)

    def loss(sol):
        return factory.metrics(sol)[problem.metric]

    return factory, loss


def _to_py(x):
    x = np.asarray(x)
    return float(x) if x.ndim == 0 else x.tolist()


def _flat(params: dict, columns=None) -> dict:
    """A point as table columns: a vector parameter one column per component (named by
    the problem's `columns`, else `name_i`)."""
    out = {}
    for k, v in params.items():
        if isinstance(v, list):
            names = component_names(k, np.shape(v), (columns or {}).get(k))
            out.update(zip(names, map(float, np.ravel(v)), strict=True))
        else:
            out[k] = v
    return out
