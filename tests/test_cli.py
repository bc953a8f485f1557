import json

from visjax.cli import main


def test_geometry_command_writes_summary_and_figure(tmp_path, capsys):
    assert main(["geometry", "--scenes", "5", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "visjax median" in printed and "OpenCV median" in printed
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["scenes"] == 5
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
