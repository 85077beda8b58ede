"""Instructions per output of an FMU in the ladder's plain C host, counted by valgrind's callgrind.

Wall time on a shared machine varies by a factor ~1.6 between runs; the number of instructions executed is
deterministic. This module runs the ladder's C timing host (timing_host.c, one repeat) under
`valgrind --tool=callgrind` with collection switched on only inside its doStep and getReal calls, so the count is
the work of the output loop (doStep + getReal(x)) and nothing of instantiation or initialisation; divided by
the number of outputs it is the instruction cost per output.

    python -m vibrofmu.speed.instructions [--build DIR] [--stop 200] [--interval 0.1 --interval 1]

prints the ladder's rungs on the native FMUs of DIR/native (default build/native), plus the pythonfmu FMUs of
DIR where they run in the C host (--pythonfmu), plus the plant FMU of an older checkout's build folder
(--old-build OLD/build: the same rungs, where that FMU has them; "is exact f0 slower than before?"). Needs valgrind.
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from fmpy import extract

from vibrofmu.fmus import toolchain
from vibrofmu.speed.ladder import RUNGS, callgrind_counts, compile_timing_host, host_command, valgrind_missing

FMU_FILES = {"plant": "HertzEAOscillator.fmu", "closed_loop": "HertzEAClosedLoop.fmu"}


def count_instructions(fmu_unzip_dir, start_values: dict, stop: float, interval: float,
                       host: Path | None = None, environment: dict | None = None) -> float:
    """Instructions executed inside doStep + getReal(x) per output, for one run of the FMU unpacked in
    fmu_unzip_dir from 0 to stop at this output interval with these start values (names as in the ladder's
    RUNGS), in the ladder's C timing host under callgrind (ladder.callgrind_counts: the same count as the
    ladder's instruction column). host: a compiled timing host (default: compiled here); environment: variables set
    over the host's (legacy_environment() for an FMU built by an older checkout). Raises RuntimeError
    when valgrind is missing or the run fails."""
    missing = valgrind_missing()
    if missing:
        raise RuntimeError(missing)
    with tempfile.TemporaryDirectory(prefix="vibrofmu-instr-") as work:
        if host is None:
            host = compile_timing_host(Path(work))
        cmd, env = host_command(Path(host), Path(fmu_unzip_dir), [(start_values, interval)], stop, 1)
        (count,), proc = callgrind_counts(cmd, {**env, **(environment or {})}, 1)
    outputs = [int(line.split()[2]) for line in proc.stdout.splitlines() if line.startswith("loop ")]
    if not outputs:
        raise RuntimeError("no loop line from the timing host")
    return count / outputs[0]


# The kernel floor of exact f0: Plant.do_step in C (vk_run), without the FMI layer, for this tree's kernel or the
# single-file kernel of older ones (fmu_src/vibrokernel.c, commit f1a4d0f). The tree's own Python sets up the
# plant (CompiledPlant) and writes the plant structure's bytes (pointer-free in every version) into a file;
# the small C driver floor_driver.c loads them and runs vk_run under callgrind, so no Python is inside the count.
_FLOOR_SETUP = """
import ctypes, sys
from pathlib import Path
from vibrofmu.fmus.kernel import compile_kernel
from vibromodel.compiled import CompiledPlant, load_library
from vibromodel.parameters import Scene
from vibromodel.plant import Settings
out = Path(sys.argv[1])
compile_kernel(out / 'vibrokernel.so')
library, why = load_library([out])
assert library is not None, why
plant = CompiledPlant(Scene(), Settings(), library, 0.0)
(out / 'plant.bin').write_bytes(ctypes.string_at(plant.address, ctypes.sizeof(plant._plant)))
"""
FLOOR_DRIVER_SOURCE = Path(__file__).with_name("floor_driver.c")  # a C file, compiled with toolchain.HOST


def count_kernel_floor(tree: Path, python: Path, stop: float, interval: float) -> float:
    """Instructions per output inside vk_run (stop / interval do_steps of the paper example's exact f0 plant) for
    the kernel of the checkout `tree`, set up by `python` (that tree's environment)."""
    import os

    n = int(round(stop / interval))
    with tempfile.TemporaryDirectory(prefix="vibrofmu-floor-") as work:
        work = Path(work)
        env = {**os.environ, "PYTHONPATH": f"{Path(tree) / 'fmu_src'}{os.pathsep}{Path(tree) / 'harness'}"}
        subprocess.run([str(python), "-c", _FLOOR_SETUP, str(work)], check=True, env=env, cwd=tree)
        subprocess.run([*toolchain.c_compiler(), *toolchain.HOST, "-o", str(work / "driver"), str(FLOOR_DRIVER_SOURCE),
                        *toolchain.HOST_LIBS], check=True)
        out = work / "callgrind.out"
        proc = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", "--collect-atstart=no",
                               "--toggle-collect=vk_run", str(work / "driver"), str(work / "vibrokernel.so"),
                               str(work / "plant.bin"), repr(interval), str(n)], capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"kernel floor under callgrind failed: {proc.stderr.strip()[-800:]}")
        match = re.search(r"^(?:summary|totals):\s+(\d+)", out.read_text(), re.MULTILINE)
        return int(match.group(1)) / n


