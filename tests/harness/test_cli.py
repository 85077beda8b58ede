"""The vibrofmu command. End to end: simulate writes CSV, JSON and PNG; demo prints the table.

User mistakes on the command line: each ends with one line `error: ...` on stderr, exit code 2, no traceback,
before anything long runs. The commands run as a user runs them, in a subprocess, from an empty folder (so
that no ./build is found and nothing is built). Also: `import vibrofmu.cli` imports no heavy module, and every
option has help text that states its default."""
import argparse
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from vibrofmu.cli import commands, main, make_parser
from vibrofmu.commands.closed_loop import study_cell as _study_cell
from vibrofmu.commands.common import HelpFormatter


def stand_in_fmu(path: Path) -> Path:
    """A finished archive of these sources (vibrofmu.fmus.archive.current: normalized, then published with the
    sources' stamp) standing in for an FMU: no build is started for it."""
    from vibrofmu.fmus.archive import normalize_entries, publish, staging

    with staging(path.parent) as stage:
        with zipfile.ZipFile(stage / path.name, "w") as z:
            z.writestr("modelDescription.xml", "<fmiModelDescription/>")
        return publish(normalize_entries(stage / path.name), path)


def stand_in_fmus(folder: Path) -> Path:
    """`folder`, made, with a stand-in (stand_in_fmu) for each of the three FMUs."""
    from vibrofmu.paths import CLOSED_LOOP_NAME, CONTROLLER_NAME, PLANT_NAME

    folder.mkdir()
    for name in (PLANT_NAME, CONTROLLER_NAME, CLOSED_LOOP_NAME):
        stand_in_fmu(folder / name)
    return folder


def stand_in_checkout(tmp_path: Path) -> tuple[Path, Path]:
    """(tmp_path/root: a copy of this checkout's docs and README.md, tmp_path/fmus: stand_in_fmus)."""
    import shutil

    checkout = Path(__file__).resolve().parents[2]
    root = tmp_path / "root"
    shutil.copytree(checkout / "docs", root / "docs")
    shutil.copy(checkout / "README.md", root / "README.md")
    return root, stand_in_fmus(tmp_path / "fmus")


def test_simulate_with_compare_writes_all_results(tmp_path, plant_fmu, capsys):
    from vibrofmu.analyses import simulate

    simulate.NOTED.clear()  # the note is printed once per process: forget earlier tests' runs
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
    # the plant's error estimate (RK4's phase error and the polynomial's truncation) bounds the measured error
    assert summary["error"]["max_abs_error_x"] <= summary["error_estimate"] < 1.0
    assert (out / "x.png").stat().st_size > 10_000


