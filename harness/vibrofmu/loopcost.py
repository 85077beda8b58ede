"""Cost per output of the closed-loop FMU against the plant FMU at fidelity 0 (issue 13: closed loop <= 3 x plant),
side by side in one run under FMPy: doStep + getReal(x) over tau in [0, STOP], best of REPEATS, at each interval.

    python -m vibrofmu.loopcost BUILD_DIR [--kernel 0|1] [--repeats 3]

BUILD_DIR holds HertzEAOscillator.fmu and HertzEAClosedLoop.fmu (vibrofmu.build). Prints one line per FMU and
interval and the ratios; numbers taken on a shared machine are noisy, the ratios less so (each pair runs
interleaved).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from .run import FmuInstance

STOP = 200.0
INTERVALS = (0.1, 1.0)
FMUS = {"plant f0": "HertzEAOscillator.fmu", "closed loop": "HertzEAClosedLoop.fmu"}


def cost_per_output(fmu_path: Path, interval: float, parameters: dict) -> tuple[float, int]:
    """(seconds per doStep + getReal(x) over [0, STOP], fast-path steps) of one run."""
    with FmuInstance(fmu_path, "cost") as instance:
        fmu = instance.fmu
        fmu.setupExperiment(startTime=0.0, stopTime=STOP)
        fmu.enterInitializationMode()
        instance.set(parameters)
        fmu.exitInitializationMode()
        x = instance.value_references(["x"])
        n = round(STOP / interval)
        do_step, get_real = fmu.doStep, fmu.getReal
        start = time.perf_counter()
        for i in range(n):
            do_step(i * interval, interval)
            get_real(x)
        elapsed = time.perf_counter() - start
        return elapsed / n, instance.fast_path_steps()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("build_dir", type=Path)
    parser.add_argument("--kernel", type=int, default=0, help="the FMUs' kernel parameter (0 compiled, 1 Python)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    for interval in INTERVALS:
        best = {}
        for _ in range(args.repeats):
            for name, file in FMUS.items():
                cost, fast = cost_per_output(args.build_dir / file, interval, {"kernel": args.kernel})
                if name not in best or cost < best[name][0]:
                    best[name] = (cost, fast)
        for name, (cost, fast) in best.items():
            print(f"FMPy interval {interval:g}: {name:12s} {cost * 1e6:9.2f} us per output (fast-path steps {fast})")
        ratio = best["closed loop"][0] / best["plant f0"][0]
        print(f"FMPy interval {interval:g}: closed loop / plant f0 = {ratio:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
