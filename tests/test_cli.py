import json

import pytest

from visjax.cli import main


def test_geometry_command_writes_summary_and_figure(tmp_path, capsys):
    assert main(["geometry", "--scenes", "5", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "visjax median" in printed and "OpenCV median" in printed
    summary = json.loads((tmp_path / "summary.json").read_text())
    err = summary["errors"]
    # noise-free: visjax recovers ground truth to float64 precision, OpenCV to its float32
    # point conversion
    assert err["visjax"]["R_bar_deg"]["max"] < 1e-9
    assert err["visjax"]["alpha_rel"]["max"] < 1e-12
    assert err["opencv"]["alpha_rel"]["max"] < 1e-4
    assert (tmp_path / "geometry.png").stat().st_size > 10_000


def test_geometry_rejects_too_few_points(capsys):
    assert main(["geometry", "--points", "3"]) == 2
    assert "at least 4" in capsys.readouterr().err


def test_velocity_command(tmp_path, capsys):
    assert main(["velocity", "--duration", "1", "--quiet", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "RMS" in printed and "vz" in printed
    summary = json.loads((tmp_path / "summary.json").read_text())
    for key in ("rms_5_10s", "max_5_10s"):
        assert len(summary[key]) == 6
    assert summary["window_s"] == [0.5, 1.0]  # the paper's 5-10 s, shrunk into 1 s
    assert max(summary["rms_5_10s"]) < 0.1  # noise-free: already in the chattering band
    assert abs(summary["z1_star_recovered"] - 1.99) < 1e-8
    assert (tmp_path / "velocity.png").stat().st_size > 20_000


def test_velocity_rejects_bad_gains(capsys):
    with pytest.raises(SystemExit):
        main(["velocity", "--K", "1 2 3"])
    assert "six positive numbers" in capsys.readouterr().err


def test_structure_command(tmp_path, capsys):
    assert (
        main(
            [
                "structure",
                "--set",
                "I.1",
                "--set",
                "II.2",
                "--duration",
                "10",
                "--quiet",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "Table 5-3" in printed and "Table 5-4" in printed
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary) == {"I.1", "II.2"}
    assert len(summary["II.2"]["rms"]) == 3
    assert max(summary["I.1"]["rms"]) < 0.05  # metres, static point, 0.1 px
    assert (tmp_path / "structure_I.1.png").stat().st_size > 20_000
    with pytest.raises(SystemExit):
        main(["structure", "--set", "III.9"])


def test_euclidean_command(tmp_path, capsys):
    assert main(["euclidean", "--duration", "3", "--quiet", "--out", str(tmp_path)]) == 0
    assert "final position error" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary["final_position_error_m"]) == 4
    assert max(summary["final_position_error_m"]) < 0.2  # from 10-16 cm, 3 s in
    assert (tmp_path / "euclidean.png").stat().st_size > 20_000
