"""Issue 16: `vibrofmu study` on Dask — the engines agree, resume recomputes nothing, a killed worker loses
and duplicates no row, Ctrl-C leaves readable Parquet, an external scheduler works, bad specs exit 2.

The studies here are small Monte Carlo runs on the compiled core (`--engine core`: no FMU needed in the
workers); the FMU engine is checked equal to the core case by case in test_engines_give_the_same_bits.
"""
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from vibrofmu.cli import main
from vibrofmu.study.cases import make_cases, run_case
from vibrofmu.study.engines import CoreEngine, FmuEngine
from vibrofmu.study.spec import build_spec
from vibrofmu.study.storage import Store

BIN = Path(sys.executable).parent
# mu = 0.02: the transient decays 5x slower than at the paper's mu = 0.1, so a case takes ~0.1 s and a
# study of 24 is still running when the test interrupts it or kills a worker
SLOW_CASES = ["--set", "mu=0.02", "--set", "samples=24"]
# waits for a study's first part file, or its exit after SIGINT: only end a run that hangs (a loaded 2-core machine
# stretches seconds to minutes); the tests check what happened (exit code, rows, files), not how fast
WAIT_S = 900


@pytest.fixture(scope="module")
def cluster():
    """Two worker processes on 127.0.0.1 shared by the tests that run studies in this process (a cluster
    start costs seconds; the Ctrl-C test starts the command's own LocalCluster). No client is kept open: while a
    study runs, its own client must be the only one in the process, as it is under the CLI (a second synchronous
    client in the same process, with a worker dying, let distributed bind a future's wait event to the other
    client's loop: "is bound to a different event loop", seen in 1 of 2 runs)."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as local:
        yield local


def worker_pids(cluster, n: int) -> list[int]:
    """The PIDs of the cluster's n worker processes, through a short-lived client."""
    from distributed import Client

    with Client(cluster.scheduler_address) as client:
        client.wait_for_workers(n, timeout=30)
        return list(client.run(os.getpid).values())


def study(tmp_path, *extra, name="out"):
    out = tmp_path / name
    code = main(["study", "monte-carlo", "--engine", "core", "--out", str(out), *extra])
    return code, out


def rows(out: Path):
    return pq.read_table(out / "results.parquet").to_pylist()


def test_engines_give_the_same_bits(plant_fmu):
    """The FMU's C fast path steps the kernel that CompiledPlant steps (vibrokernel.c), with the same
    settings: every outcome column must be equal to the last bit, on basins cases (bistable point, long runs)
    and Monte Carlo samples."""
    core, fmu = CoreEngine(), FmuEngine(plant_fmu.read_bytes())
    basins = build_spec("basins", sets=["sigma=-0.0024"], quick=True)
    monte_carlo = build_spec("monte-carlo", quick=True)
    sample = [(basins, case) for case in make_cases(basins)[::21]] + [(monte_carlo, case) for case in make_cases(monte_carlo)[:3]]
    for spec, case in sample:
        a, b = run_case(spec, core, case)[0], run_case(spec, fmu, case)[0]
        for key in ("r", "A", "B", "mean", "settled", "periods", "x_end", "v_end", "contact_loss", "pull_in", "failed"):
            assert a[key] == b[key], (case, key, a[key], b[key])
        assert a["engine"] == "core" and b["engine"] == "fmu"


@pytest.mark.long  # a Dask cluster
def test_resume_recomputes_nothing_written(tmp_path, capsys, cluster):
    address = cluster.scheduler_address
    code, out = study(tmp_path, "--scheduler", address, "--set", "samples=10")
    assert code == 0
    first = {row["case"]: row for row in rows(out)}
    assert sorted(first) == list(range(10))
    # without --resume the folder is not overwritten; with it, only the same study continues (no cluster starts)
    assert study(tmp_path, "--workers", "1", "--set", "samples=10")[0] == 2
    assert study(tmp_path, "--workers", "1", "--set", "samples=11", "--resume")[0] == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert "already holds results" in errors[-2] and "holds another study" in errors[-1]
    # an interrupted study: cases 3, 4 and 7 never reached the disk
    kept = [row for case, row in first.items() if case not in (3, 4, 7)]
    import pyarrow as pa

    from vibrofmu.study.storage import write_atomic
    digest = json.loads((out / "spec.json").read_text())["digest"]  # a file without it would be set aside (issue 26)
    write_atomic(pa.Table.from_pylist(kept), out / "results.parquet", digest)
    code, _ = study(tmp_path, "--scheduler", address, "--set", "samples=10", "--resume")
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["computed_this_run"] == 3 and summary["resumed_from_disk"] == 7 and summary["cases"] == 10
    again = rows(out)
    assert sorted(row["case"] for row in again) == list(range(10))
    for row in again:
        if row["case"] not in (3, 4, 7):
            assert row == first[row["case"]]  # cost_s is a wall-clock measurement: a recomputed row would differ
        else:
            assert row["r"] == first[row["case"]]["r"]  # deterministic: the recomputed case gives the same bits


