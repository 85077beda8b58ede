"""Issue 26: Ctrl-C stops every command, inside FMU calls too, and no file is ever half-written under its final name.

The long measurements (random SIGINTs during bench, report, simulate, study, oafm) are the slow campaign in
tests/robustness/; here the fast part: the atomic writer, the slave's answer to a KeyboardInterrupt, and one real
SIGINT during a pure-Python FMU run.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from vibrofmu.output import export

HARNESS = Path(__file__).resolve().parents[2] / "harness"


def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "result.json"
    export.write_json(path, {"a": 1})
    with pytest.raises(KeyboardInterrupt):
        with export.atomic(path) as tmp:
            tmp.write_text('{"a": 2, "half')
            raise KeyboardInterrupt
    assert path.read_text() == '{\n  "a": 1\n}\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.json"]


def test_csv_written_in_chunks_reads_back_exactly(tmp_path, monkeypatch):
    import numpy as np

    monkeypatch.setattr(export, "CSV_CHUNK", 7)  # several chunks and a partial last one
    time_ = np.linspace(0.0, 1.0, 30)
    columns = {"x": np.sin(time_) / 3, "flag": (time_ > 0.5).astype(float)}
    export.write_csv(tmp_path / "r.csv", time_, columns)
    data = np.loadtxt(tmp_path / "r.csv", delimiter=",", skiprows=1)
    assert (tmp_path / "r.csv").read_text().splitlines()[0] == "time,x,flag"
    assert np.array_equal(data, np.column_stack([time_, columns["x"], columns["flag"]]))  # %.17g round-trips


def test_a_keyboard_interrupt_inside_a_slave_call_fails_the_call_and_is_flagged(monkeypatch):
    """pythonfmu turns an exception leaving a callback into fmi2Fatal and the host went on; the slave now catches
    the KeyboardInterrupt, halts with a log line and sets the flag on which the status shim re-raises SIGINT."""
    from vibrofmu.fmus.build import FMU_SRC

    monkeypatch.syspath_prepend(str(FMU_SRC))
    from AdaptiveLyapunovController import AdaptiveLyapunovController
    from slave_support import STATUS_INTERRUPTED

    slave = AdaptiveLyapunovController(instance_name="direct")
    logged = []
    monkeypatch.setattr(slave, "log", lambda message, status=None: logged.append(message))

    def interrupted(*_):
        raise KeyboardInterrupt

    monkeypatch.setattr(slave, "_allowed", interrupted)  # the first thing setup_experiment does
    assert slave.setup_experiment(0.0, 10.0) is None  # no exception leaves the callback
    assert slave.fmi_status == STATUS_INTERRUPTED and "interrupted (SIGINT" in logged[-1]
    assert slave.halted is not None
    monkeypatch.setattr(slave, "_step_allowed", interrupted)
    assert slave.do_step(0.0, 0.1) is False
    monkeypatch.setattr(slave, "_get_values", interrupted)
    assert slave.get_real([1, 2, 3]) == [0.0, 0.0, 0.0]


RUN = textwrap.dedent("""
    import sys, time
    from vibrofmu import interrupts
    from vibrofmu.hosts.run import run_fmu
    def progress(done, total):
        if done == 10:  # inside the doStep loop (instantiation took seconds on a loaded machine)
            print("stepping", flush=True)

    with interrupts.install():
        print("started", flush=True)
        try:
            run = run_fmu(sys.argv[1], {"kernel": 1}, 1e5, 0.1, progress=progress)  # pure Python doSteps: minutes
        except KeyboardInterrupt:
            sys.exit(130)
    print("not interrupted:", run.stop_reason)
    sys.exit(1)
""")


@pytest.mark.fmu
def test_ctrl_c_during_pure_python_do_steps_stops_the_host_within_a_second(plant_fmu, tmp_path):
    """A real SIGINT while the slave's Python code runs doSteps: the host stops with KeyboardInterrupt (exit 130)
    instead of recording a failed (fatal) case and going on."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HARNESS), os.environ.get("PYTHONPATH", "")]),
           "TMPDIR": str(tmp_path)}
    process = subprocess.Popen([sys.executable, "-c", RUN, str(plant_fmu)], env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True,  # SIGINT's default (not an inherited SIG_IGN)
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert process.stdout.readline().strip() == "started"
    assert process.stdout.readline().strip() == "stepping"  # past instantiation, whatever the machine's load
    time.sleep(0.2)  # into the later doSteps
    process.send_signal(signal.SIGINT)
    # what happened, not how fast: the run left alone takes hours on a loaded machine (1e6 pure-Python doSteps), so
    # exit 130 means the SIGINT stopped it; the timeout only ends a run that ignored it (the 1 s latency is measured
    # by the slow campaign, tests/harness/test_interrupt_campaign.py)
    out, err = process.communicate(timeout=600)
    assert process.returncode == 130, (out, err)
    assert list(tmp_path.iterdir()) == []  # the FMU's extracted folder removed
