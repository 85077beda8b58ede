"""The speed-accuracy ladder of `vibrofmu bench`: cost per output and error of x of every rung a user can pick.

A rung is one FMU configuration: exact f0 (Eq. 3, C kernel), polynomial f1, averaged f3, analytic f4, RK4 at
h = 0.01 (fidelity 0), and the closed-loop FMU (plant + adaptive controller). Each runs the paper example over
tau in [0, stop] in three columns:
  - a plain C FMI host (timing_host.c, compiled here; the pythonfmu binary gets `vibrofmu doctor`'s
    environment), at output intervals 0.1 and 1;
  - FMPy in this process, at output interval 1.
Timing (noisy machines): after a warm-up round, `rounds` interleaved rounds; each round runs every rung once in
every column, from a fresh instance (TIMING_NOTE), so that the rungs compared in a ratio ran side by side under the
same machine conditions. Per cell all rounds are kept; the cost per output is the best of them; the ratio to exact
f0 is given as best/best and as the median over rounds of the per-round ratio, which the acceptance reads
(ACCEPTANCE_NOTE).
Instructions (deterministic): the C host under valgrind's callgrind counts the instructions of doStep +
getReal(x) per output (INSTRUCTIONS_NOTE), at every interval of `instruction_intervals`; absent, with the reason,
when valgrind is not installed.
The error of x is the largest |x - x_ref| on the output grid: for the plant's rungs against the exact model's
reference (DOP853, rtol 1e-13); for the closed loop against the closed loop itself run in vibromodel at rtol 1e-12
(its x is a different trajectory: the plant under control).
"""
from __future__ import annotations

import itertools
import math
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description

from vibromodel import fidelities
from vibromodel.fidelities import Fidelity
from vibromodel.integrate import ATOL_PER_RTOL
from vibromodel.parameters import Scene
from vibromodel.settings import Settings

from vibrofmu import paths
from vibrofmu.fmus import toolchain
from vibrofmu.hosts.doctor import host_environment
from vibrofmu.analyses.reference import reference_solution
from vibrofmu.hosts.run import FmuInstance
from vibrofmu.speed import child

TIMING_HOST_SOURCE = Path(__file__).with_name("timing_host.c")
FMU_SRC = paths.FMU_SRC  # the checkout's fmu_src/ or the installed vibrofmu/fmu_src/
REFERENCE_RTOL = 1e-13
CLOSED_LOOP_REFERENCE_RTOL = 1e-12
C_INTERVALS = (0.1, 1.0)
FMPY_INTERVAL = 1.0
LEVELS = tuple(e for e in fidelities.REGISTRY.values() if e.ladder)  # the registry's rungs, the base first
BASE = LEVELS[0].rung  # "exact f0": the plant FMU at its default fidelity
RUNGS = (  # (name, FMU, start values)
    *((e.rung, "plant", {} if e.level == Settings().fidelity else {"fidelity": int(e.level)}) for e in LEVELS),
    ("RK4 h = 0.01", "plant", {"solver": 1, "max_step": 0.01}),
    ("closed loop", "closed_loop", {}),
)
# issue 13's acceptance: cost per output of a rung over exact f0's, at most
LIMITS = {**{e.rung: e.ladder_limit for e in LEVELS if e.ladder_limit is not None}, "RK4 h = 0.01": 4.0,
          "closed loop": 3.0}
COLUMNS = tuple(("C host", interval) for interval in C_INTERVALS) + (("FMPy", FMPY_INTERVAL),)
ACCEPTANCE_COLUMNS = (("C host", 0.1), ("FMPy", FMPY_INTERVAL))  # the issue's: C host at 0.1, FMPy at 1
INSTRUCTION_INTERVALS = C_INTERVALS
TIMING_NOTE = ("a warm-up round (round 0 in order, not kept: the first FMPy instance of a process pays for loading and "
               "first calls), then interleaved rounds: in each round every rung runs once in every column (C host "
               "0.1, C host 1, FMPy 1; within a column the rungs run back to back, round r starting at rung r), each from a fresh "
               "instance (the C host runs consecutive rungs of one FMU in one process; the first instantiation in "
               "a process also starts the embedded Python); "
               "cost per output = wall time of the doStep + getReal(x) loop / outputs; per cell all rounds are kept "
               "(cost_per_output_seconds_runs: wall time; cpu_per_output_seconds_runs: the loop's thread CPU time, C "
               "host CLOCK_THREAD_CPUTIME_ID, FMPy time.thread_time, which does not count the time the thread waits "
               "for a CPU held by other processes); cost_per_output_seconds and cpu_per_output_seconds are the best "
               "of the rounds")
