"""The papers' reproductions (what `visjax.report` prints and writes): the printed tables,
the rows of `visjax reproduce`, the seed checks, and the files handed to `write`."""

import numpy as np
import pytest

from visjax import studies
from visjax.papers import chitrakaran, jang, nath
from visjax.papers._reproduction import check_seeds, floats, median


def test_the_thesis_tables_print_values_infeasible_and_the_thesis():
    per_set = {
        "I.1": {"rms": [0.00123, 0.002, 0.003], "thesis_rms": list(jang.SETS["I.1"].thesis_rms)},
        "II.1": {"rms": None, "thesis_rms": list(jang.SETS["II.1"].thesis_rms)},
    }
    lines = jang.table_lines(per_set, ["I.1", "II.1"], "twin")
    assert lines[1] == "Table 5-3 (static point): twin (thesis)"
    x_static = lines[3]
    assert x_static.split() == ["x", "0.0012", f"({jang.SETS['I.1'].thesis_rms[0]:.4f})"]
    assert "infeasible" in lines[-1] and lines[-1].startswith("z")
    assert jang.table_lines(per_set, ["I.1"], "twin")[-1].startswith("z")
    assert not any("5-4" in line for line in jang.table_lines(per_set, ["I.1"], "twin"))


def test_set_names_default_to_all_and_refuse_unknown_ones():
    assert jang.set_names() == list(jang.SETS)
    assert jang.set_names(["II.3"]) == ["II.3"]
    with pytest.raises(ValueError, match="unknown set 'III.1'"):
        jang.set_names(["III.1"])


def test_reproduce_rows_hold_numbers_and_kinds():
    velocity = {"window_s": [5.0, 10.0], "rms_window": [0.01, 0.04, 0.02], "z1_star_recovered": 2}
    worst = {"visjax": 1e-13, "opencv": 1e-4}
    geometry = {"errors": {w: {"R_bar_deg": {"max": m}} for w, m in worst.items()}}
    rows = chitrakaran.velocity_rows(velocity) + chitrakaran.geometry_rows(geometry)
    assert studies.check_rows("chitrakaran", rows) == rows
    assert [r["reference_kind"] for r in rows] == ["bound", "truth", "OpenCV"]
    assert rows[0]["value"] == 0.04 and (rows[2]["value"], rows[2]["reference"]) == (1e-13, 1e-4)
    # the truth of z1* is feature 1's depth in the reference pose, as the scenario has it
    sc = chitrakaran.section6_scenario(0.3, 1000.0)
    assert rows[1]["reference"] == pytest.approx(float(sc.z1_star), abs=1e-12)

    structure = {"sets": {n: {"rms": [0.01, 0.02, 0.03], "thesis_rms": list(s.thesis_rms)}
                          for n, s in jang.SETS.items()}}  # fmt: skip
    testbed = {"sets": {"I.1": {"rms": None, "thesis_rms": [0.1, 0.3, 0.2]}}}
    rows = jang.moving_point_rows(structure) + jang.testbed_rows(testbed)
    assert studies.check_rows("jang", rows) == rows
    assert len(rows) == len(jang.SETS) + 1  # one row per set, no average over sets
    for row, (name, s) in zip(rows, jang.SETS.items()):
        ratios = np.abs(np.log(np.array([0.01, 0.02, 0.03]) / np.array(s.thesis_rms)))
        i = int(np.argmax(ratios))
        assert f"set {name}: RMS {'xyz'[i]}" in row["name"]
        assert (row["value"], row["reference"]) == ([0.01, 0.02, 0.03][i], s.thesis_rms[i])
    assert rows[-1]["name"].endswith("(infeasible)") and rows[-1]["value"] is None
    assert rows[-1]["reference"] == 0.3
    (row,) = nath.static_points_rows({"final_position_error_m": [2e-4, 5e-4]})
    assert (row["value"], row["unit"], row["reference"]) == (0.5, "mm", nath.POSITION_BOUND_MM)


def test_seed_checks_medians_and_floats():
    check_seeds(3, 0.1)
    for seeds, noise, match in ((0, 0.1, "positive int"), (True, 0.1, "positive int"),
                                (2, 0.0, "need pixel noise")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            check_seeds(seeds, noise)
    assert median([[1.0, 4.0], [3.0, 2.0], [2.0, 9.0]]) == [2.0, 4.0]
    assert floats([1, 2]) == [1.0, 2.0] and floats([1.0, np.nan]) is None


def test_the_geometry_reproduction_hands_its_files_to_write():
    got = []
    rep = chitrakaran.geometry_reproduction(4, 4, 0.0, 0, write=got.append)
    (outputs,) = got
    table = outputs.tables["scenes"]
    assert len(table) == 8 and set(table["method"]) == {"visjax", "opencv"}
    assert set(outputs.figures) == {"geometry"} and callable(outputs.figures["geometry"])
    worst = rep.body["errors"]["visjax"]["R_bar_deg"]["max"]
    assert (
        worst == pytest.approx(table[table.method == "visjax"]["R_bar_deg"].max()) and worst < 1e-8
    )
    assert rep.lines[0].startswith("Euclidean reconstruction from a homography")
    assert chitrakaran.geometry_reproduction(4, 4, 0.0, 0).body["errors"] == rep.body["errors"]
