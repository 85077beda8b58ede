"""Cost per output of the closed-loop FMU against the plant FMU at fidelity 0 (target: closed loop <= 3 x plant),
side by side in one run: doStep + getReal(x) over tau in [0, STOP], paper example, best of REPEATS, at intervals
0.1 and 1, in the plain C host of the bench ladder (timing_host.c, `vibrofmu doctor`'s environment) and under FMPy.

    python -m vibrofmu.loopcost BUILD_DIR [--repeats 3] [--kernel 0|1] [--reference 0|1|2] [--clock wall|cpu]

BUILD_DIR holds HertzEAOscillator.fmu and HertzEAClosedLoop.fmu (vibrofmu.build). Both FMUs run with their
defaults (the closed loop's reference: --reference, default its own). Numbers on a shared machine are noisy; each
host and interval runs the two FMUs one after the other, so their ratio is the number to read. On a loaded
machine a long loop is preempted more often than a short one, which inflates the wall-time ratio; --clock cpu
builds the C host with the calling thread's CPU clock instead (CLOCK_THREAD_CPUTIME_ID: the fast path runs in
that thread) and times the FMPy loop with time.thread_time().
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from fmpy import extract

import subprocess

import time

from . import paths
from .ladder import FMU_SRC, TIMING_HOST_SOURCE, communication_points, compile_timing_host, fmpy_run, host_run
from .run import FmuInstance

STOP = 200.0
INTERVALS = (0.1, 1.0)
FMUS = {"plant f0": "HertzEAOscillator.fmu", "closed loop": "HertzEAClosedLoop.fmu"}


def compile_cpu_clock_host(out_dir: Path) -> Path:
    """The ladder's timing host with CLOCK_MONOTONIC replaced by the thread's CPU clock."""
    header = Path(out_dir) / "cpu_clock.h"
    header.write_text("#include <time.h>\n#undef CLOCK_MONOTONIC\n#define CLOCK_MONOTONIC CLOCK_THREAD_CPUTIME_ID\n")
    host = Path(out_dir) / "timing_host_cpu"
    cmd = [*paths.c_compiler(), "-O2", f"-I{FMU_SRC}", "-include", "time.h", "-include", str(header), "-o", str(host),
           str(TIMING_HOST_SOURCE), "-ldl", "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the timing host failed ({' '.join(cmd)}):\n{proc.stderr}")
    return host


def fmpy_cpu_run(fmu: Path, unzip_dir: str, start: dict, stop: float, step: float, repeats: int) -> dict:
    """The ladder's FMPy loop (ladder.fmpy_run) timed on this thread's CPU clock."""
    points = communication_points(stop, step)
    loops = []
    for _ in range(repeats):
        with FmuInstance(fmu, instance_name="loopcost", unzip_dir=unzip_dir) as instance:
            f = instance.fmu
            f.setupExperiment(startTime=0.0, stopTime=stop)
            f.enterInitializationMode()
            instance.set(start)
            f.exitInitializationMode()
            refs = instance.value_references(["x"])
            do_step, get_real = f.doStep, f.getReal
            started, t = time.thread_time(), 0.0
            for next_t in points:
                do_step(t, next_t - t)
                get_real(refs)
                t = next_t
            loops.append(time.thread_time() - started)
    return {"loop": loops, "outputs": len(points)}


def measure(build_dir: Path, repeats: int, kernel: int, reference: int | None,
            clock: str = "wall") -> list[tuple[str, float, float]]:
    """[(host and interval, plant's seconds per output, closed loop's)]."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        host = compile_cpu_clock_host(Path(tmp)) if clock == "cpu" else compile_timing_host(Path(tmp))
        unzipped = {name: extract(str(build_dir / file), unzipdir=str(Path(tmp) / name)) for name, file in FMUS.items()}
        start = {"plant f0": {"kernel": kernel},
                 "closed loop": {"kernel": kernel, **({} if reference is None else {"reference": reference})}}
        for interval in INTERVALS:
            for label, run in ((f"C host ({clock})", lambda name: host_run(host, Path(unzipped[name]), start[name], STOP,
                                                                interval, repeats)),
                               (f"FMPy ({clock})", lambda name: (fmpy_cpu_run if clock == "cpu" else fmpy_run)(
                                   build_dir / FMUS[name], unzipped[name], start[name], STOP, interval, repeats))):
                cost = {}
                for name in FMUS:
                    record = run(name)
                    cost[name] = min(record["loop"]) / record["outputs"]
                rows.append((f"{label}, interval {interval:g}", cost["plant f0"], cost["closed loop"]))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("build_dir", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--kernel", type=int, default=0, help="both FMUs' kernel parameter (0 compiled, 1 Python)")
    parser.add_argument("--reference", type=int, default=None, help="the closed loop's reference (0 OAFM, 1, 2)")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall", help="the C host's clock")
    args = parser.parse_args(argv)
    for what, plant, loop in measure(args.build_dir, args.repeats, args.kernel, args.reference, args.clock):
        print(f"{what:26s} plant f0 {plant * 1e6:8.2f} us  closed loop {loop * 1e6:9.2f} us  ratio {loop / plant:7.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
