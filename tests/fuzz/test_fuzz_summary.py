"""tests/fuzz/run.py's summary (<out>/fuzz.json) and the report block made of it (`vibrofmu report --from OUT
--only fuzz`): the block renders every target's numbers from run.py's own writer, says that its counts depend on the
machine and the campaign's length, and a missing or damaged summary is one line `error: ...` and exit 2. Synthetic
results: nothing is built or fuzzed here."""
import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vibrofmu import report
from vibrofmu.cli import main

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import run  # noqa: E402  (tests/fuzz/run.py)

ROOT = HERE.parents[1]


def synthetic(out: Path, findings=()) -> Path:
    """<out>/fuzz.json as run.main writes it, for two targets with made-up numbers."""
    args = argparse.Namespace(seconds=600.0, runs=None, jobs=1, timeout=30, skip_null=False)
    results = [{"target": "calls_HertzEAOscillator", "runs": 123456, "seconds": 300.4, "cpu_seconds": 40.0,
                "exec_per_sec": 411, "cov": 2263, "ft": 11182, "corpus": 2314, "returncode": 0},
               {"target": "layer", "runs": 2500000, "seconds": 299.6, "cpu_seconds": 25.0, "exec_per_sec": 8345,
                "cov": 283, "ft": 1191, "corpus": 399, "returncode": 0}]
    for r in results:
        if r["target"] in findings:
            r["returncode"] = 1
    out.mkdir(parents=True, exist_ok=True)
    return run.write_summary(out, ["--seconds", "600", "--jobs", "1", "--out", str(out)], args,
                             (1796126400.0, (3.25, 2.0, 1.0), "0123456789ab"), 21.7, 625.0, results)


def test_the_block_renders_run_py_s_summary(tmp_path):
    path = synthetic(tmp_path / "campaign")
    assert path == tmp_path / "campaign" / "fuzz.json"
    body = report.summary_block("fuzz", [tmp_path / "nothing", tmp_path / "campaign"])
    lines = body.splitlines()
    assert lines[0].startswith(f"`python3 tests/fuzz/run.py --seconds 600 --jobs 1 --out {tmp_path / 'campaign'}` "
                               f"(2026-12-01 12:00 UTC, sources at 0123456789ab, {os.cpu_count()} CPUs, ")
    assert "load average 3.2 at its start" in lines[0] and "built in 22 s" in lines[0]
    assert "each target its share of the 600 s budget, 1 at a time" in lines[0]
    # executions, wall s, exec/s, CPU s, executions per CPU second (123,456 / 40), edges / features, corpus, findings
    assert "| calls_HertzEAOscillator | 123,456 | 300 | 411 | 40 | 3,086 | 2,263 / 11,182 | 2,314 | 0 |" in lines
    assert "| layer | 2,500,000 | 300 | 8,345 | 25 | 100,000 | 283 / 1,191 | 399 | 0 |" in lines
    # 10^7 / 3,086.4 and 10^7 / 100,000 executions per CPU second
    assert ("2,623,456 executions in 65 CPU seconds over 2 targets, 0 findings. At each target's executions per CPU "
            "second here, 10⁷ executions take 100 to 3,240 CPU seconds a target (3,340 for the 2 targets short of "
            "them).") in lines
    assert ("depend on the machine (so `vibrofmu report --check` does not compare this block) and on the campaign's "
            "length" in body.lower())


def test_a_finding_is_counted(tmp_path):
    synthetic(tmp_path, findings=("layer",))
    body = report.summary_block("fuzz", [tmp_path])
    assert "| layer | 2,500,000 | 300 | 8,345 | 25 | 100,000 | 283 / 1,191 | 399 | 1 |" in body.splitlines()
    assert ", 1 finding." in body


def test_report_from_a_campaign_writes_the_block(tmp_path, capsys, monkeypatch):
    synthetic(tmp_path / "campaign")
    monkeypatch.chdir(tmp_path)
    assert main(["report", "--from", str(tmp_path / "campaign"), "--only", "fuzz", "--out", "docs_out"]) == 0, \
        capsys.readouterr().err
    written = report.parse_blocks((tmp_path / "docs_out" / "docs" / "robustness.md").read_text())
    assert written["fuzz"].rstrip() == report.summary_block("fuzz", [tmp_path / "campaign"]).rstrip()
    assert "wrote docs_out/docs/robustness.md: fuzz" in capsys.readouterr().out


