"""Instructions per output of the native plant FMU and of numbalsoda, at equal accuracy: the deterministic twin of
`vibrofmu bench --peers` (whose timings vary with the machine's load).

On the peers' scenes (speed.peers.SCENES: paper and contact loss, tau in [0, 200], 2,000 outputs) at each rtol:
- the native plant FMU in the ladder's C timing host (doStep + getReal(x), speed.ladder.callgrind_counts), with the
  default max_step (the drive's ceiling) and with max_step = 1000 (none);
- numbalsoda's DOP853 and LSODA (its compiled libraries) on a C right-hand side equal to speed.peers.accel, the
  function numba compiles for the bench (numbalsoda_driver.c): the count is the solver and the right-hand side of a
  run, nothing of Python or numba's dispatch;
each under valgrind's callgrind, with the error max|x - x_ref| on the output grid against the bench's reference. A
row's verdict: the cheapest setting of each contender that reaches the error (<= 1e-6, <= 1e-9), ours over the best
peer's. Needs valgrind, numbalsoda and a built plant FMU.

    python -m vibrofmu.speed.peer_instructions [--fmu build/HertzEAOscillator.fmu] [--rtol 1e-4 --rtol 1e-6 ...]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from vibromodel.integrate import ATOL_PER_RTOL
from vibromodel.plant import Settings

from vibrofmu.analyses.reference import reference_solution
from vibrofmu.analyses.simulate import start_values
from vibrofmu.fmus import toolchain
from vibrofmu.speed.ladder import callgrind_counts, compile_timing_host, host_command, parse_host_output
from vibrofmu.speed.peers import INTERVAL, NO_CEILING, REFERENCE_RTOL, SCENES, STOP, THRESHOLDS, grid, parameters

DRIVER_SOURCE = Path(__file__).with_name("numbalsoda_driver.c")
RTOLS = tuple(10.0 ** -k for k in range(4, 12))
NUMBALSODA = {"numbalsoda DOP853": ("libdop853.so", "dop853_wrapper"), "numbalsoda LSODA": ("liblsoda.so", "lsoda_wrapper")}
OURS = {"native FMU, C host": 0.0, "native FMU, C host, no drive ceiling": NO_CEILING}


def native_counts(fmu: Path, work: Path, rtols) -> dict:
    """{(scene, contender, rtol): (instructions per output, error)} of the native plant FMU built from `fmu`."""
    from fmpy import extract

    from vibrofmu.fmus.native import build_native

    native = build_native(fmu, work / "native", win64=False, reference=False)
    unzipped = Path(extract(str(native), unzipdir=str(work / "native-unzipped")))
    host = compile_timing_host(work)
    found = {}
    for name, scene in SCENES.items():
        x_ref = _reference(scene)
        keys, specs = [], []
        for contender, max_step in OURS.items():
            for rtol in rtols:
                start = start_values(scene, Settings(rtol=rtol, max_step=max_step))
                start = {k: v for k, v in start.items() if k not in ("oafm_order", "tau_star", "oafm_tau_end")}
                keys.append((name, contender, rtol))
                specs.append((start, INTERVAL))
        cmd, env = host_command(host, unzipped, specs, STOP, 1)
        counts, proc = callgrind_counts(cmd, env, len(specs))
        for key, count, record in zip(keys, counts, parse_host_output(proc.stdout, len(specs))):
            x = np.concatenate([[scene.x_start], record["x"]])
            found[key] = (count / record["outputs"], float(np.max(np.abs(x - x_ref))))
    return found


def numbalsoda_counts(work: Path, rtols) -> dict:
    """{(scene, contender, rtol): (instructions per output, error)} of numbalsoda's DOP853 and LSODA."""
    import numbalsoda

    folder = Path(numbalsoda.__file__).parent
    driver = work / "numbalsoda_driver"
    subprocess.run([*toolchain.c_compiler(), "-O2", "-o", str(driver), str(DRIVER_SOURCE), "-ldl", "-lm"], check=True)
    found = {}
    for name, scene in SCENES.items():
        x_ref = _reference(scene)
        for contender, (library, symbol) in NUMBALSODA.items():
            cmd = [str(driver), str(folder / library), symbol, repr(scene.x_start), repr(scene.v_start),
                   *map(repr, parameters(scene).tolist()), repr(STOP), repr(INTERVAL), *map(repr, rtols)]
            counts, proc = callgrind_counts(cmd, dict(os.environ), len(rtols), collect=("nb_run",),
                                            dump_after="nb_done")
            runs = [line.split() for line in proc.stdout.splitlines() if line.startswith("run ")]
            for rtol, count, run in zip(rtols, counts, runs):
                x = np.array([float(v) for v in run[4:]])
                error = float(np.max(np.abs(x - x_ref))) if run[3] == "1" else float("nan")
                found[name, contender, rtol] = (count / (len(x) - 1), error)
    return found


def _reference(scene) -> np.ndarray:
    return reference_solution(scene, 0, STOP, rtol=REFERENCE_RTOL, atol=ATOL_PER_RTOL * REFERENCE_RTOL)(grid())[0]


def verdict_lines(found: dict) -> list[str]:
    """Per scene and error level: each contender's cheapest setting reaching it, ours over the best peer's."""
    lines = []
    contenders = sorted({c for _, c, _ in found})
    for name in SCENES:
        for threshold in THRESHOLDS:
            best = {}
            for contender in contenders:
                within = [(count, rtol) for (s, c, rtol), (count, error) in found.items()
                          if s == name and c == contender and error <= threshold]
                if within:
                    best[contender] = min(within)
            peers = {c: b for c, b in best.items() if c in NUMBALSODA}
            if not peers:
                lines.append(f"{name} scene, error <= {threshold:g}: no peer reached it")
                continue
            peer = min(peers, key=lambda c: peers[c][0])
            shown = ", ".join(f"{c} {count:.0f} (rtol {rtol:g})" for c, (count, rtol) in sorted(best.items(),
                                                                                          key=lambda i: i[1]))
            lines.append(f"{name} scene, error <= {threshold:g} (instructions per output, cheapest rtol): {shown}")
            for ours in OURS:
                if ours in best:
                    lines.append(f"  {ours} / best peer ({peer}): {best[ours][0] / peers[peer][0]:.2f}x")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m vibrofmu.speed.peer_instructions",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmu", type=Path, default=Path("build/HertzEAOscillator.fmu"), help="the plant FMU")
    parser.add_argument("--rtol", type=float, action="append", help="rtol (repeatable; default 1e-4 ... 1e-11)")
    args = parser.parse_args(argv)
    if not args.fmu.is_file():
        print(f"error: {args.fmu} not found (run `vibrofmu build`)", file=sys.stderr)
        return 2
    rtols = tuple(args.rtol or RTOLS)
    with tempfile.TemporaryDirectory(prefix="vibrofmu-peer-instr-") as work:
        found = {**native_counts(args.fmu, Path(work), rtols), **numbalsoda_counts(Path(work), rtols)}
    for (name, contender, rtol), (count, error) in sorted(found.items()):
        print(f"{name:13s} {contender:38s} rtol {rtol:6g}: {count:7.0f} instructions per output, error {error:.2e}")
    print("\n".join(verdict_lines(found)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
