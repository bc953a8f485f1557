"""The registry of problems: a name -> a function that builds the problem, which the
command line's `run|compare|sweep|tune PROBLEM` verbs look up.

The three papers' problems are registered by `visjax.papers`. A user's problem is one line,
`visjax.studies.register_problem("name", build)`, in code run before the study (for the
command line: a module named with `visjax --import MODULE`, or an entry point of the group
`visjax.problems` in the package's metadata, `name = "package.module:build"`). A method
of your own joins a registered problem with `add_method` (no re-registration).
"""

import dataclasses
import importlib
import importlib.util
import inspect
import os
import pathlib
import re
import sys
import traceback
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from .._util import did_you_mean
from ..estimators import MAX_STEPS
from ..io import output_name
from ._methods import Method, WithMethods, check_added
from ._problem import AbstractProblem, Parameter

DEFAULT_RATE_HZ = 1000.0
"""The sample rate a scene is assumed to have, for the step count of its `--duration`,
when its builder states none (a `rate_hz` default): the papers' 1 kHz."""


@dataclasses.dataclass(frozen=True)
class Registered:
    """A registered problem: `name`, `build` (keyword options -> `AbstractProblem`; the
    command line passes `data`, `noise_px`, `duration`, `rate_hz` and `variant` when the
    user gives them), `variants` (named variants the study commands run one by one when
    none is chosen, e.g. the thesis' experiment sets; empty: none), `aliases` (other
    command names), `summary` (one line for `--help`)."""

    name: str
    build: Callable[..., AbstractProblem]
    variants: tuple[str, ...] = ()
    aliases: tuple[str, ...] = ()
    summary: str = ""

    def options(self) -> set[str]:
        """The keyword options `build` accepts."""
        params = inspect.signature(self.build).parameters.values()
        if any(p.kind is p.VAR_KEYWORD for p in params):
            return {"*"}
        return {p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}

    def check(self, data=None, duration=None, rate_hz=None, variants=None, robust=False) -> None:
        """The command line's options for this problem, checked before any work: a
        `ValueError` names an option it does not take (`robust`: its builder's `robust`
        option), an unknown variant, a scene's option given with a data file, a
        `--duration` whose samples (at `rate_hz`, the builder's default rate or
        `DEFAULT_RATE_HZ`) exceed `visjax.estimators.MAX_STEPS`. A method is checked by the
        built problem (`AbstractProblem.check_method`: its own methods and those added to
        it), not here: a builder's annotation does not say what it builds."""
        if data is not None and (duration is not None or rate_hz is not None):
            raise ValueError("--duration and --rate apply to the problem's scene, not to --data")
        if duration is not None:
            default = inspect.signature(self.build).parameters.get("rate_hz")
            rate = rate_hz
            if rate is None and default is not None and isinstance(default.default, int | float):
                rate = float(default.default)
            rate = DEFAULT_RATE_HZ if rate is None else rate
            if duration * rate > MAX_STEPS:
                raise ValueError(
                    f"--duration {duration:g} s at {rate:g} Hz makes {duration * rate:.3g} "
                    f"samples, more than a run takes ({MAX_STEPS:.0e}, "
                    "visjax.estimators.MAX_STEPS): give a shorter --duration"
                )
        accepted = self.options()
        given = {"data": data, "duration": duration, "rate_hz": rate_hz, "robust": robust or None}
        for option, value in given.items():
            if value is not None and "*" not in accepted and option not in accepted:
                raise ValueError(f"problem {self.name!r} takes no --{option.removesuffix('_hz')}")
        bad = [v for v in variants or () if v not in self.variants]
        if bad:
            hint = did_you_mean(bad[0], self.variants)
            raise ValueError(
                f"unknown variant(s) {bad} of problem {self.name!r}{hint}; choose from "
                f"{list(self.variants)}"
            )

    def make(self, **options) -> AbstractProblem:
        """The problem built with the options that are not `None`; a `ValueError` names
        an option this problem does not take."""
        given = {k: v for k, v in options.items() if v is not None}
        accepted = self.options()
        if "*" not in accepted:
            bad = sorted(set(given) - accepted)
            if bad:
                flags = ", ".join("--" + b.removesuffix("_px").removesuffix("_hz") for b in bad)
                raise ValueError(f"problem {self.name!r} takes no {flags}")
        try:
            problem = self.build(**given)
        except ValueError:  # the builder's own refusal of an option or a data file
            raise
        except Exception as e:
            raise UserCodeError(
                f"problem {self.name!r}: its builder {_where(self.build)} raised "
                f"{type(e).__name__}: {_first_line(e)}"
            ) from e
        if not isinstance(problem, AbstractProblem):
            raise UserCodeError(
                f"the builder of problem {self.name!r} ({_where(self.build)}) returned "
                f"{type(problem).__name__}, not a visjax.studies.AbstractProblem."
            )
        added = tuple(_ADDED.get(self.name, {}).values())
        if not added:
            return problem
        check_added(problem, added, self.name)
        return WithMethods(problem, added)