@pytest.mark.parametrize("damage,words", [
    (lambda path: path.unlink(), "no summary for the block asked for (fuzz needs a fuzz.json"),
    (lambda path: path.write_text('{"fuzz": {"command": "x"'), "not a summary of tests/fuzz/run.py (JSONDecodeError"),
    (lambda path: path.write_text("[1, 2]"), "not a summary of tests/fuzz/run.py (TypeError"),
    (lambda path: path.write_text(json.dumps({"fuzz": {k: v for k, v in json.loads(path.read_text())["fuzz"].items()
                                                       if k != "targets"}})), "(no field 'targets')"),
    (lambda path: path.write_bytes(b"\xff\xfe\x00garbage"), "not a summary of tests/fuzz/run.py (UnicodeDecodeError"),
], ids=["missing", "truncated", "not-an-object", "no-targets", "not-text"])
def test_a_missing_or_damaged_summary_is_one_line(tmp_path, capsys, monkeypatch, damage, words):
    damage(synthetic(tmp_path / "campaign"))
    monkeypatch.chdir(tmp_path)
    assert main(["report", "--from", str(tmp_path / "campaign"), "--only", "fuzz", "--out", "docs_out"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --from ") and words in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "docs_out").exists()  # nothing written


def test_targets_at_the_goal_need_no_estimate(tmp_path):
    path = synthetic(tmp_path)
    data = json.loads(path.read_text())
    for r in data["fuzz"]["targets"]:
        r["executions"] = 10**7
    path.write_text(json.dumps(data))
    body = report.summary_block("fuzz", [tmp_path])
    assert "20,000,000 executions in 65 CPU seconds over 2 targets, 0 findings. Every target reached 10⁷ executions." \
        in body.splitlines()


def test_a_campaign_run_in_several_runs_is_one_block(tmp_path):
    """Targets run side by side as separate runs (each its own summary, `--from A --from B`): each run's table in the
    order given, and per target the most executions one run gave it (the runs are separate campaigns: not summed)."""
    synthetic(tmp_path / "a")
    path = synthetic(tmp_path / "b", findings=("layer",))
    data = json.loads(path.read_text())
    data["fuzz"]["targets"][0]["executions"] = 10**7  # calls_HertzEAOscillator reaches the goal in run b
    path.write_text(json.dumps(data))
    body = report.summary_block("fuzz", [tmp_path / "a", tmp_path / "b"])
    lines = body.splitlines()
    heads = [i for i, line in enumerate(lines) if line.startswith("`python3 tests/fuzz/run.py")]
    assert len(heads) == 2 and str(tmp_path / "a") in lines[heads[0]] and str(tmp_path / "b") in lines[heads[1]]
    assert "| calls_HertzEAOscillator | 10,000,000 | 300 | 411 | 40 | 250,000 | 2,263 / 11,182 | 2,314 | 0 |" in lines
    # layer: 2,500,000 in both runs (short of 10^7); calls_HertzEAOscillator 10^7 in b (123,456 in a); b's finding
    assert ("Together, 2 runs: 2 targets, 1 finding; short of 10⁷ executions in every run: layer (2,500,000).") in lines
    data["fuzz"]["targets"][1]["executions"] = 10**7
    data["fuzz"]["targets"][1]["finding"] = False
    path.write_text(json.dumps(data))
    assert ("Together, 2 runs: 2 targets, 0 findings; every target reached 10⁷ executions in one run."
            in report.summary_block("fuzz", [tmp_path / "a", tmp_path / "b"]).splitlines())
    # one run alone: no "Together" line
    assert "Together" not in report.summary_block("fuzz", [tmp_path / "a"])


FAKE_TARGET = """#!/bin/sh
# a stand-in for a libFuzzer target: runs until SIGUSR1, then prints libFuzzer's final statistics and exits 0, as
# libFuzzer's graceful exit does
trap 'echo "stat::number_of_executed_units: 4242" >&2; echo "stat::average_exec_per_sec: 7" >&2; exit 0' USR1
echo "#4242 DONE cov: 10 ft: 20 corp: 3/1b" >&2
echo started > "$(dirname "$0")/../started-$(basename "$0")"
while :; do sleep 0.05; done
"""


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_stopped_campaign_keeps_what_ran(tmp_path, signum, code):
    """SIGINT / SIGTERM to run.py: the running target is asked to stop gracefully (SIGUSR1) and its executions are
    in the summary, the target not yet started is not run, exit 128 + the signal, and the block says so. Fake
    targets (shell scripts), one at a time: nothing is built or fuzzed."""
    out = tmp_path / "out"
    (out / "bin").mkdir(parents=True)
    for name in ("calls_HertzEAOscillator", "layer"):
        (out / "bin" / name).write_text(FAKE_TARGET)
        (out / "bin" / name).chmod(0o755)
    proc = subprocess.Popen([sys.executable, str(HERE / "run.py"), "--no-build", "--jobs", "1", "--runs", "100",
                             "--out", str(out), "calls_HertzEAOscillator", "layer"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (out / "started-calls_HertzEAOscillator").exists():
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    proc.send_signal(signum)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == code, stderr
    assert f"stopped by {signal.Signals(signum).name}: 1 of 2 targets ran" in stdout
    assert not (out / "started-layer").exists()  # never started
    f = json.loads((out / "fuzz.json").read_text())["fuzz"]
    assert f["stopped"] == signal.Signals(signum).name
    assert [(r["target"], r["executions"], r["finding"], r["stopped"]) for r in f["targets"]] == [
        ("calls_HertzEAOscillator", 4242, False, True)]
    body = report.summary_block("fuzz", [out])
    assert f"stopped early by {signal.Signals(signum).name}" in body.splitlines()[0]
    assert "| calls_HertzEAOscillator | 4,242 (stopped) |" in body
