"""`vibrofmu ssp`: the shipped co-simulation scenes as SSP files, optionally checked with FMPy's simulate_ssp."""
import sys
from pathlib import Path

from vibrofmu import paths
from vibrofmu.commands.common import CONTROLLER_NAME, PLANT_NAME, Command, built_all


def options(p):
    p.add_argument("--fmu-dir", default=None, help="where the FMUs are (default: build/; built when missing)")
    p.add_argument("--out-dir", default=None, help="where to write the .ssp files (default: the FMU folder)")
    p.add_argument("--check", action="store_true",
                   help="also run each .ssp with FMPy's simulate_ssp and with the master (ordering fmpy) and "
                        "print max |difference| (default: off)")


def run(args) -> int:
    from dataclasses import replace

    from vibrofmu.hosts.cosim import SceneError, run_cosim
    from vibrofmu.hosts.ssp import load_ssp, max_difference, simulate_with_fmpy, write_scene_ssps

    fmu_dir = built_all(Path(args.fmu_dir or paths.build_dir()), (PLANT_NAME, CONTROLLER_NAME))
    scenes = sorted(paths.SCENES_DIR.glob("*.toml"))
    try:
        written = write_scene_ssps(scenes, fmu_dir, Path(args.out_dir or fmu_dir))
    except SceneError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    for path in written:
        print(f"wrote {path}")
        if args.check:
            ours = run_cosim(replace(load_ssp(path), ordering="fmpy"))
            theirs = simulate_with_fmpy(path)
            columns = [c for c in ours.outputs if c in theirs]
            worst = max(max_difference(theirs, ours.outputs, columns).values())
            print(f"  fmpy.ssp vs the master (ordering fmpy), {len(columns)} outputs at {len(ours.time)} points: "
                  f"max |difference| = {worst:.3g}")
    return 0


COMMAND = Command("ssp", "write the co-simulation scenes as SSP files (default: build/closed_loop.ssp)", options, run)
