"""A data file through its problem, the one route from a file to an estimate (what `visjax
run PROBLEM --data` and its alias `visjax PROBLEM --data` run); and the summaries the
removed per-paper file route wrote, still read (with a warning)."""

import json

import jax
import numpy as np
import pytest

from tests.helpers import euclidean_scene_file
from visjax import io, papers, studies


def test_static_points_file_run_equals_its_saved_trajectory(tmp_path):
    """Two independent paths to the final estimate: the saved trajectory's last sample
    and the final state's output (the metric)."""
    path = euclidean_scene_file(tmp_path / "scene.npz", 2.0, 20.0)
    problem = papers.static_points_problem(data=path, noise_px=0.0)
    ev = studies.evaluate(problem, keys=jax.random.key(0)[None])
    sol = studies.solution(problem, None, 0)
    saved = np.asarray(sol.outputs.omega_s[-1])
    truth = np.asarray(problem.truth)
    np.testing.assert_allclose(
        np.linalg.norm(saved - truth, axis=-1), ev.metrics["error"][0], rtol=1e-10
    )
    assert np.max(ev.metrics["error"][0]) < 0.5  # 2 s in: converging, not diverged
    # the tidy table of `visjax run`: one column per number, named by the problem, the
    # truth beside each estimate; the evaluation's table names the metric's components
    table = studies.solution_table(sol, problem, "estimator")
    n = truth.shape[0]
    for i in range(n):
        for j, c in enumerate("XYZ"):
            np.testing.assert_allclose(table[f"{c}_{i}"], sol.outputs.omega_s[:, i, j])
            np.testing.assert_array_equal(table[f"{c}_{i}_true"], truth[i, j])
    assert {"A_11", "A_33", "R_c_12", "x_c_0"} <= set(table) and not any("[" in k for k in table)
    assert all(np.ndim(v) == 1 and len(v) == len(table["t"]) for v in table.values())
    frame = ev.to_pandas()
    assert {f"error_{i}" for i in range(n)} | {"error_worst"} <= set(frame)
    assert problem.settings()["integration_step_s"] == pytest.approx(1e-3)
    with pytest.raises(ValueError, match="`exciting` chooses the project's scene"):
        papers.static_points_problem(data=path, exciting=False)


def _value(spec: str):
    """One value of a schema's type (`float`, `list[list[float]]`, `int|null`, ...)."""
    first = spec.split("|")[0]
    if first.startswith("list["):
        return [_value(first[5:-1])]
    return {"str": "x", "int": 1, "float": 1.0, "dict": {}, "bool": False, "null": None}[first]


def _legacy_summary(kind: str) -> dict:
    """A summary of `kind` as visjax 0.3 wrote it: each required key of its schema."""
    schema = {**io.COMMON, **io.SUMMARIES[kind]}
    summary = {k: _value(spec) for k, (spec, _) in schema.items() if not k.endswith("?")}
    return {**summary, "kind": kind}


@pytest.mark.parametrize("kind", sorted(io.READ_ONLY_KINDS))
def test_a_summary_of_the_old_file_route_is_read_with_a_warning(tmp_path, kind):
    path = tmp_path / "summary.json"
    path.write_text(json.dumps(_legacy_summary(kind)))
    problem = io.READ_ONLY_KINDS[kind]
    with pytest.warns(FutureWarning, match=f"visjax {problem} --data"):
        summary = io.read_summary(path)
    assert summary["kind"] == kind
