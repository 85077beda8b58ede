"""The ladder's measuring machinery (ladder.py, timing_host.c) on a stand-in FMU: the C host's run specifications,
the interleaved rounds and the instruction count. No timing is asserted; the real FMUs' ladder is checked in
test_bench.py (--quick) and, with the instruction counts, in the slow test below."""
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from vibrofmu.speed import ladder

from vibrofmu.fmus import toolchain

# A stand-in FMU: every fmi2DoStep runs the same fixed loop (WORK iterations) and x = t, so that every doStep
# + getReal pair executes exactly the same instructions: a count that is right must be proportional to the
# number of outputs, with no constant part (instantiation, set-up or the host's own loop would add one).
STAND_IN = r"""
#include "fmi2Functions.h"
typedef struct { double t, acc; } S;
static S state;
fmi2Component fmi2Instantiate(fmi2String n, fmi2Type k, fmi2String g, fmi2String r, const fmi2CallbackFunctions *f,
                              fmi2Boolean v, fmi2Boolean l)
{ (void)n; (void)k; (void)g; (void)r; (void)f; (void)v; (void)l; state.t = 0.0; state.acc = 0.0; return &state; }
void fmi2FreeInstance(fmi2Component c) { (void)c; }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real d, fmi2Boolean e, fmi2Real f)
{ (void)c; (void)a; (void)b; (void)d; (void)e; (void)f; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[])
{ (void)vr; for (size_t i = 0; i < n; i++) v[i] = ((S *)c)->t; return fmi2OK; }
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[])
{ (void)c; (void)vr; (void)n; (void)v; return fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[])
{ (void)c; (void)vr; (void)n; (void)v; return fmi2OK; }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean p)
{
    (void)p;
    S *s = c;
    for (int i = 0; i < WORK; i++) s->acc += 1e-3 * (double)i;
    s->t = t + h;
    return fmi2OK;
}
"""
WORK = 100


@pytest.fixture(scope="module")
def stand_in(tmp_path_factory):
    """(timing host, stand-in library) compiled here."""
    out = tmp_path_factory.mktemp("stand_in")
    source = out / "stand_in.c"
    source.write_text(STAND_IN)
    library = out / "stand_in.so"
    subprocess.run([*toolchain.c_compiler(), "-O1", "-shared", "-fPIC", f"-DWORK={WORK}", toolchain.fmi_include(), "-o",
                    str(library), str(source)], check=True, capture_output=True)
    return ladder.compile_timing_host(out), library


def host_argv(host, library, stop, specs, repeats):
    """The timing host's command line for the stand-in: [(STEP, parameters)] as the first spec and 'then' ones."""
    (step, params), *others = specs
    cmd = [str(host), str(library), "file:///nowhere", "guid", repr(stop), repr(step), str(repeats), "0", *params]
    for step, params in others:
        cmd += ["then", repr(step), *params]
    return cmd


def test_timing_host_runs_each_specification_repeats_times_with_its_own_grid(stand_in):
    host, library = stand_in
    proc = subprocess.run(host_argv(host, library, 1.0, [(0.1, ["r3=2.5"]), (0.25, ["i4=1"]), (1.0, [])], 2),
                          capture_output=True, text=True, check=True)
    records = ladder.parse_host_output(proc.stdout, 3)
    for record, step in zip(records, (0.1, 0.25, 1.0)):
        grid = ladder.communication_points(1.0, step)
        assert len(record["loop"]) == len(record["init"]) == 2 and record["outputs"] == len(grid)
        # t: the host's n * step (printed with %.17g, which round-trips) against the grid's n * step, values <= 1:
        # atol 1e-15 (about 9 ulps of 1.0) admits only rounding and no wrong point (the points are >= 0.1 apart);
        # x == t exactly: the stand-in returns t + (next - t), and next - t is exact (Sterbenz: t <= next <= 2t,
        # or t = 0), so the sum is next
        assert np.allclose(record["t"], grid, rtol=0, atol=1e-15) and np.array_equal(record["x"], record["t"])
    with pytest.raises(RuntimeError, match="3 run specifications, not 2"):
        ladder.parse_host_output(proc.stdout, 2)


def test_instruction_count_is_exactly_proportional_to_the_outputs_or_valgrind_is_reported_missing(stand_in,
                                                                                                   monkeypatch):
    """With valgrind: the counts of runs with 10, 20 and 40 outputs are in the exact ratio 1 : 2 : 4 (only
    doStep + getReal are counted, each pair the same instructions) and a repeated run gives the same count. Without
    it: the reason names valgrind. Either way a missing valgrind is reported, not an error."""
    monkeypatch.setattr(shutil, "which", lambda name, *a, **k: None)
    assert "valgrind is not installed" in ladder.valgrind_missing()
    monkeypatch.undo()
    if ladder.valgrind_missing() is not None:
        assert shutil.which("valgrind") is None
        return
    host, library = stand_in
    cmd = host_argv(host, library, 1.0, [(0.1, []), (0.05, []), (0.025, [])], 2)
    counts, proc = ladder.callgrind_counts(cmd, None, 6)
    records = ladder.parse_host_output(proc.stdout, 3)
    assert [r["outputs"] for r in records] == [10, 20, 40]
    assert counts[0] == counts[1] and counts[2] == counts[3] and counts[4] == counts[5]  # deterministic
    per_output = counts[0] / 10
    assert per_output > WORK  # the stand-in's loop alone runs WORK iterations
    assert counts[2] == 2 * counts[0] and counts[4] == 4 * counts[0]  # no constant part: only the loop's calls
    with pytest.raises(RuntimeError, match="profiles for 5 runs"):
        ladder.callgrind_counts(cmd, None, 5)


