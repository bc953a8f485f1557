"""Methods a user adds to a registered problem (`studies.add_method`): a researcher's own
estimator beside a problem's estimator and baselines, on the same draws, scored by the
same metrics, swept, tuned and compared like them, without subclassing or re-registering
the problem. The registry of added methods is `visjax.studies._registry`'s; this module
holds what a built problem carries: `Method` and the problem with them, `WithMethods`.
"""

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any, final

import equinox as eqx
import jax.numpy as jnp

from ._problem import AbstractProblem, Parameter


@dataclasses.dataclass(frozen=True)
class Method:
    """A method added to a problem (`studies.add_method` makes it).

    **Fields:** `name`; `solve`, `(problem, params, inputs) -> solution`: the problem as
    built (its fields: the sample times, the camera, the truth, ...), every parameter
    (defaults filled in, the problem's own included) and one draw (`problem.inputs(key)`);
    pure JAX, with a `result` (a visjax `RESULTS` item) on the solution, never raising for
    a value; `parameters`: `(name, Parameter)` pairs, this method's tunable parameters;
    `like`: the problem's method whose solutions this one's resemble, so the problem scores
    it (`metrics`), draws it (`figure`) and counts its updates as that method's; `metrics`:
    `(problem, solution) -> {name: array}` instead (the problem's metric names); `where`:
    the module and function that added it (for messages)."""

    name: str
    solve: Callable[..., Any]
    parameters: tuple[tuple[str, Parameter], ...] = ()
    like: str | None = None
    metrics: Callable[..., Any] | None = None
    where: str = ""


def check_added(problem: AbstractProblem, added: tuple[Method, ...], name: str) -> None:
    """The added methods fit the built `problem` (registered as `name`): no name of the
    problem's own methods or parameters taken, `like` one of its methods. **Raises:**
    `ValueError` naming both sides of a clash."""
    own = set(problem.methods)
    specs = problem.parameters()
    for m in added:
        if m.name in own:
            raise ValueError(
                f"problem {name!r} has a method {m.name!r} of its own ({problem.title}); the "
                f"method added by {m.where} needs another name."
            )
        if m.like is not None and m.like not in own:
            raise ValueError(
                f"method {m.name!r} of problem {name!r} (added by {m.where}): like={m.like!r} "
                f"is not one of the problem's methods {sorted(own)}."
            )
        clash = sorted(set(dict(m.parameters)) & set(specs))
        if clash:
            raise ValueError(
                f"method {m.name!r} of problem {name!r} (added by {m.where}): parameter(s) "
                f"{clash} are the problem's own; name them differently (e.g. "
                f"{m.name}_{clash[0]})."
            )