def test_simulate_fidelity_auto_lets_the_fmu_choose(tmp_path, plant_fmu, capsys):
    """--fidelity auto --tolerance 1e-3 gives the FMU fidelity = -1 and the tolerance: the FMU chooses (its log line
    of the choice is the one printed) and summary.json reads its outputs: fidelity_chosen as --fidelity accepts it
    (over tau in [0, 20] the exact model at its loosest rtol: the cheap rungs' set-up costs more than its run) and
    error_estimate, with --compare the measured error beside it."""
    out = tmp_path / "auto"
    code = main(["simulate", "--fmu", str(plant_fmu), "--fidelity", "auto", "--tolerance", "1e-3", "--stop-time", "20",
                 "--compare", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["fidelity"] == -1 and summary["tolerance"] == 1e-3
    assert summary["auto_choice"].startswith("fidelity auto chose fidelity 0 at rtol 0.0001 ")
    assert summary["auto_choice"] in printed and f"[ok] {summary['auto_choice']}" in summary["fmu_log"]
    assert summary["fidelity_chosen"] == "exact"
    assert summary["error"]["max_abs_error_x"] <= summary["error_estimate"] <= 1e-3
    assert summary["estimate_and_measured"] == {"error_estimate": summary["error_estimate"],
                                                "max_abs_error_x": summary["error"]["max_abs_error_x"]}


@pytest.mark.slow  # the FMU builds the averaged and analytic rungs before it refuses (~1 s of CPU)
def test_simulate_fidelity_auto_a_tolerance_nothing_meets_is_a_user_error(tmp_path, plant_fmu, capsys):
    """The FMU's refusal naming `tolerance` becomes one line naming --tolerance, exit 2."""
    code = main(["simulate", "--fmu", str(plant_fmu), "--fidelity", "auto", "--tolerance", "1e-16", "--stop-time",
                 "1", "--out", str(tmp_path / "refused")])
    err = capsys.readouterr().err
    assert code == 2
    assert "error: --tolerance 1e-16: no rung's error estimate meets it (" in err and "Traceback" not in err


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

    simulate.NOTED.clear()
    for run in ("a", "b"):
        assert main(["simulate", "--fmu", str(plant_fmu), "--stop-time", "1", "--out", str(tmp_path / run)]) == 0
    assert capsys.readouterr().err.count("note: beta^2") == 1


def run_cli(args, cwd):
    return subprocess.run([sys.executable, "-m", "vibrofmu.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)  # only ends a hung run: a loaded 2-core machine stretches seconds to minutes


@pytest.fixture(scope="module")
def not_plant(tmp_path_factory):
    """A zip with a modelDescription.xml of another model: an FMU, but not the plant's."""
    path = tmp_path_factory.mktemp("other") / "Other.fmu"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("modelDescription.xml", '<fmiModelDescription fmiVersion="2.0" modelName="Other"/>')
    return path


# (command line, a fragment the one line must contain); {readme} and {other} are filled in below.
# The mistakes the issue names run as a user runs them, in a subprocess (about 1 s each: Python starts and
# imports the command's modules); the others run in this process through main(), which shows the same line
# and code (a traceback there would be an exception failing the test).
ISSUE_MISTAKES = [
    (["simulate", "--fmu", "/nonexist.fmu", "--out", "o"], "no FMU at /nonexist.fmu"),
    (["doctor", "/nonexist.fmu"], "no FMU at /nonexist.fmu"),
    (["simulate", "--fmu", "{readme}", "--out", "o"], "is not an FMU"),
    (["simulate", "--out", "/etc/hostname/sub"], "cannot create the output folder /etc/hostname/sub"),
    (["stability", "--sweep-points", "0", "--out", "o"], "--sweep-points: must be an integer >= 1, got 0"),
    (["bench", "--repeats", "0", "--out", "o"], "--repeats: must be an integer >= 1, got 0"),
    (["closed-loop", "--H", "-1", "--out", "o"], "--H: must be a finite number > 0, got -1"),
    (["closed-loop", "--stop-time", "0", "--out", "o"], "--stop-time: must be a finite number > 0, got 0"),
    (["simulate", "--set", "R", "--out", "o"], "--set R: expected NAME=VALUE"),
]
MORE_MISTAKES = [
    (["doctor", "."], "is not a file"),
    (["closed-loop", "--H", "1e-9", "--out", "o"], "with --H 1e-09 the run has 200,000,000,001 output points"),
    (["report", "--check", "--quick", "--root", "{dir}"], "--quick: --check compares with the documents"),
    (["simulate", "--fmu", "{other}", "--out", "o"], "needs HertzEAOscillator"),
    (["demo", "--out", "/etc/hostname/sub"], "cannot create the output folder"),
    (["build", "--out-dir", "/etc/hostname"], "a file of that name exists"),
    (["stability", "--omega-range", "1.1", "0.9", "11", "--out", "o"], "--omega-range"),
    (["stability", "--omega-range", "0.9", "1.1", "2.5", "--out", "o"], "integer N >= 3"),
    (["closed-loop", "--fmu-dir", "{readme}", "--out", "o"], "is not a folder"),
    (["closed-loop", "--mode", "cosim", "--scene", "/nonexist.toml", "--out", "o"], "no scene file at /nonexist.toml"),
    (["simulate", "--set", "R=abc", "--out", "o"], "parameter R = 'abc': not a number"),
    (["simulate", "--set", "Q=1", "--out", "o"], "unknown parameter"),
    (["simulate", "--set", "R=-1", "--out", "o"], "parameter R = -1.0"),
    (["simulate", "--rtol", "0", "--out", "o"], "parameter rtol = 0.0"),
    (["simulate", "--stop-time", "nan", "--out", "o"], "parameter stop-time = nan"),
    (["simulate", "--stop-time", "inf", "--out", "o"], "parameter stop-time = inf"),
    (["simulate", "--stop-time", "0", "--out", "o"], "parameter stop-time = 0.0"),
    (["simulate", "--max-step", "-0.1", "--out", "o"], "--max-step: must be a finite number >= 0"),
    (["simulate", "--output-interval", "5", "--stop-time", "1", "--out", "o"], "longer than --stop-time"),
    (["simulate", "--solver", "rk4", "--max-step", "1e-7", "--output-interval", "1", "--stop-time", "2", "--out", "o"],
     "parameter output-interval = 1.0: needs more than 1000000 steps of --max-step 1e-07 per output"),
    (["simulate", "--max-step", "1e-7", "--output-interval", "1", "--stop-time", "2", "--out", "o"],
     "shorten --output-interval or raise --max-step"),
    (["simulate", "--fidelity", "bogus", "--out", "o"], "invalid choice: 'bogus'"),
    (["simulate"], "required: --out"),
    (["stability", "--set", "omega=0", "--out", "o"], "needs a forcing frequency omega > 0"),
    (["stability", "--set", "R=0", "--out", "o"], "parameter R = 0.0"),
    (["oafm", "--set", "R=0", "--out", "o"], "parameter R = 0.0"),
    (["closed-loop", "--H", "300", "--out", "o"], "--H 300 is longer than the stop time 200"),
    (["oafm", "--order", "0", "--out", "o"], "--order: must be an integer >= 1"),
    (["oafm", "--order", "x", "--out", "o"], "'x' is not an integer"),
    (["oafm", "--nodes", "0", "--out", "o"], "--nodes: must be an integer >= 1"),
    (["oafm", "--panel", "-1", "--out", "o"], "--panel: must be a finite number > 0"),
    (["simulate", "--fidelity", "analytic", "--stop-time", "3000", "--out", "o"],
     "--stop-time 3000: --fidelity analytic fits its solution over the whole experiment, at most tau = 2000"),
    (["simulate", "--fidelity", "analytic", "--stop-time", "3000", "--out", "o"], "add --set oafm_tau_end=2000"),
    (["simulate", "--fidelity", "analytic", "--set", "oafm_order=1.5", "--out", "o"], "parameter oafm_order = 1.5"),
    (["simulate", "--fidelity", "analytic", "--set", "oafm_order=9", "--out", "o"], "parameter oafm_order = 9"),
    (["simulate", "--fidelity", "analytic", "--set", "oafm_tau_end=-1", "--out", "o"], "parameter oafm_tau_end = -1"),
    (["stability", "--set", "oafm_tau_end=10", "--out", "o"], "`vibrofmu simulate --fidelity analytic --set` takes"),
    (["doctor", "--env-file", "e", "--python", "/nonexist"], "--python /nonexist: no such file"),
    (["doctor", "--env-file", "e", "--python", "{dir}"], "is a folder"),
    (["doctor", "--env-file", "e", "--python", "{readme}"], "not executable"),
    (["doctor", "--python", "/nonexist"], "--python /nonexist: only with --env-file"),
    (["report", "--from", "{dir}", "--only", "speed"], "no summary for the block asked for (speed needs a bench.json"),
    (["nosuch"], "invalid choice: 'nosuch'"),
    ([], "required: COMMAND"),
]
# Options the run would ignore (given the others): refused by name before anything runs, instead of a run that
# silently leaves them out (commands.common.check_given and each command's `unused` rule).
IGNORED = [
    (["closed-loop", "--scene", "/nonexist.toml", "--out", "o"], "--scene /nonexist.toml: only --mode cosim reads it"),
    (["closed-loop", "--no-study", "--out", "o"], "--no-study: only --mode cosim reads it"),
    (["closed-loop", "--mode", "cosim", "--reference", "oafm", "--out", "o"], "--reference oafm: only --mode monolithic"),
    (["simulate", "--solver", "rk4", "--rtol", "1e-6", "--out", "o"], "--rtol 1e-06: --solver rk4 (fixed-step RK4) has "
                                                                      "no tolerance"),
    (["simulate", "--fidelity", "exact", "--set", "R=2", "--set", "oafm_order=3", "--out", "o"],
     "--set oafm_order=3: --fidelity exact does not read it"),
    (["simulate", "--fidelity", "analytic", "--solver", "rk4", "--out", "o"], "--solver rk4: --fidelity analytic"),
    (["simulate", "--fidelity", "averaged", "--solver", "adaptive", "--out", "o"], "--solver adaptive: --fidelity "
                                                                                   "averaged"),
    (["simulate", "--fidelity", "analytic", "--rtol", "1e-6", "--out", "o"], "--rtol 1e-06: --fidelity analytic"),
    (["simulate", "--fidelity", "analytic", "--max-step", "0.5", "--out", "o"], "--max-step 0.5: --fidelity analytic"),
    (["simulate", "--set", "R=2", "--set", "R=3", "--out", "o"], "--set R given twice (R=2, then R=3)"),
    (["stability", "--set", "mu=0.1", "--set", " mu=0.2", "--out", "o"], "--set mu given twice"),
    (["simulate", "--rtol", "1e-6", "--rtol", "1e-7", "--out", "o"], "--rtol given twice (1e-06, then 1e-07)"),
    (["simulate", "--fidelity", "exact", "--fidelity", "analytic", "--out", "o"], "--fidelity given twice"),
    (["oafm", "--no-fmu", "--fmu", "{other}", "--out", "o"], "--no-fmu skips the FMU check"),
    (["oafm", "--basis", "paper", "--order", "4", "--out", "o"], "--order 4: --basis paper has no order"),
    (["oafm", "--basis", "paper", "--fmu", "{other}", "--out", "o"], "with --basis paper there is no FMU check"),
    (["stability", "--no-fmu", "--sweep-points", "5", "--out", "o"], "--sweep-points 5: --no-fmu skips the FMU sweeps"),
    (["bench", "--ladder-only", "--repeats", "2", "--out", "o"], "--repeats 2: --ladder-only runs no work-precision"),
    (["bench", "--peers", "--repeats", "2", "--out", "o"], "--repeats 2: --peers runs each setting once per round"),
    (["bench", "--peers", "--ladder-only", "--out", "o"], "--ladder-only: --peers runs only the comparison"),
    (["continuation", "--bench", "--param", "mu", "--out", "o"], "--param mu: --bench continues its own branch"),
    (["continuation", "--bench", "--points", "5", "--out", "o"], "--points 5: --bench continues its own branch"),
    (["continuation", "--param", "omega", "--from", "1", "--to", "2", "--delta", "0.1", "--out", "o"],
     "--delta 0.1: only --confirm runs the FMU"),
    (["continuation", "--param", "omega", "--from", "1", "--to", "2", "--no-doubling", "--max-period", "4", "--out",
      "o"], "--max-period 4: --no-doubling follows no doubled branch"),
    (["bench", "--curve", "--repeats", "2", "--out", "o"], "--repeats 2: --curve runs only the fold-curve benchmark"),
    (["diagram", "--param", "omega", "--from", "1", "--to", "2", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1",
      "--out", "o"], "--workers 2: --scheduler tcp://127.0.0.1:1 runs on that scheduler's workers"),
    (["study", "basins", "--scheduler", "tcp://127.0.0.1:1", "--workers", "2", "--out", "o"], "--workers 2: --scheduler"),
    (["study", "basins", "--engine", "core", "--fmu", "{other}", "--out", "o"], "--engine core runs the compiled kernel"),
    (["report", "--check", "--only", "accuracy", "--root", "{dir}"], "--only accuracy: --check compares every"),
    (["report", "--check", "--out", "{dir}", "--root", "{dir}"], "--check writes nothing"),
]


def _filled(argv, fragment, tmp_path, other):
    readme = tmp_path / "README.md"
    readme.write_text("# not an FMU\n")
    fill = {"readme": readme, "other": other, "dir": tmp_path}
    return [arg.format(**fill) for arg in argv], fragment.format(**fill)


def _assert_one_line(code, stderr, fragment, folder):
    lines = stderr.splitlines()
    assert code == 2, stderr
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    assert fragment in lines[0] and "Traceback" not in stderr
    assert not (folder / "build").exists() and not (folder / "o").exists()  # nothing built or written


@pytest.mark.long  # one vibrofmu subprocess per case
@pytest.mark.parametrize("argv, fragment", ISSUE_MISTAKES, ids=[" ".join(a) for a, _ in ISSUE_MISTAKES])
def test_a_mistake_is_one_line_and_exit_2(argv, fragment, tmp_path, not_plant):
    argv, fragment = _filled(argv, fragment, tmp_path, not_plant)
    proc = run_cli(argv, tmp_path)
    _assert_one_line(proc.returncode, proc.stderr, fragment, tmp_path)


@pytest.mark.parametrize("argv, fragment", MORE_MISTAKES, ids=[" ".join(a) or "(none)" for a, _ in MORE_MISTAKES])
def test_more_mistakes_in_process(argv, fragment, tmp_path, not_plant, monkeypatch, capsys):
    argv, fragment = _filled(argv, fragment, tmp_path, not_plant)
    monkeypatch.chdir(tmp_path)
    code = main(argv)
    _assert_one_line(code, capsys.readouterr().err, fragment, tmp_path)


@pytest.mark.parametrize("argv, fragment", IGNORED, ids=[" ".join(a) for a, _ in IGNORED])
def test_an_option_the_run_would_ignore_is_refused(argv, fragment, tmp_path, not_plant, monkeypatch, capsys):
    argv, fragment = _filled(argv, fragment, tmp_path, not_plant)
    monkeypatch.chdir(tmp_path)
    code = main(argv)
    _assert_one_line(code, capsys.readouterr().err, fragment, tmp_path)


def test_the_ignored_option_of_the_issue_runs_as_a_user_runs_it(tmp_path):
    """`closed-loop --scene` in the default (monolithic) mode ran without reading it and exited 0."""
    proc = run_cli(["closed-loop", "--scene", "nonexist.toml", "--out", "o"], tmp_path)
    _assert_one_line(proc.returncode, proc.stderr, "--scene nonexist.toml: only --mode cosim reads it", tmp_path)


def test_an_option_given_once_or_used_is_accepted():
    """The check refuses only what the run ignores: the same options in the mode or with the settings that read
    them pass it (the rule of each command, without running the command)."""
    from vibrofmu.commands.common import check_given

    for argv in (["closed-loop", "--mode", "cosim", "--scene", "s.toml", "--no-study", "--out", "o"],
                 ["closed-loop", "--reference", "oafm", "--out", "o"],
                 ["simulate", "--solver", "adaptive", "--rtol", "1e-6", "--max-step", "0.5", "--out", "o"],
                 ["simulate", "--solver", "rk4", "--max-step", "0.05", "--out", "o"],
                 ["simulate", "--fidelity", "averaged", "--rtol", "1e-6", "--max-step", "2", "--out", "o"],
                 ["simulate", "--fidelity", "analytic", "--set", "oafm_order=3", "--set", "R=2", "--out", "o"],
                 ["continuation", "--bench", "--chart", "0.1", "0.2", "3", "--points", "5", "--out", "o"],
                 ["oafm", "--basis", "paper", "--no-fmu", "--out", "o"],
                 ["study", "basins", "--quick", "--quick", "--set", "sigma=0.1", "--set", "R=2", "--out", "o"]):
        args = make_parser({argv[0]}).parse_args(argv)
        check_given(args)  # no UserError


def test_a_harmless_unused_option_is_a_warning_and_the_command_runs(capsys):
    """Unused(harmless=True): one `warning:` line naming the option, then the command runs (exit code its own)."""
    from vibrofmu.commands.common import Command, Parser, Unused, run

    ran = []
    command = Command("probe", "a probe", lambda p: p.add_argument("--level", type=int, default=1),
                      lambda args: ran.append(args.level) or 0,
                      lambda args: [Unused("level", "the probe reads no level", harmless=True)])
    parser = Parser(prog="vibrofmu probe")
    command.options(parser)
    parser.set_command(command)
    assert run(command.run, parser.parse_args(["--level", "3"])) == 0 and ran == [3]
    assert capsys.readouterr().err == "warning: --level 3: the probe reads no level\n"
    assert run(command.run, parser.parse_args([])) == 0 and capsys.readouterr().err == ""  # not given: no line


def test_version_prints_the_package_version(tmp_path):
    from importlib import metadata

    proc = run_cli(["--version"], tmp_path)
    assert proc.returncode == 0 and proc.stdout == f"vibrofmu {metadata.version('vibrofmu')}\n", proc.stderr


@pytest.mark.parametrize("argv", [["--stop-time", "1e6", "--output-interval", "1e-3"],
                                  ["--fidelity", "analytic", "--stop-time", "3000"]])
def test_the_note_on_the_scene_is_not_printed_before_an_error(argv, tmp_path, monkeypatch, capsys):
    """The paper's scene has beta^2 != 8 alpha gamma: its note belongs to a run that starts, not before the one
    line of a refused command line."""
    from vibrofmu.analyses import simulate

    simulate.NOTED.clear()
    monkeypatch.chdir(tmp_path)
    code = main(["simulate", *argv, "--out", "o"])
    _assert_one_line(code, capsys.readouterr().err, "--stop-time", tmp_path)


def test_closed_loop_lists_only_the_files_it_wrote(tmp_path, monkeypatch, capsys):
    """A run that stops at its first output has nothing to plot: the line names result.csv and summary.json only,
    each of which exists (it named four plots that were never drawn)."""
    from vibrofmu.analyses import closed_loop
    from vibrofmu.commands import closed_loop as command

    monkeypatch.setattr(command, "built_all", lambda folder: folder)
    monkeypatch.setattr(command, "checked_fmu", lambda path, model, **checks: path)
    stopped = {"time": np.array([0.0]), "series": {"x": np.array([0.1])}, "completed": False,
               "stop_reason": "pull-in at tau = 0", "wall_time_s": 0.0, "log": []}
    monkeypatch.setattr(closed_loop, "monolithic", lambda *args: stopped)
    monkeypatch.setattr(closed_loop, "summarise", lambda result, theta: {"completed": False})
    out = tmp_path / "out"
    assert main(["closed-loop", "--fmu-dir", str(tmp_path), "--out", str(out)]) == 1
    wrote = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("wrote "))
    names = wrote.removeprefix(f"wrote {out}/").split(" (")[0].split(", ")
    assert names == ["result.csv", "summary.json"] and sorted(names) == sorted(p.name for p in out.iterdir())


def test_importing_the_cli_imports_no_heavy_module():
    """`vibrofmu --help` must not pay for scipy, matplotlib, FMPy or numpy (each command imports its own)."""
    heavy = ("scipy", "matplotlib", "fmpy", "numpy")
    code = f"import sys, vibrofmu.cli; print(','.join(m for m in {heavy!r} if m in sys.modules))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.strip() == ""


def test_top_level_help_lists_every_command(tmp_path):
    proc = run_cli(["--help"], tmp_path)
    assert proc.returncode == 0
    text = " ".join(proc.stdout.split())  # argparse wraps the descriptions
    for command in commands():  # each command, followed by its one-line description
        assert f"{command.name} {' '.join(command.help.split())}" in text, command.name


def _options():
    parser = make_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, subparser in sub.choices.items():
        for action in subparser._actions:
            if action.option_strings and action.dest != "help":
                yield name, action


@pytest.mark.parametrize("command, action", list(_options()),
                         ids=[f"{name} {a.option_strings[0]}" for name, a in _options()])
def test_every_option_has_help_with_its_default(command, action):
    text = HelpFormatter("vibrofmu")._get_help_string(action)
    assert text.strip()
    # a flag is off by default and a required option has none; every other option names its default
    assert isinstance(action, argparse._StoreTrueAction) or action.required or "default" in text


def test_the_convergence_table_shows_a_stopped_run():
    """A Jacobi run of the study that stops at pull-in has no error to print (None): the cell says so instead of
    failing on None's format (the crash of `closed-loop --mode cosim`)."""
    stopped = {"H": 0.5, "max_abs_error_x": None, "completed": False, "stop_reason": "plant: pull-in at tau = 3"}
    assert _study_cell(stopped) == "H=0.5: stopped (plant: pull-in at tau = 3)"
    done = {"H": 0.2, "max_abs_error_x": 1.5e-3, "completed": True, "stop_reason": None, "order": 1.02}
    assert _study_cell(done) == "H=0.2: 1.50e-03 (order 1.02)"


def _interrupted(args):
    raise KeyboardInterrupt


def test_ctrl_c_stops_a_command_run_by_another(monkeypatch, tmp_path):
    """Ctrl-C inside a study that `report` runs stops the report (nothing rewritten), instead of being answered by
    the study (exit 130) and the report going on to the next one."""
    from dataclasses import replace

    from vibrofmu.commands import oafm, report, stability

    ran = []
    monkeypatch.setattr(oafm, "COMMAND", replace(oafm.COMMAND, run=_interrupted))
    monkeypatch.setattr(stability, "COMMAND", replace(stability.COMMAND, run=lambda args: ran.append(args) or 0))
    with pytest.raises(KeyboardInterrupt):
        report.run_studies(tmp_path, tmp_path, quick=True)
    assert ran == []


def test_ctrl_c_is_one_line_and_exit_130(monkeypatch, capsys):
    from dataclasses import replace

    from vibrofmu.commands import build

    monkeypatch.setattr(build, "COMMAND", replace(build.COMMAND, run=_interrupted))
    assert main(["build"]) == 130
    assert capsys.readouterr().err == "error: interrupted\n"


def test_a_failing_command_leaves_no_empty_output_folder(tmp_path):
    """The folder out_folder made for a command that then fails is removed (with the parents it made); a folder
    that existed before, or that holds a file, stays."""
    from vibrofmu.commands.common import UserError, out_folder, run

    def fails_after(folder, write=False):
        def command(args):
            out = out_folder(str(folder))
            if write:
                (out / "partial.csv").write_text("time\n")
            raise UserError("late mistake")
        return command

    assert run(fails_after(tmp_path / "new" / "deeper"), None) == 2
    assert not (tmp_path / "new").exists()
    (tmp_path / "old").mkdir()
    assert run(fails_after(tmp_path / "old"), None) == 2
    assert (tmp_path / "old").is_dir()
    assert run(fails_after(tmp_path / "kept", write=True), None) == 2
    assert (tmp_path / "kept" / "partial.csv").is_file()


def test_summary_json_is_always_valid_json(tmp_path):
    """NaN and infinities become null: the file parses with a parser that refuses NaN/Infinity tokens."""
    from vibrofmu.output.export import write_json

    write_json(tmp_path / "s.json", {"end_time": float("nan"), "r": [1.0, float("inf"), np.float64(-np.inf)],
                                     "n": np.int64(3), "ok": np.bool_(True), "a": np.array([0.5, np.nan])})

    def refuse(token):
        raise ValueError(f"not JSON: {token}")

    data = json.loads((tmp_path / "s.json").read_text(), parse_constant=refuse)
    assert data == {"end_time": None, "r": [1.0, None, None], "n": 3, "ok": True, "a": [0.5, None]}


def test_rk4_steps_longer_than_the_output_interval_are_not_warned_about_in_the_summary(tmp_path, plant_fmu):
    """--max-step 5 at --output-interval 0.1: the result is bit for bit that of --max-step 0.1, and no warning of
    the run (the harness's or the FMU's log) says the drive is wrong by more than 1000 %."""
    runs = {}
    for step in ("5", "0.1"):
        out = tmp_path / step
        assert main(["simulate", "--fmu", str(plant_fmu), "--solver", "rk4", "--max-step", step, "--stop-time", "20",
                     "--out", str(out)]) == 0
        runs[step] = ((out / "result.csv").read_bytes(), json.loads((out / "summary.json").read_text()))
    assert runs["5"][0] == runs["0.1"][0]
    summary = runs["5"][1]
    assert summary["settings"]["max_step"] == 5 and summary["settings"]["fmu_max_step"] == 0.1
    assert summary["warnings"] == [] and not any("does not resolve" in line for line in summary["fmu_log"])


def test_the_rk4_warning_is_about_the_step_rk4_takes():
    """max_step 5 at output interval 0.1: every doStep is one RK4 step of 0.1, so the result is bit for bit that of
    max_step 0.1 and no warning is due; at output interval 1 the steps are 1 long and the warning names them."""
    from vibromodel.parameters import Scene
    from vibromodel.plant import Settings
    from vibromodel.settings import checked_settings

    from vibrofmu.analyses.simulate import SOLVERS, plant_run

    scene = Scene()
    long_ceiling = Settings(solver=SOLVERS["rk4"], max_step=5.0)
    assert checked_settings(scene, long_ceiling, interval=0.1)[1] == []
    warned = checked_settings(scene, long_ceiling, interval=1.0)[1]
    assert warned and all(w.startswith("RK4 steps of 1 (the output interval; max_step = 5") for w in warned)
    assert checked_settings(scene, long_ceiling)[1]  # without the interval (the FMU): about max_step itself
    _, five, _ = plant_run(scene, long_ceiling, 5.0, 0.1)
    _, tenth, _ = plant_run(scene, Settings(solver=SOLVERS["rk4"], max_step=0.1), 5.0, 0.1)
    assert np.array_equal(five, tenth)


def test_the_machine_block_reports_the_start_of_the_report():
    from vibrofmu.report import machine_block

    text = machine_block((0.0, (1.0, 2.5, 3.25)))
    assert "1970-01-01 00:00 UTC" in text and "load average 1.00, 2.50, 3.25" in text


def test_report_keeps_an_edit_made_while_it_ran(tmp_path, monkeypatch, capsys):
    """`report` rewrites only its blocks, in the documents as they are when it writes: a line a user adds to
    a document while the studies run (minutes) is kept (the report used to write back the text it read at its start).
    The blocks are generated by a stand-in that makes that edit; the FMUs are stand-in files (no FMU runs)."""
    import shutil

    import vibrofmu.report as report

    root = tmp_path / "root"
    (root / "docs").mkdir(parents=True)
    checkout = Path(__file__).resolve().parents[2]
    shutil.copy(checkout / "README.md", root / "README.md")
    for doc in (checkout / "docs").glob("*.md"):
        shutil.copy(doc, root / "docs" / doc.name)
    fmus = stand_in_fmus(tmp_path / "fmus")
    edit = "\nA line the user wrote while the report ran.\n"

    def generate(names, *args):
        with open(root / "docs" / "robustness.md", "a") as doc:  # the document that holds the ranges block
            doc.write(edit)
        return {"ranges": "generated ranges table\n"}

    monkeypatch.setattr(report, "generate", generate)
    assert main(["report", "--only", "ranges", "--root", str(root), "--fmu-dir", str(fmus)]) == 0
    capsys.readouterr()
    robustness = (root / "docs" / "robustness.md").read_text()
    assert robustness.endswith(edit)
    assert "<!-- report:ranges -->\ngenerated ranges table\n<!-- /report:ranges -->" in robustness


def test_report_leaves_the_blocks_of_a_failed_study_alone(monkeypatch, tmp_path, capsys):
    """A study that fails (here the bench) leaves every block that reads its summary as it is -- the speed block
    gathers oafm, stability and bench, and from the first two alone it lost the bench's lines -- and the report
    exits 1. The studies are stand-ins; the FMUs are stand-in files (no FMU runs)."""
    from dataclasses import replace

    import vibrofmu.report as report
    from vibrofmu.commands import bench, oafm, stability

    root, fmus = stand_in_checkout(tmp_path)
    monkeypatch.setattr(oafm, "COMMAND", replace(oafm.COMMAND, run=lambda args: 0))
    monkeypatch.setattr(stability, "COMMAND", replace(stability.COMMAND, run=lambda args: 0))
    monkeypatch.setattr(bench, "COMMAND", replace(bench.COMMAND, run=lambda args: 1))
    asked = []
    monkeypatch.setattr(report, "generate", lambda names, *args: asked.extend(names) or {})
    assert main(["report", "--only", "oafm", "speed", "--root", str(root), "--fmu-dir", str(fmus)]) == 1
    assert asked == ["oafm"]
    assert "the blocks that read its summary (auto_setup, speed) are not updated" in capsys.readouterr().err


# A Ctrl-C while `vibrofmu` is still importing the model (about 0.5 s at start-up) is an interrupt like any other.
# Deterministic: the SIGINT's KeyboardInterrupt is raised by the import of vibromodel.parameters itself (a real
# signal would land there only by timing), in a fresh interpreter so that nothing is imported yet.
START_UP_INTERRUPT = """
import builtins, sys
real_import = builtins.__import__
def interrupted_import(name, *args, **kwargs):
    if name == "vibromodel.parameters":
        raise KeyboardInterrupt
    return real_import(name, *args, **kwargs)
builtins.__import__ = interrupted_import
from vibrofmu.cli import main
sys.exit(main(["simulate", "--stop-time", "1"]))
"""


def test_an_interrupt_while_importing_ends_in_one_line():
    done = subprocess.run([sys.executable, "-c", START_UP_INTERRUPT], capture_output=True, text=True, timeout=120)
    assert (done.returncode, done.stderr) == (130, "error: interrupted\n")


def test_the_closed_loop_size_estimate_bounds_its_columns(tmp_path, monkeypatch, controller_fmu, closed_loop_fmu):
    """closed-loop refuses a run whose output would not fit (--max-output-mb) from a count of values per output
    point: it must bound the columns a real run writes (monolithic and co-simulated)."""
    from vibrofmu.commands.closed_loop import COLUMNS

    monkeypatch.chdir(tmp_path)
    for mode in COLUMNS:
        study = ["--no-study"] if mode == "cosim" else []
        assert main(["closed-loop", "--mode", mode, "--stop-time", "0.2", *study, "--fmu-dir",
                     str(closed_loop_fmu.parent), "--out", mode]) == 0
        header = (tmp_path / mode / "result.csv").read_text().splitlines()[0]
        assert len(header.split(",")) <= COLUMNS[mode], (mode, header)


def test_an_fmu_that_does_not_start_is_one_line(plant_fmu, tmp_path, monkeypatch, capsys):
    """fmi2Instantiate answering NULL (here: a plant FMU whose resources lost their identity file, which its loader
    refuses) ends the command with one `error:` line carrying the FMU's own reason, not FMPy's traceback."""
    damaged = tmp_path / "HertzEAOscillator.fmu"
    with zipfile.ZipFile(plant_fmu) as source, zipfile.ZipFile(damaged, "w", zipfile.ZIP_DEFLATED) as target:
        for item in source.infolist():
            if not item.filename.endswith("vibrofmu_identity.txt"):
                target.writestr(item, source.read(item.filename))
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "--fmu", str(damaged), "--stop-time", "1", "--out", "o"]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("note: ")]  # (the scene's)
    assert len(err) == 1 and err[0].startswith(f"error: {damaged}: fmi2Instantiate failed"), err
    assert "vibrofmu_identity.txt is missing" in err[0], err


def test_the_program_exits_at_once_after_an_interrupt_with_its_atexit_handlers_run():
    """The `vibrofmu` program is cli.console (pyproject.toml): after a Ctrl-C it skips the modules' teardown
    (seconds of a loaded machine) but still runs the atexit handlers (temporary folders, multiprocessing)."""
    import tomllib

    scripts = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["vibrofmu"] == "vibrofmu.cli:console"
    code = ("import atexit; atexit.register(print, 'atexit ran', flush=True)\n"
            + START_UP_INTERRUPT.replace("from vibrofmu.cli import main\n", "from vibrofmu.cli import console\n")
            .replace('sys.exit(main(["simulate", "--stop-time", "1"]))',
                     'sys.argv[1:] = ["simulate", "--stop-time", "1"]\nsys.exit(console())'))
    assert "console()" in code
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert (done.returncode, done.stderr, done.stdout) == (130, "error: interrupted\n", "atexit ran\n")


def test_an_fmu_without_a_variable_the_run_needs_is_one_line(tmp_path):
    """An FMU built by another version of vibrofmu may lack a variable a command reads: FmuInstance names the FMU
    and the variable (FmuVariableMissing, printed in one line by the command line), never a bare KeyError."""
    from vibrofmu.hosts.run import FmuInstance, FmuUnusable

    instance = FmuInstance.__new__(FmuInstance)  # (no FMU needed: the lookup alone)
    instance.path, instance.variables = tmp_path / "old.fmu", {}
    with pytest.raises(FmuUnusable, match=r"old.fmu: the FMU has no variable 'fidelity_chosen' \(an FMU built by "):
        instance.value_references(["fidelity_chosen"])
    with pytest.raises(KeyError):  # still a KeyError for code that expects one
        instance.variable("x")


def test_an_fmi3_plant_fmu_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    """The harness drives FMI 2.0 co-simulation FMUs: an FMI 3.0 plant FMU (build/native/fmi3/) given to simulate
    ended in FMPy's 'Cannot find shared library' traceback; now one line naming the FMU and what it is."""
    fmu = tmp_path / "HertzEAOscillator.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", '<fmiModelDescription fmiVersion="3.0" modelName="HertzEAOscillator">'
                         '<CoSimulation modelIdentifier="HertzEAOscillator"/></fmiModelDescription>')
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "--fmu", str(fmu), "--stop-time", "1", "--out", "o"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"error: {fmu} is an FMI 3.0 FMU; this command runs FMI 2.0 co-simulation FMUs (vibrofmu build "
                   "writes them to build/ and build/native/)"]