def stand_in_runs(monkeypatch) -> list:
    """Replace run_ladder's runs by stand-ins that record what ran (no FMU, no timing); returns that record."""
    ran = []

    def fake_run(name):
        def run(*args):
            start = args[2]
            interval = args[4]
            ran.append((name, tuple(sorted(start.items())), interval))
            n = len(ladder.communication_points(args[3], interval))
            t = np.array(ladder.communication_points(args[3], interval))
            cost = 1.0 + len(ran)  # a distinct loop time per run, to check the per-round ratios
            cpu = 1.0 + (len(ran) % 7)  # and a distinct CPU time, not proportional to it
            return {"loop": [cost * n], "cpu": [cpu * n], "init": [0.0], "outputs": n, "t": t, "x": 0.04 * np.ones(n)}
        return run

    monkeypatch.setattr(ladder, "host_runs", lambda host, unzip, specs, stop:
                        [fake_run("C host")(host, unzip, start, stop, step) for start, step in specs])
    monkeypatch.setattr(ladder, "_fmpy_once", fake_run("FMPy"))
    monkeypatch.setattr(ladder, "compile_timing_host", lambda out: Path(out) / "host")
    monkeypatch.setattr(ladder, "extract", lambda fmu, out: out)
    return ran


def test_rounds_interleave_every_rung_in_every_column(monkeypatch):
    """run_ladder's order, with stand-in runs: each round runs every rung once in every column before the next
    round starts, and round r starts at rung r."""
    ran = stand_in_runs(monkeypatch)
    record = ladder.run_ladder(Path("plant.fmu"), Path("closed_loop.fmu"), stop=1.0, rounds=3, instructions=False)
    names = [name for name, _, _ in ladder.RUNGS]
    columns = [(c["host"], c["interval"]) for c in record["columns"]]
    assert columns == list(ladder.COLUMNS)
    order = record["order"]
    assert len(order) == len(ran) == 4 * len(names) * len(columns)  # a warm-up round (0), then 3
    for r in (0, 1, 2, 3):
        this = [o for o in order if o["round"] == r]
        assert sorted((o["rung"], o["host"], o["interval"]) for o in this) == sorted(
            (n, h, i) for n in names for h, i in columns)
        assert this[0]["rung"] == names[max(r - 1, 0) % len(names)]
    assert [o["round"] for o in order] == sorted(o["round"] for o in order)  # rounds do not overlap
    assert [(o["host"], o["interval"]) for o in order] == [(run[0], run[2]) for run in ran]
    # per cell every round kept; the per-round ratio pairs runs of the same round and column
    for rung in record["rungs"]:
        for c in rung["columns"]:
            assert len(c["cost_per_output_seconds_runs"]) == 3  # the warm-up's run is not kept
            warm = [i for i, o in enumerate(order) if o["round"] == 0 and (o["host"], o["interval"], o["rung"]) ==
                    (c["host"], c["interval"], rung["rung"])]
            kept = [1.0 + 1 + i for i, o in enumerate(order) if o["round"] > 0 and (o["host"], o["interval"], o["rung"])
                    == (c["host"], c["interval"], rung["rung"])]
            # the stand-in's seconds are small integers divided by the outputs: one rounding (half an ulp, 1.1e-16
            # relative) per value; rel 1e-15 admits a few such roundings and no other run's value
            assert len(warm) == 1 and c["cost_per_output_seconds_runs"] == pytest.approx(kept, rel=1e-15)
            assert c["cost_per_output_seconds"] == min(c["cost_per_output_seconds_runs"])
            base = next(b for b in record["rungs"][0]["columns"] if (b["host"], b["interval"]) == (c["host"], c["interval"]))
            expected = [a / b for a, b in zip(c["cost_per_output_seconds_runs"], base["cost_per_output_seconds_runs"])]
            # the same quotients of the same doubles recomputed: at most a rounding or two, inside rel 1e-15
            assert c["over_exact_f0_per_round"] == pytest.approx(expected, rel=1e-15)
            assert c["over_exact_f0_median"] == pytest.approx(sorted(expected)[1], rel=1e-15)
            cpu = [a / b for a, b in zip(c["cpu_per_output_seconds_runs"], base["cpu_per_output_seconds_runs"])]
            assert c["cpu_over_exact_f0_median"] == pytest.approx(sorted(cpu)[1], rel=1e-15)
            assert c["repeatable"]
    assert record["instructions"] == {"measured": False, "reason": "not requested (--no-instructions)",
                                      "intervals": [], "what": ladder.INSTRUCTIONS_NOTE}
    assert all("instructions" not in rung for rung in record["rungs"])
    for a in record["acceptance"]:
        # the median of the record's own ratios: the same doubles; approx's default rel 1e-6 checks the formula
        assert a["met"] == (a["ratio"] <= a["limit"]) and a["ratio"] == pytest.approx(np.median(a["ratios_per_round"]))
        column = next(c for r in record["rungs"] if r["rung"] == a["rung"] for c in r["columns"]
                      if (c["host"], c["interval"]) == (a["host"], a["interval"]))
        assert a["ratio"] == column["cpu_over_exact_f0_median"] != column["over_exact_f0_median"]  # CPU, not wall
    lines = ladder.ladder_lines(record)
    assert any("instructions per output: not measured: not requested" in line for line in lines)
    assert math.isfinite(record["acceptance"][0]["ratio_best_over_best"])
    # FMPy's own cost: per rung, FMPy's CPU minus the C host's at the same interval, paired by round, median
    (floor,) = record["fmpy_floor"]
    fmpy, c_host = list(ladder.COLUMNS).index(("FMPy", 1.0)), list(ladder.COLUMNS).index(("C host", 1.0))
    for rung in record["rungs"]:
        own = [a - b for a, b in zip(rung["columns"][fmpy]["cpu_per_output_seconds_runs"],
                                     rung["columns"][c_host]["cpu_per_output_seconds_runs"])]
        # the same differences of the same doubles recomputed: at most a rounding or two, inside rel 1e-15
        assert floor["fmpy_own_per_output_seconds"][rung["rung"]] == pytest.approx(sorted(own)[1], rel=1e-15)
    assert floor["floor_seconds"] == min(floor["fmpy_own_per_output_seconds"].values())
    f0 = sorted(record["rungs"][0]["columns"][fmpy]["cpu_per_output_seconds_runs"])[1]
    assert floor["lowest_reachable_ratio"] == pytest.approx(floor["floor_seconds"] / f0, rel=1e-15)
    assert any(line.startswith("  FMPy's own cost per output at interval 1") for line in lines)


