"""`AbstractProblem`: one definition of "estimate X from Y" that every study speaks.

A problem holds its inputs (a scene, or a user's data file, as arrays), says how one noisy
draw of the measurements is made from a PRNG key (`inputs`), how each method estimates
from them (`solve`: the paper's estimator and every baseline), which parameters those
methods take (`parameters`: defaults, units, positivity) and how a solution is scored
(`metrics`). `evaluate`, `compare`, `sweep` and `tune` take any problem; the command line's
`run|compare|sweep|tune` verbs take any registered one (`register_problem`).
"""

import abc
import dataclasses
import hashlib
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._results import RESULTS, all_finite, result_names
from .._util import did_you_mean
from ._study import Result


class Parameter(eqx.Module):
    """A tunable parameter of a problem's methods.

    **Fields:** `default` (a float, or nested tuples of floats for an array parameter: the
    published value where there is one); `units`; `positive` (the value must stay above 0:
    `tune` then optimises its logarithm); `doc` (one line: what it is, where it comes
    from); `nonnegative` (the value must not be below 0, e.g. a noise level); `span`
    (`(low, high)`, both positive: the range `compare --tune` searches, log-uniform;
    default a decade either side of a positive scalar default, `None` for an array or a
    parameter that may be 0 or negative); `tunable` (`False`: `compare --tune` leaves it
    at its default, e.g. an initial guess that every method shares). A scalar given for an
    array parameter is broadcast to its shape (one value for every component).
    """

    default: Any = eqx.field(static=True)
    units: str = eqx.field(static=True, default="")
    positive: bool = eqx.field(static=True, default=True)
    doc: str = eqx.field(static=True, default="")
    nonnegative: bool = eqx.field(static=True, default=False)
    span: tuple[float, float] | None = eqx.field(static=True, default=None)
    tunable: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        if self.span is not None:
            lo, hi = self.span
            if not (0 < lo < hi < np.inf):
                raise ValueError(f"`span` must be (low, high), 0 < low < high; got {self.span}.")

    @property
    def search_span(self) -> tuple[float, float] | None:
        """The range `compare --tune` searches (`span`; by default a decade either side of
        a positive scalar default), or `None`: not searched."""
        if not self.tunable:
            return None
        if self.span is not None:
            return (float(self.span[0]), float(self.span[1]))
        v = self.value
        if v.ndim == 0 and self.positive and v > 0:
            return (float(v) / 10, float(v) * 10)
        return None

    @property
    def value(self) -> np.ndarray:
        """The default as a float array."""
        return np.asarray(self.default, float)


def noise_parameter(noise_px) -> Parameter:
    """The `noise_px` parameter of a problem whose draws add Gaussian pixel noise: a data
    parameter (`AbstractProblem.at`: it sets the problem's own `noise_px` field), so a
    sweep over noise levels is one compiled program; its default the problem's level."""
    try:
        default = float(noise_px)
    except (TypeError, jax.errors.ConcretizationTypeError):
        default = 0.0  # traced: shown only; `resolve` takes the problem's own field
    return Parameter(
        default, "px", False, "standard deviation of the Gaussian pixel noise of each draw",
        nonnegative=True,
    )  # fmt: skip


def robust_parameters(scale_px: float, gate: float) -> dict[str, Parameter]:
    """The parameters of a problem's robust baselines (its `robust` setting):
    `robust_scale_px`, the robust loss' scale (px), and `ekf_gate_tail`, one minus the
    probability of the EKF's outlier gate (searched over 1e-7 to 0.1, log-uniform)."""
    return {
        "robust_scale_px": Parameter(scale_px, "px", True, "the robust loss' scale"),
        "ekf_gate_tail": Parameter(
            1.0 - gate, "", True, "one minus the EKF gate's probability", span=(1e-7, 0.1)
        ),
    }


def noise_level(problem: "AbstractProblem", given=None):
    """The pixel noise of a study: `given` (a level, or levels) when not `None`, else the
    problem's own (its `noise_px` data parameter, a float; `None` for a problem without
    one)."""
    if given is not None:
        return given
    if "noise_px" not in problem.data_parameters:
        return None
    return float(problem.resolve()["noise_px"])


def as_default(x) -> float | tuple:
    """A number or an array as a `Parameter.default` (a float, or nested tuples)."""
    x = np.asarray(x, float)
    return float(x) if x.ndim == 0 else tuple(as_default(v) for v in x)


def _canonical(dtype):
    """`dtype` as JAX computes it now: float64 is float32 with `jax_enable_x64` off (a
    float32 study), without the warning an explicit float64 request gives there."""
    return jax.dtypes.canonicalize_dtype(dtype)