@pytest.mark.long  # a Dask cluster
def test_a_killed_worker_loses_and_duplicates_no_row(tmp_path, cluster):
    pids = worker_pids(cluster, 2)
    out = tmp_path / "out"
    killed = {}

    def kill_when_running():
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            parts = list((out / "parts").glob("*.parquet")) if (out / "parts").exists() else []
            if parts:  # the pilot is written: batches are running on both workers
                killed["written_before"] = len(Store(out).load_cases())
                os.kill(pids[0], signal.SIGKILL)
                return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_when_running)
    killer.start()
    code = main(["study", "monte-carlo", "--engine", "core", "--scheduler", cluster.scheduler_address,
                 "--out", str(out), *SLOW_CASES])
    killer.join()
    assert code == 0
    assert "written_before" in killed and killed["written_before"] < 24  # killed mid-study
    cases = [row["case"] for row in rows(out)]
    assert sorted(cases) == list(range(24))  # none lost, none twice
    assert pids[0] not in worker_pids(cluster, 2)  # the nanny replaced the killed worker


@pytest.mark.long  # a study in a subprocess
def test_ctrl_c_leaves_a_readable_parquet_file(tmp_path):
    out = tmp_path / "out"
    process = subprocess.Popen([str(BIN / "vibrofmu"), "study", "monte-carlo", "--engine", "core", "--workers", "1",
                                "--out", str(out), "--set", "mu=0.01", "--set", "samples=200"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                               # SIGINT's default action, as in a terminal (a test run in the background ignores it)
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + WAIT_S
        while not (out / "parts").exists() or not list((out / "parts").glob("*.parquet")):
            assert process.poll() is None and time.monotonic() < deadline, process.stderr.read() if process.poll() is not None else "timeout"
            time.sleep(0.05)
        os.killpg(process.pid, signal.SIGINT)  # as Ctrl-C in a terminal: the command and its worker processes
        _, err = process.communicate(timeout=WAIT_S)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, err
    assert "Traceback" not in err
    table = pq.read_table(out / "results.parquet")
    assert 1 <= table.num_rows < 200
    assert len(set(table.column("case").to_pylist())) == table.num_rows
    assert json.loads((out / "summary.json").read_text())["interrupted"] is True


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow  # ~12 s: starts a scheduler and a worker process
def test_external_scheduler_and_worker_processes(tmp_path):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                  "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([str(BIN / "dask"), "worker", address, "--nworkers", "1", "--nthreads", "1",
                               "--no-dashboard", "--host", "127.0.0.1"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        code, out = study(tmp_path, "--scheduler", address, "--set", "samples=6")
        assert code == 0
        summary = json.loads((out / "summary.json").read_text())
        assert summary["workers"] == 1 and summary["cases"] == 6 and summary["scheduler"] == address
        assert len({row["worker"] for row in rows(out)}) == 1
    finally:
        for process in (worker, scheduler):
            process.terminate()
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()


@pytest.mark.parametrize("args, spec_text, message", [
    (["--set", "nonsense=1"], None, "unknown parameter 'nonsense'"),
    ([], '[grid]\nx0 = [-0.5, 0.5, 0]\n', "empty grid"),
    ([], '[tolerances]\nmu = {distribution = "uniform", relative = -0.05}\n', "relative = -0.05"),
    (["--set", "mu=-1"], None, "mu"),
])
def test_bad_specs_give_one_line_and_exit_2(tmp_path, capsys, args, spec_text, message):
    kind = "basins" if spec_text and "grid" in spec_text else "monte-carlo"
    if spec_text:
        (tmp_path / "spec.toml").write_text(spec_text)
        args = args + ["--spec", str(tmp_path / "spec.toml")]
    assert main(["study", kind, "--out", str(tmp_path / "out"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err


def test_unreachable_scheduler_gives_one_line_and_exit_2(tmp_path, capsys):
    port = free_port()  # nothing listens there
    assert main(["study", "monte-carlo", "--engine", "core", "--scheduler", f"tcp://127.0.0.1:{port}",
                 "--out", str(tmp_path / "out")]) == 2
    err = [line for line in capsys.readouterr().err.strip().splitlines() if line.startswith("error")]
    assert len(err) == 1 and "cannot reach the Dask scheduler" in err[0]
    assert not (tmp_path / "out").exists()  # no spec.json and empty parts/ left behind


class _FakeClient:
    """A client of a scheduler (no local cluster): enough for study.run to reach execute."""

    def scheduler_info(self, n_workers=-1):
        return {"workers": {}}

    def register_plugin(self, plugin):
        pass

    def close(self, timeout=None):
        pass


def _interrupted_study(monkeypatch, tmp_path, *extra):
    """`study basins` on a (fake) scheduler, interrupted before any case is back: (exit code, out folder)."""
    from vibrofmu.study import scheduling

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(scheduling, "connect", lambda scheduler, workers: (_FakeClient(), None))
    monkeypatch.setattr(scheduling, "execute", interrupted)
    out = tmp_path / "out"
    return main(["study", "basins", "--quick", "--engine", "core", "--scheduler", "tcp://127.0.0.1:1",
                 "--out", str(out), *extra]), out


def test_an_interrupt_before_any_case_names_what_exists_and_lists_what_it_wrote(monkeypatch, tmp_path, capsys):
    code, out = _interrupted_study(monkeypatch, tmp_path)
    assert code == 130
    captured = capsys.readouterr()
    line = next(line for line in captured.err.splitlines() if line.startswith("interrupted: "))
    assert line.startswith("interrupted: 0/") and f"cases in {out};" in line  # not the results.parquet it has not
    wrote = [line for line in captured.out.splitlines() if line.startswith("wrote ")]
    assert len(wrote) == 1
    names = wrote[0].removeprefix(f"wrote {out}/").split(", ")
    assert sorted(names) == ["spec.json", "summary.json"] == sorted(p.name for p in out.iterdir() if p.is_file())


def test_an_interrupted_resume_leaves_no_plot_of_an_earlier_run(monkeypatch, tmp_path, capsys):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "basins.png").write_bytes(b"an earlier run's plot")
    code, out = _interrupted_study(monkeypatch, tmp_path, "--resume")
    assert code == 130 and not (out / "basins.png").exists()


# A child that blocks SIGINT: bit SIGINT - 1 of the hexadecimal SigBlk mask in /proc/PID/status (Linux).
SIGINT_BIT = 1 << (signal.SIGINT - 1)


def _blocked_mask(pid: int) -> int:
    for _ in range(600):  # the child's status exists from its fork; wait for it to run Python (its exec)
        status = Path(f"/proc/{pid}/status").read_text()
        if "python" in Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace"):
            return int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigBlk:")), 16)
        time.sleep(0.05)
    raise AssertionError(f"child {pid} never ran Python")


def test_spawned_workers_start_with_sigint_blocked():
    """A Ctrl-C reaches the whole process group: a cluster worker still importing (before worker_signals makes
    it ignore SIGINT) printed a KeyboardInterrupt traceback. After spawn_without_sigint, a spawned child starts
    with SIGINT blocked, and this process (the study's) does not block it."""
    import multiprocessing

    from vibrofmu.study import end_children
    from vibrofmu.study.scheduling import spawn_without_sigint

    spawn_without_sigint()
    child = multiprocessing.get_context("spawn").Process(target=time.sleep, args=(60,))
    child.start()
    try:
        assert _blocked_mask(child.pid) & SIGINT_BIT
        assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())
    finally:
        end_children()
        child.join(timeout=30)


def test_end_children_ends_a_child_being_spawned():
    """A child spawned but not yet among multiprocessing's active children (its start-up data not yet written) is
    ended too: left alone it read an empty pipe once this process was gone and printed an EOFError traceback."""
    from multiprocessing import util

    from vibrofmu.study import end_children
    from vibrofmu.study.scheduling import spawn_without_sigint

    spawn_without_sigint()
    pid = util.spawnv_passfds(b"/bin/sleep", [b"sleep", b"60"], ())  # spawned, never registered as a Process
    end_children()
    for _ in range(600):  # (a child left running would make waitpid block: poll, then kill it and fail)
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        time.sleep(0.1)
    else:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        raise AssertionError("end_children left the child being spawned running")
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL


def test_end_children_ends_a_spawned_child(tmp_path):
    """Before os._exit, study.run ends every process it started (a worker being spawned printed an EOFError
    traceback once its parent was gone)."""
    import multiprocessing

    from vibrofmu.study import end_children

    child = multiprocessing.get_context("spawn").Process(target=time.sleep, args=(60,))
    child.start()
    end_children()
    child.join(timeout=30)
    assert child.exitcode == -signal.SIGKILL