def test_ladder_only_writes_bench_json_the_report_reads(plant_fmu, monkeypatch, tmp_path, capsys):
    """`vibrofmu bench --ladder-only` (stand-in runs): bench.json has the machine and the ladder, the command prints
    the ladder, and the report's speed block shows it."""
    from vibrofmu.speed import bench
    from vibrofmu.fmus import build
    from vibrofmu import report
    from vibrofmu.cli import main

    stand_in_runs(monkeypatch)
    real = ladder.run_ladder
    monkeypatch.setattr(ladder, "run_ladder", lambda plant, loop, **kw: real(plant, loop, **{**kw, "stop": 1.0}))
    monkeypatch.setattr(build, "build_closed_loop", lambda out: Path(out) / "closed_loop.fmu")
    code = main(["bench", "--ladder-only", "--no-instructions", "--fmu", str(plant_fmu),
                 "--out", str(tmp_path / "out")])
    assert code == 0
    data = __import__("json").loads((tmp_path / "out" / "bench.json").read_text())
    assert data["bench"]["ladder_only"] and "cases" not in data and data["ladder"]["rounds"] == bench.LADDER_ROUNDS
    assert (tmp_path / "out" / "ladder.png").stat().st_size > 10000
    printed = capsys.readouterr().out
    assert "speed-accuracy ladder" in printed and "closed loop / exact f0 (C host, interval 0.1)" in printed
    block = report.speed_block([tmp_path / "out"])
    assert "`vibrofmu bench --ladder-only`" in block and "CPU" in block and "median of rounds" in block


@pytest.mark.slow
def test_instruction_counts_of_the_real_fmus(plant_fmu, closed_loop_fmu, tmp_path):
    """The pythonfmu FMUs under callgrind (each starts its embedded Python under valgrind: minutes): every rung has
    a positive count at both intervals, exact f0's ratio is 1, and the C host's x under valgrind is the timed run's
    up to valgrind's floating point (it runs the same code; libm may pick other code paths under valgrind's CPU)."""
    if ladder.valgrind_missing() is not None:
        pytest.fail(ladder.valgrind_missing())
    record = ladder.run_ladder(plant_fmu, closed_loop_fmu, stop=2.0, rounds=1, instruction_intervals=(0.1, 1.0))
    assert record["instructions"]["measured"] and record["instructions"]["intervals"] == [0.1, 1.0]
    for rung in record["rungs"]:
        assert [c["interval"] for c in rung["instructions"]] == [0.1, 1.0]
        for c in rung["instructions"]:
            assert c["instructions"] > 0 and c["outputs"] == round(2.0 / c["interval"])
    assert all(c["over_exact_f0"] == 1.0 for c in record["rungs"][0]["instructions"])
    assert any("instructions per output of doStep" in line for line in ladder.ladder_lines(record))
    ladder.plot_ladder(tmp_path / "ladder.png", record)
