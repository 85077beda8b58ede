"""Cost per output of the closed-loop FMU against the plant FMU at fidelity 0 (target: closed loop <= 3 x plant),
side by side in one run: doStep + getReal(x) over tau in [0, STOP], paper example, best of REPEATS, at intervals
0.1 and 1, in the plain C host of the bench ladder (timing_host.c, `vibrofmu doctor`'s environment) and under FMPy.

    python -m vibrofmu.speed.loopcost BUILD_DIR [--repeats 3] [--kernel 0|1] [--reference 0|1|2] [--clock wall|cpu]

BUILD_DIR holds HertzEAOscillator.fmu and HertzEAClosedLoop.fmu (vibrofmu.fmus.build). Both FMUs run with their
defaults (the closed loop's reference: --reference, default its own). Numbers on a shared machine are noisy; each
host and interval runs the two FMUs one after the other, so their ratio is the number to read. On a loaded
machine a long loop is preempted more often than a short one, which inflates the wall-time ratio; --clock cpu
reads the calling thread's CPU time instead, which the ladder's runs record beside the wall time (timing_host.c:
CLOCK_THREAD_CPUTIME_ID, the fast path runs in that thread; FMPy: time.thread_time()).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from fmpy import extract

from vibrofmu.speed.ladder import compile_timing_host, fmpy_run, host_run

STOP = 200.0
INTERVALS = (0.1, 1.0)
FMUS = {"plant f0": "HertzEAOscillator.fmu", "closed loop": "HertzEAClosedLoop.fmu"}


def measure(build_dir: Path, repeats: int, kernel: int, reference: int | None,
            clock: str = "wall") -> list[tuple[str, float, float]]:
    """[(host and interval, plant's seconds per output, closed loop's)]."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        host = compile_timing_host(Path(tmp))
        unzipped = {name: extract(str(build_dir / file), unzipdir=str(Path(tmp) / name)) for name, file in FMUS.items()}
        start = {"plant f0": {"kernel": kernel},
                 "closed loop": {"kernel": kernel, **({} if reference is None else {"reference": reference})}}
        for interval in INTERVALS:
            for label, run in ((f"C host ({clock})", lambda name: host_run(host, Path(unzipped[name]), start[name], STOP,
                                                                interval, repeats)),
                               (f"FMPy ({clock})", lambda name: fmpy_run(build_dir / FMUS[name], unzipped[name],
                                                                         start[name], STOP, interval, repeats))):
                cost = {}
                for name in FMUS:
                    record = run(name)
                    cost[name] = min(record["cpu" if clock == "cpu" else "loop"]) / record["outputs"]
                rows.append((f"{label}, interval {interval:g}", cost["plant f0"], cost["closed loop"]))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("build_dir", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--kernel", type=int, default=0, help="both FMUs' kernel parameter (0 compiled, 1 Python)")
    parser.add_argument("--reference", type=int, default=None, help="the closed loop's reference (0 OAFM, 1, 2)")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall", help="the clock of both hosts' loops")
    args = parser.parse_args(argv)
    missing = [str(args.build_dir / file) for file in FMUS.values() if not (args.build_dir / file).is_file()]
    if missing:
        print(f"error: {', '.join(missing)} not found (run `vibrofmu build --out-dir {args.build_dir}`)", file=sys.stderr)
        return 2
    for what, plant, loop in measure(args.build_dir, args.repeats, args.kernel, args.reference, args.clock):
        print(f"{what:26s} plant f0 {plant * 1e6:8.2f} us  closed loop {loop * 1e6:9.2f} us  ratio {loop / plant:7.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