@final
class WithMethods(AbstractProblem):
    """A problem with methods added to it (`studies.add_method`): the problem's own methods
    first, then the added ones, on the same `inputs`, scored by its `metrics`; every
    other part of the problem (its data parameters, truth, trivial estimate, settings,
    figures) is the problem's. Built by `studies.problem` and the command line when a
    problem has added methods; `base` is the problem itself."""

    base: AbstractProblem
    added: tuple[Method, ...] = eqx.field(static=True)
    base_names: tuple[str, ...] = eqx.field(static=True)  # the problem's own parameters

    def __init__(self, base: AbstractProblem, added: tuple[Method, ...]):
        self.base, self.added = base, tuple(added)
        self.base_names = tuple(base.parameters())  # concrete here; `solve` runs traced

    # -- the problem's own class settings ----------------------------------------------

    @property
    def methods(self) -> tuple[str, ...]:
        return tuple(self.base.methods) + tuple(m.name for m in self.added)

    @property
    def metric(self) -> str:
        return self.base.metric

    @property
    def label(self) -> str:
        return self.base.label

    @property
    def grid(self) -> str:
        return self.base.grid

    @property
    def defaults_label(self) -> str:
        return self.base.defaults_label

    @property
    def trivial_label(self) -> str:
        return self.base.trivial_label

    @property
    def data_parameters(self) -> tuple[str, ...]:
        return self.base.data_parameters

    @property
    def structural_parameters(self) -> tuple[str, ...]:
        return self.base.structural_parameters

    @property
    def title(self) -> str:
        return self.base.title

    @property
    def columns(self) -> Mapping[str, Any]:
        return self.base.columns

    @property
    def units(self) -> Mapping[str, str]:
        return self.base.units

    @property
    def scored(self) -> bool:
        return self.base.scored

    def _own(self, method: str) -> Method | None:
        return next((m for m in self.added if m.name == method), None)

    # -- parameters --------------------------------------------------------------------

    def parameters(self) -> dict[str, Parameter]:
        specs = dict(self.base.parameters())
        for m in self.added:
            specs.update(m.parameters)
        return specs

    def method_parameters(self, method: str) -> tuple[str, ...]:
        m = self._own(method)
        if m is None:
            return self.base.method_parameters(method)
        return tuple(name for name, _ in m.parameters)

    def resolve(self, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
        params = dict(params or {})
        base = set(self.base_names)
        out = self.base.resolve({k: v for k, v in params.items() if k in base})
        extra = {k: v for k, v in params.items() if k not in base}
        unknown = sorted(set(extra) - {n for m in self.added for n, _ in m.parameters})
        if unknown:
            raise ValueError(
                f"{self.title}: unknown parameter(s) {unknown}; it takes "
                f"{sorted(self.parameters())}."
            )
        for m in self.added:
            for name, spec in m.parameters:
                value = spec.value
                if name in extra:
                    given = jnp.asarray(extra[name], dtype=value.dtype)
                    out[name] = jnp.broadcast_to(given, value.shape)
                else:
                    out[name] = jnp.asarray(value)
        return out

    def _base_params(self, params: Mapping[str, Any]) -> dict[str, Any]:
        return {k: v for k, v in params.items() if k in self.base_names}

    def at(self, params: Mapping[str, Any]) -> "WithMethods":
        return eqx.tree_at(lambda p: p.base, self, self.base.at(params))

    def structured(self, params: Mapping[str, Any]) -> "WithMethods":
        base = self.base.structured(self._base_params(params))
        return self if base is self.base else eqx.tree_at(lambda p: p.base, self, base)

    def gains(self, params: Mapping[str, Any]) -> dict:
        p = self.resolve(params)
        own = {n: jnp.asarray(p[n]).tolist() for m in self.added for n, _ in m.parameters}
        return self.base.gains(self._base_params(p)) | own

    def checks(self, params: Mapping[str, Any]) -> dict:
        return self.base.checks(self._base_params(self.resolve(params)))

    def check_lines(self, summary: Mapping[str, Any]) -> list[str]:
        return self.base.check_lines(summary)

    # -- inputs, solutions, scores -----------------------------------------------------

    def inputs(self, key):
        return self.base.inputs(key)

    def solve(self, method: str, params: Mapping[str, Any], inputs, *, outputs=False):
        m = self._own(method)
        if m is None:
            return self.base.solve(method, self._base_params(params), inputs, outputs=outputs)
        return m.solve(self.base, params, inputs)

    def metrics(self, method: str, solution) -> dict:
        m = self._own(method)
        if m is None:
            return self.base.metrics(method, solution)
        if m.metrics is not None:
            return m.metrics(self.base, solution)
        return self.base.metrics(m.like, solution)

    def uncertainty(self, method: str, solution) -> dict:
        return {} if self._own(method) is not None else self.base.uncertainty(method, solution)

    def innovation(self, method: str, params, solution, inputs):
        if self._own(method) is not None:
            return None
        return self.base.innovation(method, self._base_params(params), solution, inputs)

    def trivial(self) -> dict:
        return self.base.trivial()

    def truth_outputs(self, method: str | None, solution) -> dict:
        m = self._own(method) if method is not None else None
        if m is not None and m.like is None:
            return {}
        return self.base.truth_outputs(method if m is None else m.like, solution)

    def updates(self, method: str) -> int:
        m = self._own(method)
        if m is None:
            return self.base.updates(method)
        return 1 if m.like is None else self.base.updates(m.like)

    def settings(self) -> dict:
        added = {
            m.name: {
                "added_by": m.where,
                "like": m.like,
                "parameters": [n for n, _ in m.parameters],
            }
            for m in self.added
        }
        return self.base.settings() | {"added_methods": added}

    def figure(self, method: str, solution):
        m = self._own(method)
        if m is None:
            return self.base.figure(method, solution)
        if m.like is not None:
            fig = self.base.figure(m.like, solution)
            title = fig.get_suptitle()  # the like method's name in it: this method's
            if title.endswith(f": {m.like}"):
                fig.suptitle(title.removesuffix(m.like) + method)
            return fig
        return AbstractProblem.figure(self, method, solution)