ACCEPTANCE_NOTE = ("the acceptance reads the median over rounds of the per-round ratio of the loops' thread CPU times "
                   "(rung's / exact f0's in the same round and column: measured side by side, so a slow machine phase "
                   "that covers both cancels, and the median of three drops one round where the phase changed in "
                   "between). Thread CPU time rather than wall time: on a loaded machine the wall time also counts the "
                   "waits for a CPU, and a long loop (RK4, the closed loop) is preempted more often than a short one "
                   "(exact f0's), which inflates the wall ratios systematically, not at random -- seen here: RK4's "
                   "loop on [0, 200] took 30 ms wall for 6.5 ms of CPU at load average 15 on 2 CPUs, f0's 2 ms loop "
                   "wall = CPU. On an idle machine the two agree (the loop runs in the calling thread, no other "
                   "thread works for it). The wall-time ratios (median per round and best/best) are reported beside "
                   "it.")
FLOOR_NOTE = ("FMPy's own cost per output: a rung's thread CPU time per output under FMPy minus the same rung's in the C "
              "host at the same interval, paired round by round (the same FMU binary and doStep/getReal calls; what "
              "remains is FMPy's Python wrappers and ctypes), median over rounds; the floor is its smallest value "
              "over the rungs. No rung can cost less than that floor under FMPy, so no rung's ratio to exact f0 can "
              "go below floor / (exact f0's cost under FMPy) while exact f0 costs what it does.")
INSTRUCTIONS_NOTE = ("instructions executed in doStep + getReal(x) and everything they call, divided by the outputs: "
                     "the C host under valgrind --tool=callgrind --collect-atstart=no --toggle-collect=timing_do_step "
                     "--toggle-collect=timing_get_real (timing_host.c's wrappers of fmi2DoStep and fmi2GetReal), one "
                     "run per rung and interval from a fresh instance; deterministic (no noise), but blind to "
                     "memory stalls and to the cost of each instruction (a division or exp counts as one)")


def compile_timing_host(out_dir: Path) -> Path:
    return toolchain.compile_host(TIMING_HOST_SOURCE, Path(out_dir) / "timing_host")


def host_command(host: Path, unzip_dir: Path, specs: list[tuple[dict, float]], stop: float,
                 repeats: int) -> tuple[list[str], dict]:
    """(argv, environment) of the C host for the run specifications [(start values, output interval)] of one FMU:
    the first as STEP and parameters, every further one after "then" (timing_host.c)."""
    md = read_model_description(str(unzip_dir))
    variables = {v.name: v for v in md.modelVariables}
    library = Path(unzip_dir) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"

    def arguments(start):
        return [("i" if variables[name].type == "Integer" else "r") + f"{variables[name].valueReference}={value!r}"
                for name, value in start.items()]

    (first, step), *others = specs
    cmd = [str(host), str(library), (Path(unzip_dir) / "resources").as_uri(), md.guid, repr(stop), repr(step),
           str(repeats), str(variables["x"].valueReference), *arguments(first)]
    for start, interval in others:
        cmd += ["then", repr(interval), *arguments(start)]
    return cmd, {**os.environ, **host_environment(Path(unzip_dir) / "resources")}


def parse_host_output(stdout: str, specs: int) -> list[dict]:
    """The C host's stdout as one record per specification: {"loop": [seconds per run], "init": [...], "outputs",
    "t": grid, "x": x of the last run}."""
    records, record = [], None
    for line in stdout.splitlines():
        kind, *values = line.split()
        if kind == "init" and (record is None or record["x"]):  # the first run of the next specification
            record = {"loop": [], "init": [], "cpu": [], "t": [], "x": []}
            records.append(record)
        if kind == "init":
            record["init"].append(float(values[0]))
        elif kind == "loop":
            record["loop"].append(float(values[0]))
            record["outputs"] = int(values[1])
            record.setdefault("cpu", []).append(float(values[2]))
        elif kind == "x":
            record["t"].append(float(values[0]))
            record["x"].append(float(values[1]))
    if len(records) != specs:
        raise RuntimeError(f"the timing host reported {len(records)} run specifications, not {specs}")
    for record in records:
        record["t"], record["x"] = np.array(record["t"]), np.array(record["x"])
    return records