def build_problems(
    name: str, *, data=None, noise_px=None, duration=None, rate_hz=None, variants=None,
    every: bool = True, robust: bool = False, options=None,
) -> list[tuple[str | None, AbstractProblem]]:  # fmt: skip
    """The registered problem `name` built once, `[(None, problem)]`, or, for a problem
    with named variants, once per variant, `[(variant, problem), ...]`: those of
    `variants`, else every one when `every` (and no data file), else its default. The
    options go to its builder (`robust`: its `robust=True`; `options`: more of its keyword
    arguments; `None` values left out). **Raises:** `ValueError` for an unknown problem,
    variant or option (`Registered.check`)."""
    entry = registered(name)
    data = None if data is None else str(data)
    if noise_px is not None and np.ndim(noise_px):  # levels (compare): built at the largest
        noise_px = float(np.max(noise_px))
    entry.check(data, duration, rate_hz, variants)
    given = dict(
        data=data, noise_px=noise_px, duration=duration, rate_hz=rate_hz,
        robust=True if robust else None, **(options or {}),
    )  # fmt: skip
    if not variants and entry.variants and every and data is None:
        variants = entry.variants
    if variants:
        return [(v, entry.make(variant=v, **given)) for v in variants]
    return [(None, entry.make(**given))]


class UserCodeError(Exception):
    """An error raised by code that registers or builds a problem (a module given to
    `--import`, a plugin, a problem's builder): the message names the code and the error
    in one line; the original error, with its traceback, is the `__cause__`."""

    def user_traceback(self) -> str:
        """The traceback of the user's error (the `__cause__`), from its first frame
        outside visjax and the import machinery (empty for none)."""
        error = self.__cause__
        if error is None:
            return ""
        package = str(pathlib.Path(__file__).resolve().parents[1])
        frames = traceback.extract_tb(error.__traceback__)
        ours = ("<frozen importlib", "importlib/__init__.py", package)
        while frames and any(
            str(frames[0].filename).startswith(o) or o in frames[0].filename for o in ours
        ):
            frames = frames[1:]
        body = "".join(traceback.format_list(frames))
        last = "".join(traceback.format_exception_only(type(error), error))
        return "Traceback (most recent call last):\n" + body + last


def _where(f) -> str:
    f = getattr(f, "__wrapped__", f)
    return f"{getattr(f, '__module__', '?')}.{getattr(f, '__qualname__', type(f).__name__)}"


