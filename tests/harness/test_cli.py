"""The vibrofmu command end to end: simulate writes CSV, JSON and PNG; demo prints the table."""
import json

import numpy as np
import pytest

from vibrofmu.cli import main


def test_simulate_with_compare_writes_all_results(tmp_path, plant_fmu, capsys):
    from vibrofmu.analyses import simulate

    simulate._NOTED.clear()  # the note is printed once per process: forget earlier tests' runs
    out = tmp_path / "run"
    code = main(["simulate", "--fmu", str(plant_fmu), "--fidelity", "polynomial", "--solver", "rk4",
                 "--max-step", "0.05", "--set", "Delta=0.001", "--stop-time", "20", "--output-interval", "0.1",
                 "--compare", "--out", str(out)])
    assert code == 0
    err = capsys.readouterr().err
    # the paper's set violates beta^2 = 8 alpha gamma: an explained note, not a warning
    assert "note: beta^2" in err and "no pair of bias and AC voltages" in err and "warning: beta" not in err
    header = (out / "result.csv").read_text().splitlines()[0].split(",")
    assert header == ["time", "x", "v", "a", "F_contact", "F_electrostatic", "in_contact"]
    data = np.loadtxt(out / "result.csv", delimiter=",", skiprows=1)
    # the last time is the FMU's clock t + h = 19.9 + 0.1: within one rounding of 20
    assert data.shape == (201, 7) and data[-1, 0] == pytest.approx(20.0, rel=1e-15)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["notes"] and summary["notes"][0].startswith("beta^2")
    assert summary["parameters"]["Delta"] == 0.001
    assert summary["settings"]["fidelity"] == 1 and summary["settings"]["solver"] == 1
    assert summary["completed"] and summary["wall_time_s"] > 0
    # RK4 at h = 0.05 on the polynomial model: ~1e-8 (test_accuracy measures the order)
    assert 0 < summary["error"]["max_abs_error_x"] < 1e-6
    assert (out / "x.png").stat().st_size > 10_000


def test_simulate_reports_an_early_stop(tmp_path, plant_fmu, capsys):
    code = main(["simulate", "--fmu", str(plant_fmu), "--set", "x_start=0.29", "--set", "R=0.2",
                 "--stop-time", "5", "--out", str(tmp_path / "pull")])
    assert code == 1
    err = capsys.readouterr().err
    assert "stopped at tau = " in err and "pull-in" in err
    summary = json.loads((tmp_path / "pull" / "summary.json").read_text())
    assert not summary["completed"] and "pull-in" in summary["stop_reason"]


def test_the_beta_note_is_printed_once_per_process(tmp_path, plant_fmu, capsys):
    from vibrofmu.analyses import simulate

    simulate._NOTED.clear()
    for run in ("a", "b"):
        assert main(["simulate", "--fmu", str(plant_fmu), "--stop-time", "1", "--out", str(tmp_path / run)]) == 0
    assert capsys.readouterr().err.count("note: beta^2") == 1