def host_runs(host: Path, unzip_dir: Path, specs: list[tuple[dict, float]], stop: float) -> list[dict]:
    """Several rungs of one FMU [(start values, interval)] in one C host process, one run each from a fresh
    instance, in the given order: one record per rung (as host_run's)."""
    cmd, env = host_command(host, unzip_dir, specs, stop, 1)
    proc = child.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    if proc.returncode != 0:
        raise RuntimeError(f"timing host failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    return parse_host_output(proc.stdout, len(specs))


def host_run(host: Path, unzip_dir: Path, start: dict, stop: float, step: float, repeats: int) -> dict:
    """One rung in the C host: {"loop": [seconds per run], "init": [...], "t": grid, "x": x of the last run}."""
    cmd, env = host_command(host, unzip_dir, [(start, step)], stop, repeats)
    proc = child.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    if proc.returncode != 0:
        raise RuntimeError(f"timing host failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    return parse_host_output(proc.stdout, 1)[0]


# ---- instruction counts (callgrind) ---------------------------------------------------------------------------

def valgrind_missing() -> str | None:
    """None if valgrind's callgrind can count instructions here, else the reason it cannot."""
    if shutil.which("valgrind") is None:
        return "valgrind is not installed (apt-get install valgrind): no instruction counts"
    return None


def callgrind_counts(cmd: list[str], env: dict, runs: int, collect=("timing_do_step", "timing_get_real"),
                     dump_after: str = "timing_run_done") -> tuple[list[int], subprocess.CompletedProcess]:
    """Instructions executed inside the functions `collect` and all they call, one count per run, under valgrind
    --tool=callgrind: collection is on only inside those functions, and a profile is dumped after each run (the
    function dump_after). By default timing_host.c's timing_do_step and timing_get_real (doStep + getReal), dumped
    at timing_run_done."""
    with tempfile.TemporaryDirectory(prefix="vibrofmu-callgrind-") as tmp:
        out = Path(tmp) / "callgrind.out"
        proc = child.run(["valgrind", "--tool=callgrind", "--collect-atstart=no",
                          *(f"--toggle-collect={name}" for name in collect),
                          f"--dump-after={dump_after}", f"--callgrind-out-file={out}", *cmd],
                         capture_output=True, text=True, env=env, timeout=3600)
        if proc.returncode != 0:
            raise RuntimeError(f"valgrind failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
        dumps = sorted(Path(tmp).glob("callgrind.out.*"), key=lambda p: int(p.name.rsplit(".", 1)[1]))
        counts = []
        for dump in dumps:
            totals = [line for line in dump.read_text().splitlines() if line.startswith(("totals:", "summary:"))]
            counts.append(int(totals[0].split()[1]))
    if len(counts) != runs:
        raise RuntimeError(f"callgrind wrote {len(counts)} profiles for {runs} runs")
    return counts, proc


def fmpy_run(fmu: Path, unzip_dir: str, start: dict, stop: float, step: float, repeats: int) -> dict:
    """One rung under FMPy in this process, the same loop as the C host's."""
    record = {"loop": [], "init": [], "cpu": [], "t": None, "x": None}
    n = len(communication_points(stop, step))
    for _ in range(repeats):
        started = time.perf_counter()
        with FmuInstance(fmu, instance_name="ladder", unzip_dir=unzip_dir) as instance:
            f = instance.fmu
            f.setupExperiment(startTime=0.0, stopTime=stop)
            f.enterInitializationMode()
            instance.set(start)
            f.exitInitializationMode()
            refs = instance.value_references(["x"])
            xs = np.empty(n)
            points = communication_points(stop, step)
            do_step, get_real = f.doStep, f.getReal
            cpu_started = time.thread_time()
            loop_started = time.perf_counter()
            t = 0.0
            for i, next_t in enumerate(points):
                do_step(t, next_t - t)
                xs[i] = get_real(refs)[0]
                t = next_t
            finished = time.perf_counter()
            cpu = time.thread_time() - cpu_started
        record["init"].append(loop_started - started)
        record["loop"].append(finished - loop_started)
        record["cpu"].append(cpu)
    record["t"], record["x"], record["outputs"] = np.array(points), xs, n
    return record


def communication_points(stop: float, step: float) -> list[float]:
    """n step for n = 1, 2, ..., the last clipped to stop: timing_host.c's points (and FMPy's simulate_fmu's)."""
    points, n, t = [], 1, 0.0
    while not (t > stop or math.isclose(t, stop)):
        t = n * step
        if t > stop and not math.isclose(t, stop):
            t = stop
        points.append(t)
        n += 1
    return points


def closed_loop_reference(stop: float):
    """x of the closed loop with the FMU's defaults, run in vibromodel at rtol 1e-12, as a function of the grid."""
    from vibromodel.closedloop import ERRATA_SCENE, ClosedLoop, LoopSettings
    from vibromodel.plant import Settings

    loop = ClosedLoop(ERRATA_SCENE, Settings(rtol=CLOSED_LOOP_REFERENCE_RTOL), LoopSettings(), 0.0, stop)
    step = min(C_INTERVALS)
    n = int(round(stop / step))
    xs = np.array([loop.do_step(i * step, step)["x"] for i in range(n)])
    grid = step * np.arange(1, n + 1)

    def at(t):
        index = np.rint(np.asarray(t) / step).astype(int) - 1
        if not np.allclose(grid[index], t, rtol=1e-9, atol=0.0):
            raise ValueError("the closed loop's reference is on the 0.1 grid only")
        return xs[index]

    return at


def _rotated(items: list, k: int) -> list:
    return items[k % len(items):] + items[:k % len(items)]


def _fmpy_once(fmu: Path, unzip_dir: str, start: dict, stop: float, step: float) -> dict:
    run = fmpy_run(fmu, unzip_dir, start, stop, step, 1)
    return {"loop": run["loop"], "cpu": run["cpu"], "init": run["init"], "outputs": run["outputs"], "t": run["t"],
            "x": run["x"]}


def instruction_counts(host: Path, unzipped: dict, stop: float, intervals: tuple[float, ...], say) -> dict:
    """Instructions per output of every rung at every interval: one valgrind process per FMU running all of its
    rungs (timing_host's run specifications), so that the embedded Python starts once per FMU under valgrind."""
    counts = {}
    for which in dict.fromkeys(fmu for _, fmu, _ in RUNGS):
        cells = [(name, start, interval) for name, fmu, start in RUNGS if fmu == which for interval in intervals]
        cmd, env = host_command(host, Path(unzipped[which]), [(start, interval) for _, start, interval in cells],
                                stop, 1)
        started = time.perf_counter()
        instructions, proc = callgrind_counts(cmd, env, len(cells))
        records = parse_host_output(proc.stdout, len(cells))
        for (name, _, interval), count, record in zip(cells, instructions, records):
            counts[name, interval] = {"instructions": count, "outputs": record["outputs"],
                                      "per_output": count / record["outputs"], "x": record["x"]}
        say(f"ladder: instruction counts of the {which} FMU's rungs under callgrind "
            f"({time.perf_counter() - started:.0f} s)")
    return counts


def run_ladder(plant_fmu: Path, closed_loop_fmu: Path, stop: float = 200.0, rounds: int = 3,
               instructions: bool = True, instruction_intervals: tuple[float, ...] = INSTRUCTION_INTERVALS,
               progress=None) -> dict:
    """Every rung in every column, in interleaved rounds, and (valgrind permitting) its instruction count: the
    ladder's record for bench.json (see the module docstring)."""
    say = progress or (lambda line: None)
    scene = Scene()
    exact = reference_solution(scene, Fidelity.EXACT, stop, rtol=REFERENCE_RTOL, atol=ATOL_PER_RTOL * REFERENCE_RTOL)
    references = {"plant": lambda t: exact(t)[0], "closed_loop": closed_loop_reference(stop)}
    fmus = {"plant": Path(plant_fmu), "closed_loop": Path(closed_loop_fmu)}
    names = [name for name, _, _ in RUNGS]
    spec = {name: (which, start) for name, which, start in RUNGS}
    runs = {(name, column): [] for name in names for column in COLUMNS}
    order = []
    missing = valgrind_missing() if instructions else "not requested (--no-instructions)"
    with tempfile.TemporaryDirectory(prefix="vibrofmu-ladder-") as work:
        host = compile_timing_host(Path(work))
        unzipped = {name: extract(str(path), str(Path(work) / name)) for name, path in fmus.items()}
        began = time.perf_counter()
        for r in range(rounds + 1):  # round 0: a warm-up, not kept; then every rung in every column once per round
            for column in COLUMNS:
                host_name, interval = column
                # round r starts at rung r: no rung always runs first; consecutive rungs of one FMU form a group,
                # which the C host runs in one process (a fresh instance each, one after the other)
                rotated = _rotated(names, max(r - 1, 0))
                groups = [list(g) for _, g in itertools.groupby(rotated, key=lambda n: spec[n][0])]
                for group in groups:
                    which = spec[group[0]][0]
                    started = time.perf_counter() - began
                    order += [{"round": r, "host": host_name, "interval": interval, "rung": name,
                               "started_seconds": started} for name in group]
                    if host_name == "C host":
                        results = host_runs(host, Path(unzipped[which]), [(spec[name][1], interval) for name in group],
                                            stop)
                    else:
                        results = [_fmpy_once(fmus[which], unzipped[which], spec[name][1], stop, interval)
                                   for name in group]
                    if r > 0:
                        for name, run in zip(group, results):
                            runs[name, column].append(run)
            if r > 0:
                last = {name: runs[name, COLUMNS[0]][-1] for name in names}
                say(f"ladder: round {r} of {rounds}: " + ", ".join(
                    f"{name} {1e6 * run['cpu'][0] / run['outputs']:.3g} us" for name, run in last.items())
                    + f" (thread CPU per output, C host, interval {COLUMNS[0][1]:g})")
        counts = {}
        if missing is None:
            counts = instruction_counts(host, unzipped, stop, instruction_intervals, say)
    rungs = []
    for name in names:
        which, start = spec[name]
        rung = {"rung": name, "fmu": which, "start_values": start, "columns": []}
        for column in COLUMNS:
            cell = runs[name, column]
            first = cell[0]
            n = first["outputs"]
            loops = [run["loop"][0] for run in cell]
            error = float(np.max(np.abs(first["x"] - references[which](first["t"]))))
            rung["columns"].append({
                "host": column[0], "interval": column[1], "outputs": n,
                "cost_per_output_seconds": min(loops) / n,
                "cost_per_output_seconds_runs": [loop / n for loop in loops],
                "loop_seconds_runs": loops, "instantiation_seconds_runs": [run["init"][0] for run in cell],
                "cpu_per_output_seconds": min(run["cpu"][0] for run in cell) / n,
                "cpu_per_output_seconds_runs": [run["cpu"][0] / n for run in cell],
                "repeatable": all(np.array_equal(run["x"], first["x"]) for run in cell),
                "linf_x": error})
        if counts:
            rung["instructions"] = [{"host": "C host (callgrind)", "interval": interval,
                                     "outputs": counts[name, interval]["outputs"],
                                     "instructions": counts[name, interval]["instructions"],
                                     "instructions_per_output": counts[name, interval]["per_output"],
                                     "x_identical_to_timed_run": bool(np.array_equal(
                                         counts[name, interval]["x"],
                                         runs[name, ("C host", interval)][0]["x"]))
                                     if ("C host", interval) in COLUMNS else None}
                                    for interval in instruction_intervals]
        rungs.append(rung)
    base = rungs[0]
    for rung in rungs:
        for column, base_column in zip(rung["columns"], base["columns"]):
            for prefix, runs_key in (("", "cost_per_output_seconds_runs"), ("cpu_", "cpu_per_output_seconds_runs")):
                per_round = [a / b for a, b in zip(column[runs_key], base_column[runs_key])]
                column[f"{prefix}over_exact_f0_per_round"] = per_round
                column[f"{prefix}over_exact_f0_median"] = float(np.median(per_round))
                column[f"{prefix}over_exact_f0_best"] = min(column[runs_key]) / min(base_column[runs_key])
        for count, base_count in zip(rung.get("instructions", []), base.get("instructions", [])):
            count["over_exact_f0"] = count["instructions_per_output"] / base_count["instructions_per_output"]
    acceptance = [{"rung": r["rung"], "host": c["host"], "interval": c["interval"],
                   "ratio": c["cpu_over_exact_f0_median"], "ratios_per_round": c["cpu_over_exact_f0_per_round"],
                   "ratio_best_over_best": c["cpu_over_exact_f0_best"],
                   "ratio_wall": c["over_exact_f0_median"], "ratios_per_round_wall": c["over_exact_f0_per_round"],
                   "ratio_wall_best_over_best": c["over_exact_f0_best"], "limit": LIMITS[r["rung"]],
                   "met": c["cpu_over_exact_f0_median"] <= LIMITS[r["rung"]]}
                  for r in rungs if r["rung"] in LIMITS for c in r["columns"]
                  if (c["host"], c["interval"]) in ACCEPTANCE_COLUMNS]
    acceptance_instructions = [{"rung": r["rung"], "interval": c["interval"], "ratio": c["over_exact_f0"],
                                "limit": LIMITS[r["rung"]], "met": c["over_exact_f0"] <= LIMITS[r["rung"]]}
                               for r in rungs if r["rung"] in LIMITS for c in r.get("instructions", [])]
    return {"stop_time": stop, "rounds": rounds, "repeats": rounds, "scene": scene.as_dict(),
            "columns": [{"host": h, "interval": i} for h, i in COLUMNS],
            "timing": TIMING_NOTE, "acceptance_rule": ACCEPTANCE_NOTE, "order": order,
            "errors": f"max |x - x_ref| on the output grid; plant rungs against the exact model (DOP853 rtol "
                      f"{REFERENCE_RTOL:g}), the closed loop against itself in vibromodel at rtol "
                      f"{CLOSED_LOOP_REFERENCE_RTOL:g}",
            "instructions": {"measured": not missing, "reason": missing,
                             "intervals": list(instruction_intervals) if not missing else [],
                             "what": INSTRUCTIONS_NOTE},
            "rungs": rungs, "acceptance": acceptance, "acceptance_instructions": acceptance_instructions,
            "fmpy_floor": fmpy_floor(rungs)}


def fmpy_floor(rungs: list[dict]) -> list[dict]:
    """Per FMPy column with a C host column at the same interval: FMPy's own cost per output of every rung (FLOOR_NOTE),
    the floor (the smallest over the rungs) and the lowest ratio to exact f0 any rung can then reach."""
    floors = []
    for index, (host, interval) in enumerate(COLUMNS):
        if host != "FMPy" or ("C host", interval) not in COLUMNS:
            continue
        c_index = COLUMNS.index(("C host", interval))
        own = {}
        for rung in rungs:
            fmpy, c = rung["columns"][index], rung["columns"][c_index]
            own[rung["rung"]] = float(np.median([a - b for a, b in zip(fmpy["cpu_per_output_seconds_runs"],
                                                                       c["cpu_per_output_seconds_runs"])]))
        base = float(np.median(rungs[0]["columns"][index]["cpu_per_output_seconds_runs"]))
        floor = min(own.values())
        floors.append({"interval": interval, "fmpy_own_per_output_seconds": own, "floor_seconds": floor,
                       "exact_f0_seconds": base, "lowest_reachable_ratio": floor / base, "what": FLOOR_NOTE})
    return floors


def ladder_lines(ladder: dict) -> list[str]:
    """The ladder as a table (time, then instructions) and the acceptance ratios, for the command's output."""
    columns = [(c["host"], c["interval"]) for c in ladder["rungs"][0]["columns"]]
    rounds = ladder.get("rounds", ladder.get("repeats"))
    cpu = "cpu_per_output_seconds" in ladder["rungs"][0]["columns"][0]
    width = 34 if cpu else 26
    head = "  rung            " + "".join(f"{h} {i:g}".rjust(width) for h, i in columns)
    lines = [(f"speed-accuracy ladder (paper example, tau in [0, {ladder['stop_time']:g}], {rounds} interleaved rounds; "
              "per cell: best thread CPU us per output (best wall us), median over rounds of the CPU ratio to exact "
              "f0, x error):") if cpu else
             f"speed-accuracy ladder (paper example, tau in [0, {ladder['stop_time']:g}], best of {rounds}; us per "
             "output, x error):", head]
    for rung in ladder["rungs"]:
        if cpu:
            cells = "".join(f"{1e6 * c['cpu_per_output_seconds']:7.3g} ({1e6 * c['cost_per_output_seconds']:.3g}) us "
                            f"{c['cpu_over_exact_f0_median']:6.3g}x {c['linf_x']:7.1e}".rjust(width)
                            for c in rung["columns"])
        else:  # a bench.json from before the interleaved rounds
            cells = "".join(f"{1e6 * c['cost_per_output_seconds']:9.3g} us {c['over_exact_f0']:5.2g}x "
                            f"{c['linf_x']:7.1e}".rjust(width) for c in rung["columns"])
        lines.append(f"  {rung['rung']:<16}{cells}")
    info = ladder.get("instructions") or {}
    if info.get("measured"):
        intervals = info["intervals"]
        lines.append("  instructions per output of doStep + getReal(x), C host under callgrind (repeatable on one "
                     "machine; the counts depend on its compiler, libm and CPU), ratio to exact f0:")
        lines.append("  rung            " + "".join(f"interval {i:g}".rjust(24) for i in intervals))
        for rung in ladder["rungs"]:
            cells = "".join(f"{c['instructions_per_output']:12.4g} {c['over_exact_f0']:8.3g}x".rjust(24)
                            for c in rung["instructions"])
            lines.append(f"  {rung['rung']:<16}{cells}")
    elif info:
        lines.append(f"  instructions per output: not measured: {info['reason']}")
    for a in ladder["acceptance"]:
        verdict = f"(limit {a['limit']:g}: {'met' if a['met'] else 'NOT met'})"
        head = f"  {a['rung']} / exact f0 ({a['host']}, interval {a['interval']:g}): "
        if "ratio_wall" not in a:  # a bench.json from before the interleaved rounds
            lines.append(head + f"{a['ratio']:.3g} {verdict}")
            continue
        per_round = " ".join(f"{x:.3g}" for x in a["ratios_per_round"])
        lines.append(head + f"CPU {a['ratio']:.3g} median of rounds [{per_round}] {verdict}; best/best "
                     f"{a['ratio_best_over_best']:.3g}; wall time {a['ratio_wall']:.3g} median, "
                     f"{a['ratio_wall_best_over_best']:.3g} best/best")
    for a in ladder.get("acceptance_instructions", []):
        lines.append(f"  {a['rung']} / exact f0 (instructions, interval {a['interval']:g}): {a['ratio']:.3g} "
                     f"(limit {a['limit']:g}: {'met' if a['met'] else 'NOT met'})")
    for f in ladder.get("fmpy_floor", []):
        own = ", ".join(f"{name} {1e6 * value:.3g}" for name, value in f["fmpy_own_per_output_seconds"].items())
        lines.append(f"  FMPy's own cost per output at interval {f['interval']:g} (FMPy - C host, thread CPU, median of "
                     f"rounds; us): {own}; floor {1e6 * f['floor_seconds']:.3g} us against exact f0's "
                     f"{1e6 * f['exact_f0_seconds']:.3g} us under FMPy: no rung can go below "
                     f"{f['lowest_reachable_ratio']:.3g} x exact f0 there")
    return lines


def _readable_log_ticks(axis) -> None:
    """A log axis labelled at 1, 2, 5 x 10^k in plain numbers ("0.2", "5", "2e+04"), unlabelled minor ticks: the
    default labels every minor tick of a short axis as "2 x 10^0", "3 x 10^0", ..., which run into each other."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    low, high = axis.get_view_interval()
    decades = math.log10(high / low) if low > 0 and high > low else 1.0
    axis.set_major_locator(LogLocator(subs=(1.0,) if decades > 2.5 else (1.0, 2.0, 5.0) if decades > 1 else
                                      (1.0, 1.5, 2.0, 3.0, 5.0, 7.0)))
    axis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    axis.set_minor_formatter(NullFormatter())


def plot_ladder(path: Path, ladder: dict) -> None:
    """Error of x against cost per output, one marker per rung: the time columns in the top row; below, the
    instruction counts per interval (when measured) and the ratios to exact f0 that the acceptance reads."""
    from vibrofmu.output import export

    plt = export.plt
    columns = [(c["host"], c["interval"]) for c in ladder["rungs"][0]["columns"]]
    info = ladder.get("instructions") or {}
    intervals = info.get("intervals", []) if info.get("measured") else []
    ncols = max(len(columns), len(intervals) + 1)
    fig, axes = plt.subplots(2, ncols, figsize=(5.6 * ncols, 9.5), squeeze=False)
    markers = "osD^vP*X"
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    def panel(ax, points, xlabel, title):
        for k, (rung, x, y) in enumerate(points):
            ax.loglog(x, max(y, 1e-17), markers[k % len(markers)], ms=9, color=colours[k % len(colours)], label=rung)
            # labels above right; the second rung's (f1) below right: f0 and f1 share their error and nearly their cost
            ax.annotate(rung, (x, max(y, 1e-17)), textcoords="offset points", xytext=(7, -12 if k == 1 else 4),
                        fontsize=8)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("max |x - x_ref| on the output grid")
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        lo, hi = ax.get_xlim()
        ax.set_xlim(lo, hi * 4)  # room for the labels right of the markers
        _readable_log_ticks(ax.xaxis)

    for ax, (host, interval) in zip(axes[0], columns):
        points = []
        for rung in ladder["rungs"]:
            c = next(c for c in rung["columns"] if (c["host"], c["interval"]) == (host, interval))
            points.append((rung["rung"], 1e6 * c["cpu_per_output_seconds"], c["linf_x"]))
        panel(ax, points, "cost per output: doStep + getReal(x) [us thread CPU], best of the rounds",
              f"time: {host}, output interval {interval:g}")
    for ax in axes[0][len(columns):]:
        ax.axis("off")
    for ax, interval in zip(axes[1], intervals):
        points = []
        for rung in ladder["rungs"]:
            c = next(c for c in rung["instructions"] if c["interval"] == interval)
            error = next(col["linf_x"] for col in rung["columns"] if (col["host"], col["interval"]) == ("C host", interval))
            points.append((rung["rung"], c["instructions_per_output"], error))  # the timed C host run's error
        panel(ax, points, "instructions per output: doStep + getReal(x) (callgrind)",
              f"instructions: C host under valgrind, output interval {interval:g}")
    ratio_ax = axes[1][len(intervals)]
    names = [a["rung"] for a in ladder["acceptance"] if (a["host"], a["interval"]) == ("C host", 0.1)]

    def ratios(rows, keep):
        by_rung = {a["rung"]: a["ratio"] for a in rows if keep(a)}
        return [by_rung.get(n) for n in names]

    series = [(f"{h}, interval {i:g} (CPU time, median of rounds)",
               ratios(ladder["acceptance"], lambda a, h=h, i=i: (a["host"], a["interval"]) == (h, i)))
              for h, i in dict.fromkeys((a["host"], a["interval"]) for a in ladder["acceptance"])]
    series += [(f"instructions, interval {i:g}",
                ratios(ladder.get("acceptance_instructions", []), lambda a, i=i: a["interval"] == i)) for i in intervals]
    width = 0.8 / max(len(series), 1)
    for k, (label, values) in enumerate(series):
        if None not in values:
            ratio_ax.bar([j + (k - (len(series) - 1) / 2) * width for j in range(len(names))], values, width,
                         label=label)
    ratio_ax.scatter(range(len(names)), [LIMITS[n] for n in names], marker="_", s=900, color="k", zorder=3,
                     label="acceptance limit")
    for floor in ladder.get("fmpy_floor", []):  # no rung's FMPy ratio can go below it (FLOOR_NOTE)
        ratio_ax.axhline(floor["lowest_reachable_ratio"], color="0.4", ls="--", lw=1,
                         label=f"FMPy, interval {floor['interval']:g}: lowest reachable ratio (FMPy's own cost)")
    ratio_ax.set_yscale("log")
    shown = [v for _, values in series if None not in values for v in values if v and v > 0]
    shown += [LIMITS[n] for n in names] + [f["lowest_reachable_ratio"] for f in ladder.get("fmpy_floor", [])]
    shown = [v for v in shown if v > 0]  # a log axis: a stand-in's zero floor cannot be shown
    if shown:  # the bars, the limits and the floors, with a margin; the legend sits below the axes, not above
        ratio_ax.set_ylim(min(shown) / 1.5, max(shown) * 1.5)
    _readable_log_ticks(ratio_ax.yaxis)
    ratio_ax.set_xticks(range(len(names)), names, fontsize=8)
    ratio_ax.set_ylabel("cost per output / exact f0's")
    ratio_ax.set_title("ratios to exact f0 (the acceptance reads the CPU-time ones)", fontsize=10)
    ratio_ax.grid(True, axis="y", which="both", alpha=0.3)
    ratio_ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncols=1, frameon=False,
                    markerscale=0.5)  # the limit marker (s=900) would run into its text
    for ax in axes[1][len(intervals) + 1:]:
        ax.axis("off")
    fig.suptitle(f"Speed-accuracy ladder, paper example, $\\tau$ in [0, {ladder['stop_time']:g}], "
                 f"{ladder.get('rounds', ladder.get('repeats'))} interleaved rounds: pick a rung")
    fig.tight_layout()
    export.save_figure(fig, path, dpi=100, bbox_inches="tight")