class AbstractProblem(eqx.Module):
    """What a researcher means by "estimate X from Y", as one Module (no closures: a rebuilt
    problem with equal fields reuses the compiled studies of the first).

    A subclass holds the inputs as fields (arrays; Python settings as static fields) and
    defines:

    - `methods` (class variable): the names of the methods, the estimator first, then
        its baselines;
    - `metric` (class variable): the headline metric, a key of `metrics`, to minimise; and
        `label`, that metric with its units (for tables and figures);
    - `parameters()`: name -> `Parameter`;
    - `inputs(key)`: one noisy draw of the measurements (a pytree of arrays; pure JAX;
        every method of one seed sees the same draw);
    - `solve(method, params, inputs, *, outputs=False)`: the method's solution (it has a
        `result`, a visjax `RESULTS` item, never raises for a value: `throw=False`
        inside), with `params` every parameter (defaults filled in, broadcast);
        `outputs=True` asks for the time series as well (for figures), which must not
        change the metrics;
    - `metrics(method, solution)`: name -> array, against the truth the problem holds
        (pure JAX; computed inside `vmap`).

    Optional: `own_parameters` (method -> the names of the parameters it uses,
    `method_parameters`: a grid axis no selected method uses is refused); `data_parameters`
    (the parameters that are data, not gains: each sets the
    problem's field of the same name, `at`, e.g. `noise_px`, `noise_parameter`);
    `structural_parameters` (each sets a static field of the same name, `structured`: a
    sliding window's length, a fit's bandwidth; a concrete value, a new compiled program
    per value, never a grid axis; its default the field's value); `label`
    (the headline metric with its units); `grid` (the default grid of
    `visjax sweep`, a `parse_grid` spec); `title` (a one-line description); `scored`
    (whether there is a truth to score against; default `True`); `settings()` (every
    stated setting, JSON-able); `updates(method)` (estimate updates per call, for the
    latency); `gains(params)` (the gains a parameter point stands for, JSON-able: where
    parameters are multipliers, the absolute gains); `checks(params)` (extra checks of a
    chosen point, e.g. a stability certificate, JSON-able, merged into the sweep's and
    tune's summaries) and `check_lines(summary)` (them, as printed lines);
    `innovation(method, params, solution, inputs)` (an observer's output error against the noise
    the data imply, `INNOVATION_GATE`: the check without the truth); `uncertainty(method,
    solution)` (the predicted standard deviations of what the metrics
    score, from a batch method's covariance; `compare` reports them); `trivial()` (the
    metrics of the trivial estimate, what one would answer knowing nothing: zero velocity,
    the initial depth guess; `run` and `compare` flag an estimate no better than it,
    `quality`); `figure(method,
    solution)` (a matplotlib figure of one solution against the truth); and
    `defaults_label` (what printed reports and figures call the default parameters:
    `"paper"` where they are a paper's published gains, else e.g. `"defaults"`; the
    summaries' JSON key stays `paper`); `columns` (a vector-valued metric, parameter or
    output field -> the names of its components' table columns, a tuple or a function of
    its shape: `{"rms": ("rms_v_x", ...), "v_hat": ("v_x", ...)}`; default `name_i`) and
    `units` (a column or field -> its unit, documented with the tables:
    `column_units`); `truth_outputs(method, solution)` (the truth at the solution's
    times, beside the estimate in `visjax run`'s table).
    """

    methods: eqx.AbstractClassVar[tuple[str, ...]]
    metric: eqx.AbstractClassVar[str]
    label: ClassVar[str] = ""
    grid: ClassVar[str] = ""
    defaults_label: ClassVar[str] = "paper"
    trivial_label: ClassVar[str] = "the trivial estimate"
    data_parameters: ClassVar[tuple[str, ...]] = ()
    structural_parameters: ClassVar[tuple[str, ...]] = ()
    own_parameters: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    columns: ClassVar[Mapping[str, Any]] = {}
    units: ClassVar[Mapping[str, str]] = {}

    @abc.abstractmethod
    def parameters(self) -> dict[str, Parameter]:
        """Name -> `Parameter` of the methods' tunable parameters."""

    @abc.abstractmethod
    def inputs(self, key) -> Any:
        """One noisy draw of the measurements from a PRNG key (pure JAX)."""

    @abc.abstractmethod
    def solve(self, method: str, params: Mapping[str, Any], inputs: Any, *, outputs=False):
        """The solution of `method` with every parameter in `params`, on `inputs`."""

    @abc.abstractmethod
    def metrics(self, method: str, solution) -> dict[str, jax.Array]:
        """Name -> array: how well `solution` (of `method`) did against the truth."""

    @property
    def title(self) -> str:
        return type(self).__name__

    @property
    def scored(self) -> bool:
        return True

    def settings(self) -> dict:
        return {}

    def updates(self, method: str) -> int:
        return 1

    def gains(self, params: Mapping[str, Any]) -> dict:
        data = set(self.data_parameters)
        return {k: np.asarray(v).tolist() for k, v in self.resolve(params).items() if k not in data}

    def checks(self, params: Mapping[str, Any]) -> dict:
        return {}

    def check_lines(self, summary: Mapping[str, Any]) -> list[str]:
        return []

    def uncertainty(self, method: str, solution) -> dict[str, jax.Array]:
        """Name -> array: the standard deviation of the estimate that the metrics score, as
        the method predicts it (a batch fit's covariance, $\\hat\\sigma^2(J^TJ)^{-1}$,
        propagated to the scored quantity), named `<metric>_std` after the metric whose
        spread it predicts; the same names for every method, NaN where a method predicts
        none (an observer). `compare` reports them beside the metrics
        (`None` where NaN). Default: none."""
        return {}

    def truth_outputs(self, method: str | None, solution) -> dict[str, Any]:
        """Output field -> the true value at `solution.ts` (the solution's saved times),
        for the fields of `method`'s outputs that have a truth: the tables of `visjax run`
        put each beside its estimate (`<column>_true`, `solution_table`). Default: none."""
        return {}

    def trivial(self) -> dict[str, jax.Array]:
        """Name -> array: the metrics of the trivial estimate (`trivial_label`: what one
        would answer knowing nothing, e.g. zero velocity or the initial guess held), with
        the names of `metrics`, against the same truth. An estimate whose headline metric
        is not below `QUALITY_RATIO` times the trivial one's is worse than no estimate:
        `run` reports it with the result `worse_than_trivial` and `compare` counts it
        (`quality`). Default: none (no such check)."""
        return {}

    def innovation(self, method: str, params: Mapping[str, Any], solution, inputs):
        """The output error of an observer against the noise level the data imply
        (`visjax.estimators.Innovation`), for a solution of `method` with `params` made
        with `outputs=True` on `inputs`: a check of the run without the truth. `run`
        reports it in `quality` (`innovation`) and warns where its `ratio` exceeds
        `INNOVATION_GATE`. Default: `None` (no such check: a method that is not an
        observer)."""
        return None

    def figure(self, method: str, solution):
        """A figure of one solution (made with `outputs=True`): each saved output field
        over time. Problems override it to draw the truth beside the estimate."""
        import matplotlib.pyplot as plt

        fields = _output_fields(solution)
        if not fields:  # no time series (a scalar estimate): say so on the figure
            fig, ax = plt.subplots(figsize=(7, 2.2))
            ax.axis("off")
            ax.text(0.5, 0.5, "no time series saved", ha="center", va="center")
            fig.suptitle(f"{self.title}: {method}")
            return fig
        fig, axes = plt.subplots(len(fields), 1, figsize=(7, 2.2 * len(fields)), squeeze=False)
        for ax, (name, values) in zip(axes[:, 0], fields.items()):
            names = component_names(name, values.shape[1:], self.columns.get(name))
            lines = ax.plot(np.asarray(solution.ts), values.reshape(values.shape[0], -1))
            ax.set_ylabel(f"{name} [{self.units.get(name, '?')}]")  # `?`: no `units` given
            if 1 < len(lines) <= 8:
                ax.legend(lines, names, fontsize=7, ncol=min(4, len(lines)))
        axes[-1, 0].set_xlabel("time [s]")
        fig.suptitle(f"{self.title}: {method}")
        fig.tight_layout()
        return fig

    # -- helpers every study uses ------------------------------------------------------

    def defaults(self) -> dict[str, np.ndarray]:
        """Every parameter at its default value."""
        return {name: p.value for name, p in self.parameters().items()}

    def resolve(self, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """`params` completed with the defaults of the parameters it does not name, each
        broadcast to its parameter's shape (traceable; no value check).

        **Raises:** `ValueError` naming an unknown parameter."""
        specs = self.parameters()
        params = dict(params or {})
        unknown = sorted(set(params) - set(specs))
        if unknown:
            raise ValueError(
                f"{self.title}: unknown parameter(s) {unknown}; it takes {sorted(specs)}."
            )
        out = {}
        for name, spec in specs.items():
            value = spec.value
            if name in params:
                given = jnp.asarray(params[name], dtype=_canonical(value.dtype))
                out[name] = jnp.broadcast_to(given, value.shape)
            elif name in self.data_parameters:  # the problem's own (traced) value
                own = jnp.asarray(getattr(self, name), dtype=_canonical(value.dtype))
                out[name] = jnp.broadcast_to(own, value.shape)
            else:
                out[name] = jnp.asarray(value)
        return out

    def at(self, params: Mapping[str, Any]) -> "AbstractProblem":
        """The problem with its data parameters (`data_parameters`) set from `params`: each
        replaces the (non-static) field of the same name, such as a noise level `noise_px`,
        so `inputs` reads it from `self` and a sweep over it is one `vmap`. Every study
        calls it before `inputs` and `solve` (traceable)."""
        names = [n for n in self.data_parameters if n in params]
        if not names:
            return self
        return eqx.tree_at(
            lambda p: [getattr(p, n) for n in names], self, [params[n] for n in names]
        )

    def structured(self, params: Mapping[str, Any]) -> "AbstractProblem":
        """The problem with its structural parameters (`structural_parameters`) set from
        `params`: each replaces the static field of the same name (an int field takes a
        whole number of at least 1), so the methods are compiled for it. Every study calls
        it before `at`.

        **Raises:** `ValueError` for a traced value or one of the wrong kind."""
        names = [n for n in self.structural_parameters if n in params]
        if not names:
            return self
        changes = {}
        for n in names:
            try:
                v = float(np.asarray(params[n]))
            except (TypeError, jax.errors.ConcretizationTypeError) as e:
                raise ValueError(
                    f"{self.title}: {n!r} is a structural parameter (it sets the size of a "
                    "compiled program): give it a concrete number, not a traced or an array "
                    "value; it cannot be swept in one compiled program."
                ) from e
            if isinstance(getattr(self, n), int):
                if not (np.isfinite(v) and v == round(v) and v >= 1):
                    raise ValueError(f"{self.title}: {n!r} must be a whole number >= 1; got {v}.")
                v = int(round(v))
            elif not (np.isfinite(v) and v > 0):
                raise ValueError(f"{self.title}: {n!r} must be positive and finite; got {v}.")
            changes[n] = v
        return dataclasses.replace(self, **changes)

    def method_parameters(self, method: str) -> tuple[str, ...]:
        """The tunable parameters `method` uses (its gains; the data parameters, such as
        `noise_px`, belong to every method and are not listed): `own_parameters[method]`
        where the problem states it (those the problem has: a robust setting's only when
        it is robust), else every parameter that is neither data nor structural. A sweep
        or a tuning of selected methods refuses a grid axis that none of them uses."""
        specs = self.parameters()
        if method in self.own_parameters:
            return tuple(n for n in self.own_parameters[method] if n in specs)
        skip = set(self.data_parameters) | set(self.structural_parameters)
        return tuple(n for n in specs if n not in skip)

    def check_method(self, method: str | None) -> str:
        """The method's name (`None`: the estimator, the first). **Raises:** `ValueError`
        naming the problem's methods (the closest one suggested) and how to add one."""
        if method is None:
            return self.methods[0]
        if method not in self.methods:
            hint = did_you_mean(method, self.methods)
            raise ValueError(
                f"{self.title}: unknown method {method!r}{hint}; its methods are "
                f"{list(self.methods)} (a method of your own: visjax.studies.add_method)."
            )
        return method

    def check_methods(self, methods: Sequence[str | None] | None) -> tuple[str, ...]:
        """The methods a study runs: `methods` (each checked, `check_method`, a `None` entry
        the estimator; in the given order, once each), or every method when `None`."""
        if methods is None:
            return tuple(self.methods)
        if isinstance(methods, str) or not len(methods):
            raise ValueError(f"`methods` must be a non-empty list of names; got {methods!r}.")
        return tuple(dict.fromkeys(self.check_method(m) for m in methods))

    def check_axes(self, names, methods: Sequence[str]) -> None:
        """A sweep's or a tuning's parameter names (`names`) for `methods`: a parameter of
        the problem that is neither data nor used by any of them (`method_parameters`) is
        refused (the methods would be swept over a parameter they ignore)."""
        fixed = [n for n in names if n in self.structural_parameters]
        if fixed:
            raise ValueError(
                f"{self.title}: {fixed} set the size of a compiled program (structural "
                "parameters): they cannot be a grid axis; give one value (--set, `fixed`) or "
                "let `compare --tune` search them."
            )
        used = set(self.data_parameters).union(*(self.method_parameters(m) for m in methods))
        idle = [n for n in names if n in self.parameters() and n not in used]
        if idle:
            owners = {n: [m for m in self.methods if n in self.method_parameters(m)] for n in idle}
            said = "; ".join(f"{n!r} is used by {owners[n] or 'no method'}" for n in idle)
            raise ValueError(
                f"{self.title}: {said}, not by the selected method(s) {list(methods)}: drop "
                "it from the grid or select a method that uses it (--methods)."
            )


def _output_fields(solution) -> dict[str, np.ndarray]:
    outputs = solution.outputs
    if outputs is None:
        raise ValueError("the solution saved no outputs: solve it with `outputs=True`.")
    if isinstance(outputs, eqx.Module | dict):
        items = outputs.items() if isinstance(outputs, dict) else vars(outputs).items()
        return {k: np.asarray(v) for k, v in items if v is not None and np.ndim(v) >= 1}
    return {"output": np.asarray(outputs)}


def check_values(problem: AbstractProblem, params: Mapping[str, Any], where: str) -> None:
    """`ValueError` (before any run) if a value of `params` is not finite, or not positive
    for a positive parameter."""
    specs = problem.parameters()
    for name, value in params.items():
        if name not in specs:
            raise ValueError(
                f"{where}: unknown parameter {name!r} of {problem.title}; it takes {sorted(specs)}."
            )
        v = np.asarray(value, float)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{where}: parameter {name!r} has non-finite values: {v}.")
        if specs[name].positive and np.any(v <= 0):
            raise ValueError(f"{where}: parameter {name!r} must be positive; got {v}.")
        if specs[name].nonnegative and np.any(v < 0):
            raise ValueError(f"{where}: parameter {name!r} must not be negative; got {v}.")


def fingerprint(problem: AbstractProblem) -> str:
    """A digest of the problem: its type, its static fields and its arrays' bytes. Two
    problems with equal fields have equal fingerprints (the studies' compilation caches
    are keyed by it)."""
    leaves, treedef = jax.tree_util.tree_flatten(problem)
    h = hashlib.sha1(f"{type(problem).__module__}.{type(problem).__qualname__}".encode())
    h.update(str(treedef).encode())
    for leaf in leaves:
        if isinstance(leaf, jax.Array | np.ndarray | np.generic | float | int | bool):
            a = np.asarray(leaf)
            h.update(f"{a.dtype}{a.shape}".encode())
            h.update(np.ascontiguousarray(a).tobytes())
        else:
            h.update(repr(leaf).encode())
    return h.hexdigest()


class _Run(eqx.Module):
    """`(point, key) -> solution` and `solution -> metrics` of one method of a problem.

    A Module: the problem's arrays (its data, camera, scene) and the fixed parameters are
    leaves, traced through `filter_jit` and passed as arguments to a sweep's compiled
    chunk, so a second problem of equal shapes and settings reuses every compiled program,
    and `jax.grad` reaches the problem's data. Only Python settings (sizes, method names,
    flags) are static."""

    problem: AbstractProblem
    method: str = eqx.field(static=True)
    params: dict  # every parameter: the fixed ones, the rest at their defaults (resolved)

    def __call__(self, point, key):
        params = dict(self.params)
        for name, value in point.items():
            if name in self.problem.structural_parameters:
                raise ValueError(
                    f"{self.problem.title}: {name!r} is a structural parameter: not a point's "
                    "(a grid axis); set it once (`fixed`)."
                )
            if name not in params:
                raise ValueError(
                    f"{self.problem.title}: unknown parameter {name!r}; it takes {sorted(params)}."
                )
            given = jnp.asarray(value, dtype=params[name].dtype)
            params[name] = jnp.broadcast_to(given, params[name].shape)
        problem = self.problem.at(params)
        return problem.solve(self.method, params, problem.inputs(key))

    def metrics(self, solution):
        return self.problem.metrics(self.method, solution)


def run_identity(run: _Run) -> str:
    """A digest of what a problem's run computes (the problem's fingerprint, the method
    and the resolved parameters): the parts of two sweeps are interchangeable only when
    these, their points, seeds and chunk agree."""
    h = hashlib.sha1(fingerprint(run.problem).encode())
    h.update(run.method.encode())
    for name, value in sorted(run.params.items()):
        a = np.asarray(value)
        h.update(f"{name}{a.dtype}{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


class FunctionProblem(AbstractProblem):
    """A plain function as a problem, so that every study (`evaluate`, `compare`, `sweep`,
    `tune`) takes it through its one signature.

    `FunctionProblem(solve, metrics, *, metric="", inputs=None, title=...)`:

    - `solve`: `(params, key) -> solution`, a pure JAX function of one parameter point
        (any pytree: what the study's points hold, one point at a time) and one PRNG key:
        it builds the estimator from the parameters and the noisy measurements from the
        key, and runs it (`throw=False`); the solution has a `result` (a visjax `RESULTS`
        item). Or a dict name -> such functions: several methods (the first the
        estimator), compared on identical inputs.
    - `metrics`: `solution -> {name: array}` (pure JAX, computed inside the batch).
    - `metric`: the headline metric, a key of `metrics` (what `tune` minimises and
        `held_out` reports); default none.
    - `inputs`: `key -> inputs`, the noisy measurements of one seed, shared by every
        method; `solve` then takes `(params, inputs)`. Default: the key itself.

    A function has no named parameters: a study's points are passed to it as they are
    (no defaults, no positivity checks but `tune`'s), so `parameters()` is empty.
    """

    _solve: Any
    _metrics: Any
    _inputs: Any
    _metric: str = eqx.field(static=True)
    _title: str = eqx.field(static=True)

    def __init__(self, solve, metrics, *, metric: str = "", inputs=None, title: str = ""):
        funcs = solve if isinstance(solve, Mapping) else {"function": solve}
        if not funcs or not all(callable(f) for f in funcs.values()):
            raise ValueError(
                "`solve` must be a function `(params, key) -> solution` or a non-empty dict "
                f"name -> such functions; got {solve!r}."
            )
        if not callable(metrics):
            raise ValueError(f"`metrics` must be a function solution -> dict; got {metrics!r}.")
        if inputs is not None and not callable(inputs):
            raise ValueError(f"`inputs` must be a function key -> inputs; got {inputs!r}.")
        self._solve = dict(funcs)
        self._metrics = metrics
        self._inputs = inputs
        self._metric = str(metric)
        self._title = title or f"function {_name(next(iter(funcs.values())))}"

    @property
    def methods(self) -> tuple[str, ...]:  # the class variable of other problems
        return tuple(self._solve)

    @property
    def metric(self) -> str:
        return self._metric

    @property
    def title(self) -> str:
        return self._title

    def parameters(self) -> dict[str, Parameter]:
        return {}

    def resolve(self, params=None):
        return {} if params is None else params

    def gains(self, params) -> dict:
        return jax.tree_util.tree_map(lambda v: np.asarray(v).tolist(), dict(params or {}))

    def inputs(self, key):
        return key if self._inputs is None else self._inputs(key)

    def solve(self, method, params, inputs, *, outputs=False):
        return self._solve[method](params, inputs)

    def metrics(self, method, solution):
        return self._metrics(solution)


def _name(f) -> str:
    f = getattr(f, "__wrapped__", f)
    return getattr(f, "__qualname__", type(f).__name__)


class _FunctionRun(eqx.Module):
    """A `FunctionProblem`'s run of one method: the study's point passed as it is (the
    point of `evaluate`, `params`, when a study gives none)."""

    problem: FunctionProblem
    method: str = eqx.field(static=True)
    params: Any

    def __call__(self, point, key):
        params = point if jax.tree_util.tree_leaves(point) else self.params
        return self.problem.solve(self.method, params, self.problem.inputs(key))

    def metrics(self, solution):
        return self.problem.metrics(self.method, solution)


def runner(
    problem: AbstractProblem, method: str | None = None, fixed=None, check=True
) -> "_Run | _FunctionRun":
    """The run of one method of a problem (`run(point, key) -> solution`,
    `run.metrics(solution)`): the parameters not in `point` from `fixed`, then the
    defaults (a `FunctionProblem`: the point as it is, `fixed` when it is empty).
    `check=False` (traceable `fixed`, as `evaluate` takes them): no value check."""
    method = problem.check_method(method)
    if isinstance(problem, FunctionProblem):
        return _FunctionRun(problem, method, fixed)
    fixed = dict(fixed or {})
    if check:
        check_values(problem, fixed, "fixed parameters")
    problem = problem.structured(fixed)
    return _Run(problem, method, problem.resolve(fixed))


def component_names(name: str, shape, names=None) -> list[str]:
    """The column names of the components of an array of `shape` (one row's) named
    `name`: `names` (a sequence, or a function of the shape returning one) where it has
    one per component, else `name_i` (`name_i_j` for a matrix; indices from 0)."""
    shape = tuple(shape)
    if callable(names):
        names = names(shape)
    size = math.prod(shape)
    if names is not None and len(names) == size:
        return [str(n) for n in names]
    return [f"{name}_{'_'.join(map(str, ix))}" for ix in np.ndindex(*shape)]


class Evaluation(Result, eqx.Module):
    """What `evaluate` returns, one entry per key: `metrics` (name -> array with a leading
    key axis; NaN where the run failed), `result` (a `RESULTS` item per key) and
    `failed_sample` (per key, -1 if none). A pytree (it comes out of `jit` and `grad`);
    `to_pandas()`: one row per key (`key`, `result`, `failed_sample`, the metrics, an
    array metric one column per component, named by the problem's `columns`)."""

    metrics: dict
    result: RESULTS
    failed_sample: jax.Array
    columns: tuple = eqx.field(static=True, default=())  # the problem's, as items

    def to_pandas(self):
        import pandas as pd

        failed = np.asarray(self.failed_sample)
        rows = {"key": np.arange(failed.shape[0]), "result": result_names(self.result)}
        rows["failed_sample"] = failed
        for name, values in self.metrics.items():
            values = np.asarray(values)
            if values.ndim == 1:
                rows[name] = values
            else:
                names = component_names(name, values.shape[1:], dict(self.columns).get(name))
                rows.update(zip(names, values.reshape(failed.shape[0], -1).T, strict=True))
        return pd.DataFrame(rows)


def evaluate(
    problem: AbstractProblem,
    params: Mapping[str, Any] | None = None,
    keys: Any = None,
    *,
    method: str | None = None,
) -> Evaluation:
    """One parameter point of `problem` over noise keys: its metrics per key.

    A pure JAX function of `params` (the parameters it names; the others at their
    defaults): it works under `jit`, and `jax.grad` of a metric's mean gives the gradient
    with respect to the gains. A failed run (any result code but `successful`, or a
    metric that is not finite) has NaN metrics and its code, never its frozen state's
    numbers.

    **Arguments:** `problem`; `params` (name -> value, default none: every default);
    `keys` (a 1-D array of int seeds or of typed PRNG keys; default the seed 0);
    `method` (default: the estimator).
    """
    method = problem.check_method(method)
    keys = jnp.arange(1) if keys is None else jnp.asarray(keys)
    if not jnp.issubdtype(keys.dtype, jax.dtypes.prng_key):
        if not jnp.issubdtype(keys.dtype, jnp.integer) or keys.ndim != 1:
            raise ValueError(
                "`keys` must be a 1-D array of integer seeds or of typed PRNG keys "
                f"(jax.random.key); got dtype {keys.dtype} and shape {keys.shape}."
            )
        keys = jax.vmap(jax.random.key)(keys)
    values, result, failed = _evaluate_keys(runner(problem, method, params, check=False), keys)
    return Evaluation(values, result, failed, tuple(problem.columns.items()))


@eqx.filter_jit  # compiled once per problem type, shapes and settings (its arrays traced)
def _evaluate_keys(run, keys):
    def one(key):
        sol = run({}, key)
        values = {n: jnp.asarray(v) for n, v in run.metrics(sol).items()}
        result = sol.result
        fresh = (result == RESULTS.successful) & ~all_finite(values)
        result = RESULTS.where(fresh, RESULTS.nonfinite_output, result)
        ok = result == RESULTS.successful
        values = {n: jnp.where(ok, v, jnp.nan) for n, v in values.items()}
        failed = jnp.asarray(getattr(sol, "failed_sample", -1), jnp.int32)
        return values, result, failed

    return jax.vmap(one)(keys)


def solution(
    problem: AbstractProblem,
    params: Mapping[str, Any] | None = None,
    key: Any = 0,
    *,
    method: str | None = None,
):
    """One run of one method of `problem` with its time series: the solution of
    `problem.solve(method, params, problem.inputs(key), outputs=True)`, compiled once per
    problem and method (`equinox.filter_jit`). What `visjax run PROBLEM`, the figures and
    the papers' reproductions are made of; `evaluate` is its batched, metrics-only
    counterpart.

    **Arguments:** `problem`; `params` (name -> value; the others at their defaults);
    `key` (an int seed or a typed PRNG key; default the seed 0: every method of one seed
    sees the same draw); `method` (default: the estimator).

    **Returns:** the method's solution (its `result` says whether it succeeded; it never
    raises for a value).
    """
    method = problem.check_method(method)
    if not jnp.issubdtype(jnp.asarray(key).dtype, jax.dtypes.prng_key):
        if isinstance(key, bool) or not isinstance(key, int | np.integer) or key < 0:
            raise ValueError(f"`key` must be a non-negative int seed or a PRNG key; got {key!r}.")
        key = jax.random.key(int(key))
    return _solve_outputs(runner(problem, method, params, check=False), key)


@eqx.filter_jit  # the problem's arrays and the parameters traced: a new file reuses it
def _solve_outputs(run, key):
    if isinstance(run, _FunctionRun):
        return run({}, key)
    problem = run.problem.at(run.params)
    return problem.solve(run.method, run.params, problem.inputs(key), outputs=True)


def method_runs(problem: AbstractProblem, params=None, methods=None, method_params=None) -> dict:
    """name -> `(inputs -> solution, the problem it runs on)` of every method, or of
    `methods` (for `compare`); `method_params`: method -> parameters of that method alone
    (a tuned point), over `params`."""
    each = dict(method_params or {})

    def make(method):
        given = {**dict(params or {}), **dict(each.get(method, {}))}
        own = problem.structured(given)
        resolved = own.resolve(given)
        own = own.at(resolved)

        def solve(inputs):
            return own.solve(method, resolved, inputs)

        return solve, own

    return {m: make(m) for m in problem.check_methods(methods)}


def as_json(values: Mapping[str, Any], ok: bool, nullable: bool = False) -> dict:
    """Metrics as JSON-able numbers (a float, or a list for an array); `None` if the run
    failed, and (`nullable`) in place of each NaN."""

    def number(x):
        return None if nullable and not np.isfinite(x) else float(x)

    out = {}
    for name, v in values.items():
        a = np.asarray(v, float)
        if not ok:
            out[name] = None
        else:
            out[name] = (
                number(a) if a.ndim == 0 else np.vectorize(number, otypes=[object])(a).tolist()
            )
    return out


QUALITY_RATIO = 1.0
"""An estimate whose headline metric is at least this multiple of the trivial estimate's
(`AbstractProblem.trivial`) is reported as `worse_than_trivial`: no better than answering
nothing."""


INNOVATION_GATE = 3.0
"""An observer whose output error is more than this multiple of the noise level its data
imply (`visjax.estimators.Innovation.ratio`, the worst output) is reported with a warning,
`innovation_too_large`: it lags its measurements or has lost them. Three standard deviations,
the usual gate of an innovation test. A check without the truth, and a one-sided one: an
output error within the gate does not show that the estimate is right (the velocity
estimator's chatter, in its rates, leaves its output error small), and on noise-free data
any lag exceeds it."""


def quality(
    problem: AbstractProblem, values: Mapping[str, Any], trivial=None, innovation=None
) -> dict | None:
    """How a run's metrics (`values`, as `metrics` returns them) compare with the trivial
    estimate's (`problem.trivial()`): `judge`'s verdict on the headline metric (its
    largest entry); with `innovation` (`problem.innovation(...)`, the check without the
    truth), `judge_innovation`'s verdict under the key `innovation`, and the first flag
    that is not `"ok"` as `flag`. `None` for a problem with neither. `trivial`:
    `problem.trivial()` computed once (for many runs of one problem)."""
    if trivial is None:
        trivial = problem.trivial() if problem.scored else {}
    judged = {}
    if problem.metric in trivial and problem.metric in values:
        value = float(np.max(np.asarray(values[problem.metric], float)))
        base = float(np.max(np.asarray(trivial[problem.metric], float)))
        judged = judge(value, base, trivial_estimate=problem.trivial_label, metric=problem.metric)
    if innovation is not None:
        judged["innovation"] = judge_innovation(innovation)
        if judged.get("flag", "ok") == "ok":
            judged["flag"] = judged["innovation"]["flag"]
    return judged or None


def judge_innovation(innovation) -> dict:
    """An observer's `visjax.estimators.Innovation` judged: `{"output_rms", "noise_rms",
    "ratio", "threshold", "flag", "samples"}`, `flag` `"innovation_too_large"` when the
    ratio exceeds `INNOVATION_GATE` or is not finite, else `"ok"`."""
    ratio = float(np.asarray(innovation.ratio))
    return {
        "output_rms": np.asarray(innovation.output_rms, float).tolist(),
        "noise_rms": np.asarray(innovation.noise_rms, float).tolist(),
        "ratio": ratio if np.isfinite(ratio) else None,
        "threshold": INNOVATION_GATE,
        "samples": int(np.asarray(innovation.samples)),
        "flag": "ok" if np.isfinite(ratio) and ratio <= INNOVATION_GATE else "innovation_too_large",
    }


def judge(value: float, trivial: float, *, trivial_estimate: str, metric: str) -> dict:
    """An error `value` against the trivial estimate's error `trivial` (the same metric,
    over the same data): `{"trivial_estimate", "metric", "trivial", "ratio_to_trivial",
    "threshold", "flag"}`, `flag` `"worse_than_trivial"` when the ratio is at least
    `QUALITY_RATIO` (or not finite), else `"ok"`."""
    ratio = value / trivial if trivial > 0 else float("inf")
    worse = not np.isfinite(ratio) or ratio >= QUALITY_RATIO
    return {
        "trivial_estimate": trivial_estimate,
        "metric": metric,
        "trivial": float(trivial),
        "ratio_to_trivial": float(ratio) if np.isfinite(ratio) else None,
        "threshold": QUALITY_RATIO,
        "flag": "worse_than_trivial" if worse else "ok",
    }


def quality_line(judged: Mapping[str, Any]) -> str:
    """`judge`'s verdict as one printed line; `quality`'s, both parts, `; `-separated."""
    if "innovation" in judged:
        rest = {k: v for k, v in judged.items() if k != "innovation"}
        lines = [quality_line(rest)] if "ratio_to_trivial" in rest else []
        return "; ".join([*lines, innovation_line(judged["innovation"])])
    ratio = judged["ratio_to_trivial"]
    times = "not finite" if ratio is None else f"{ratio:.3g} times"
    verdict = "no better than it: not to be trusted" if judged["flag"] != "ok" else "below it"
    return (
        f"{judged['metric']} is {times} that of {judged['trivial_estimate']} "
        f"({judged['trivial']:.4g}): {verdict} (threshold {judged['threshold']:g})"
    )


def innovation_line(judged: Mapping[str, Any]) -> str:
    """`judge_innovation`'s verdict as one printed line."""
    ratio = judged["ratio"]
    times = "not finite" if ratio is None else f"{ratio:.3g} times"
    verdict = (
        "within it"
        if judged["flag"] == "ok"
        else "the observer lags its measurements or has lost them: not to be trusted"
    )
    return (
        f"output error {times} the noise level the data imply (worst output; gate "
        f"{judged['threshold']:g}): {verdict}"
    )


def point_names(problem: AbstractProblem, names: Sequence[str]) -> None:
    specs = problem.parameters()
    unknown = [n for n in names if n not in specs]
    if unknown:
        raise ValueError(
            f"{problem.title}: unknown parameter(s) {unknown}; it takes {sorted(specs)}."
        )


def held(sample_ts, values, t):
    """`values` (one per time of `sample_ts`) held at the times `t`: the last sample at or
    before each (1 ns of tolerance); pure JAX. How a truth sampled at one rate scores an
    estimate saved at another."""
    sample_ts = jnp.asarray(sample_ts)
    k = jnp.searchsorted(sample_ts, jnp.asarray(t) + 1e-9, side="right") - 1
    return jnp.asarray(values)[jnp.clip(k, 0, sample_ts.shape[0] - 1)]
