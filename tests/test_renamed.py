"""The old vocabulary, read on: the names of visjax 0.3 still give the renamed objects, each
with a `FutureWarning` naming the new one; an unknown name is an `AttributeError`."""

import importlib

import pytest

from visjax import design, estimators, plots
from visjax.papers import hamel, jang, nath, spica

MODULES = (estimators, design, spica, hamel, jang, nath, plots)
CASES = [(m, old, new) for m in MODULES for old, new in m.RENAMED.items()]


@pytest.mark.parametrize("module, old, new", CASES, ids=[c[1] for c in CASES])
def test_an_old_name_gives_the_new_object_with_a_warning(module, old, new):
    with pytest.warns(FutureWarning, match=f"{module.__name__}.{old} is now .*{new}"):
        got = getattr(module, old)
    assert got is getattr(module, new)
    assert old not in vars(module)  # not a second public name


def test_an_import_of_an_old_name_works_and_an_unknown_name_fails():
    with pytest.warns(FutureWarning, match="MovingPointEstimator"):
        from visjax.estimators import MovingPointObserver  # noqa: F401
    with pytest.raises(AttributeError, match="no attribute 'NoSuchName'"):
        importlib.import_module("visjax.estimators").NoSuchName  # noqa: B018