def load_module(name: str):
    """Import a user's module that registers problems (the command line's `--import`), as
    `python -m` would find it: the current folder first, then `sys.path`. **Returns:**
    the module. **Raises:** `ValueError` for a module that is not found (one line);
    `UserCodeError` for one that does not parse or raises on import (its error and
    traceback the cause)."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][\w]*(\.[A-Za-z_][\w]*)*", name):
        raise ValueError(f"--import {name!r}: not a module name (e.g. my_problems, pkg.mod)")
    here = os.getcwd()
    if here not in sys.path and "" not in sys.path:
        sys.path.insert(0, here)
    try:
        found = importlib.util.find_spec(name)
    except ModuleNotFoundError:  # a parent package missing
        found = None
    except Exception as e:  # a parent package that raises on import
        raise UserCodeError(
            f"--import {name}: your module raised {type(e).__name__}: {_first_line(e)}"
        ) from e
    if found is None:
        raise ValueError(
            f"--import {name}: no module named {name!r} in the current folder ({here}) or "
            "on sys.path"
        )
    try:
        return importlib.import_module(name)
    except Exception as e:
        raise UserCodeError(
            f"--import {name}: your module raised {type(e).__name__}: {_first_line(e)}"
        ) from e


_REGISTRY: dict[str, Registered] = {}
_ALIASES: dict[str, str] = {}
_LOADED = False


_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")


def _check_word(what: str, name) -> None:
    """A name the command line takes as a word: letters, digits, `_` and `-`
    (`point_depth`), starting with a letter (not an option's `-`)."""
    if not (isinstance(name, str) and _NAME.fullmatch(name)):
        raise ValueError(
            f"a {what}'s name must be letters, digits, '_' or '-', starting with a letter; "
            f"got {name!r}."
        )


def register_problem(
    name: str,
    build: Callable[..., AbstractProblem],
    *,
    variants: Sequence[str] = (),
    aliases: Sequence[str] = (),
    summary: str = "",
    replace: bool = False,
) -> Registered:
    """Register a problem under `name` for the command line and `problem`.

    `build(**options) -> AbstractProblem`, called with the options the user gives (any of
    `data`, `noise_px`, `duration`, `rate_hz`, `variant`); the options it does not accept
    are refused with a clear error. A name already taken is an error unless `replace`."""
    _check_word("problem", name)
    if not callable(build):
        raise TypeError(f"`build` of problem {name!r} must be callable.")
    names = {}
    for v in variants:  # each variant's output folder (`visjax.io.output_name`): one each
        other = names.setdefault(output_name(v), v)
        if other != v:
            raise ValueError(
                f"problem {name!r}: variants {other!r} and {v!r} would share the output "
                f"folder {output_name(v)!r}; rename one."
            )
    taken = name in _REGISTRY or name in _ALIASES
    if taken and not replace:
        raise ValueError(f"a problem named {name!r} is registered already (replace=True).")
    entry = Registered(name, build, tuple(variants), tuple(aliases), summary)
    _REGISTRY[name] = entry
    for alias in entry.aliases:
        _ALIASES[alias] = name
    return entry


_PENDING: dict = {}  # installed entry points, not loaded yet (loaded when named)
_BROKEN: dict[str, str] = {}  # entry points that failed to load: why


def _load() -> None:
    """The installed packages' entry points (group `visjax.problems`), listed once and
    loaded only when their problem is named: a plugin that fails to import breaks no
    other command (`--help` and `--version` included), and naming it says why in one
    line. (The papers' problems are registered by `visjax.papers`, which `import visjax`
    imports: every import of `visjax.studies` has run it already; `studies` never imports
    the layer above it.)"""
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    from importlib.metadata import entry_points

    try:
        found = list(entry_points(group="visjax.problems"))
    except Exception:  # a damaged installation's metadata: no plugins, the rest works
        found = []
    for ep in found:
        if ep.name in _REGISTRY or ep.name in _ALIASES:  # never one silently over the other
            own = _REGISTRY[_ALIASES.get(ep.name, ep.name)]
            _BROKEN[ep.name] = (
                f"problem {ep.name!r} is both {_where(own.build)} (registered) and the "
                f"installed plugin {ep.value!r} (entry point of visjax.problems); rename the "
                "plugin's entry point"
            )
        else:
            _PENDING.setdefault(ep.name, ep)


def _resolve(name: str) -> None:
    """Load the entry point of `name`, if it is one not loaded yet (a failure recorded in
    `_BROKEN`, never raised here)."""
    ep = _PENDING.pop(name, None)
    if ep is None:
        return
    try:
        register_problem(ep.name, ep.load())
    except Exception as e:
        _BROKEN[name] = (
            f"problem {name!r}: the installed plugin {ep.value!r} (entry point of "
            f"visjax.problems) failed to load: {type(e).__name__}: {_first_line(e)}"
        )


def _first_line(error: Exception) -> str:
    lines = [ln.strip() for ln in str(error).splitlines() if ln.strip()]
    return lines[0] if lines else ""


def registered(name: str) -> Registered:
    """The registry entry of `name` (or of an alias). **Raises:** `ValueError` listing the
    registered names, or saying why an installed plugin of that name failed to load (or
    clashes with a registered problem)."""
    _load()
    if name in _BROKEN:
        raise ValueError(_BROKEN[name])
    if name in _ALIASES:
        warnings.warn(
            f"the problem name {name!r} is deprecated: it is now {_ALIASES[name]!r}",
            FutureWarning,
            stacklevel=1,  # one place: said once per process and name (the default filter)
        )
        name = _ALIASES[name]
    _resolve(name)
    if name in _BROKEN:
        raise ValueError(_BROKEN[name])
    if name not in _REGISTRY:
        hint = did_you_mean(name, problem_names())
        raise ValueError(f"unknown problem {name!r}{hint}; choose from {problem_names()}")
    return _REGISTRY[name]


def problem_names() -> list[str]:
    """The registered problems' names (with the installed plugins', loaded or not)."""
    _load()
    return sorted({*_REGISTRY, *_PENDING, *_BROKEN})


_ADDED: dict[str, dict[str, Method]] = {}  # problem name -> method name -> Method


def add_method(
    problem: str,
    name: str,
    solve: Callable[..., Any],
    parameters: Mapping[str, Parameter] | None = None,
    *,
    like: str | None = None,
    metrics: Callable[..., Any] | None = None,
    replace: bool = False,
) -> Method:
    """Add a method of your own to the registered problem `problem` (a name or an alias):
    every later `studies.problem(problem)` and command (`visjax run|compare|sweep|tune
    PROBLEM`, from a module given to `--import`) has it beside the problem's own methods,
    on the same draws, scored by the same metrics. No subclass, no re-registration.

    **Arguments:**

    - `name`: the method's name (letters, digits, `_`, `-`), not one of the problem's own.
    - `solve`: `(problem, params, inputs) -> solution`, pure JAX: `problem` is the built
        problem (its fields: sample times, camera, truth, as its documentation states),
        `params` every parameter (defaults filled in: the problem's and this method's),
        `inputs` one noisy draw (`problem.inputs(key)`). The solution carries a `result`
        (a visjax `RESULTS` item) and must not raise for a value (`throw=False` inside).
    - `parameters`: name -> `Parameter`, this method's tunable parameters (not named like
        the problem's own); swept and tuned like the problem's.
    - `like`: one of the problem's methods whose solutions have the same form (for the
        velocity problem, `"ekf"`: `ts`, `outputs.v_hat`): the problem scores, draws and
        times it as that method. Or `metrics`: `(problem, solution) -> {name: array}`
        with the problem's metric names. One of the two is needed.
    - `replace`: replace a method of that name added before (else an error).

    **Returns:** the `Method`. **Raises:** `ValueError` for an unknown problem, a taken
    name, a bad argument; a clash with the built problem's own methods or parameters is
    refused when the problem is built (it may depend on its options)."""
    entry = registered(problem)
    _check_word("method", name)
    if not callable(solve):
        raise TypeError(f"`solve` of method {name!r} must be callable; got {solve!r}.")
    if (like is None) == (metrics is None):
        raise ValueError(
            f"method {name!r}: give exactly one of `like` (the problem's method whose "
            "solutions it resembles, scored the same) and `metrics` (your own scoring)."
        )
    if metrics is not None and not callable(metrics):
        raise TypeError(f"`metrics` of method {name!r} must be callable; got {metrics!r}.")
    specs = dict(parameters or {})
    bad = [k for k, v in specs.items() if not isinstance(v, Parameter)]
    if bad:
        raise TypeError(f"method {name!r}: parameters {bad} must be visjax.studies.Parameter.")
    taken = _ADDED.setdefault(entry.name, {})
    if name in taken and not replace:
        raise ValueError(
            f"problem {entry.name!r} has a method {name!r} added by {taken[name].where} "
            "already (replace=True)."
        )
    method = Method(name, solve, tuple(specs.items()), like, metrics, _where(solve))
    taken[name] = method
    return method


def remove_method(problem: str, name: str) -> None:
    """Remove a method added to `problem` (`add_method`); `ValueError` if there is none."""
    entry = registered(problem)
    if name not in _ADDED.get(entry.name, {}):
        raise ValueError(f"problem {entry.name!r} has no added method {name!r}.")
    del _ADDED[entry.name][name]


def problem(name: str, **options) -> AbstractProblem:
    """The registered problem `name` built with `options` (those that are `None` left
    out)."""
    return registered(name).make(**options)