def legacy_environment() -> dict:
    """What a pythonfmu FMU built by a checkout before the drop-in FMUs (issue 14) needs in a C host: this Python's
    libpython loaded first, its home and its site-packages (that checkout's `vibrofmu doctor FMU` printed these)."""
    import sysconfig

    library = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")
    return {"LD_PRELOAD": str(library), "PYTHONHOME": sys.base_prefix, "PYTHONPATH": sysconfig.get_paths()["purelib"]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m vibrofmu.speed.instructions", description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", type=Path, default=Path("build"), help="folder with the built FMUs")
    parser.add_argument("--stop", type=float, default=200.0)
    parser.add_argument("--interval", type=float, action="append", help="output interval (repeatable)")
    parser.add_argument("--pythonfmu", action="store_true", help="also the pythonfmu FMUs (slow under valgrind)")
    parser.add_argument("--rung", action="append", help="only these rungs (names as in the ladder)")
    parser.add_argument("--old-build", type=Path, metavar="DIR", action="append",
                        help="also the plant FMU in DIR built by an older checkout (pythonfmu, run with "
                             "legacy_environment(); repeatable)")
    parser.add_argument("--floor", type=Path, metavar="TREE", action="append",
                        help="instead: exact f0's kernel floor (vk_run) of this checkout, with its .venv (repeatable)")
    args = parser.parse_args(argv)
    intervals = args.interval or [0.1, 1.0]
    if args.floor:
        print(f"{'kernel floor, exact f0':40s} " + " ".join(f"{'interval ' + format(i, 'g'):>16s}" for i in intervals))
        for tree in args.floor:
            counts = [count_kernel_floor(tree.resolve(), tree.resolve() / ".venv" / "bin" / "python", args.stop, i)
                      for i in intervals]
            print(f"{str(tree):40s} " + " ".join(f"{c:16.0f}" for c in counts), flush=True)
        return 0
    kinds = [("native", args.build / "native", None)] + ([("pythonfmu", args.build, None)] if args.pythonfmu else [])
    kinds += [(f"old {folder}", folder, legacy_environment()) for folder in args.old_build or []]
    with tempfile.TemporaryDirectory(prefix="vibrofmu-instr-") as work:
        host = compile_timing_host(Path(work))
        width = max(len(kind) for kind, _, _ in kinds)
        print(f"{'FMU':{width}s} {'rung':16s} " + " ".join(f"{'interval ' + format(i, 'g'):>16s}" for i in intervals))
        for number, (kind, folder, environment) in enumerate(kinds):
            unzipped = {}
            for name, start_values, which in [(n, s, w) for n, w, s in RUNGS]:
                if args.rung and name not in args.rung or environment is not None and which != "plant":
                    continue
                fmu = folder / FMU_FILES[which]
                if not fmu.is_file():
                    print(f"error: {fmu} not found (run `vibrofmu build`)", file=sys.stderr)
                    return 2
                if which not in unzipped:
                    unzipped[which] = extract(str(fmu), str(Path(work) / f"{number}-{which}"))
                try:
                    counts = [f"{count_instructions(unzipped[which], start_values, args.stop, i, host, environment):16.0f}"
                              for i in intervals]
                except RuntimeError as error:  # e.g. fidelities 3 and 4 need the pythonfmu FMU
                    counts = [f"{'n/a':>16s}"] * len(intervals)
                    print(f"{kind} {name}: {str(error)[:300]}", file=sys.stderr)
                print(f"{kind:{width}s} {name:16s} " + " ".join(counts), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
