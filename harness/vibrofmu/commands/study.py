"""`vibrofmu study KIND`: response map, basins or Monte Carlo on Dask (vibrofmu.study)."""
import sys

from vibrofmu.commands.common import FMU_HELP, Command, Unused, plant_fmu, scheduler_workers, writable_folder


def options(p):
    from vibrofmu.study.spec import KINDS

    p.add_argument("kind", choices=KINDS)
    p.add_argument("--out", required=True, help="output folder (results.parquet, summary.json, plots)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="scene parameter, or a setting of the kind (basins: sigma; monte-carlo: samples, seed); "
                        "repeatable (default: none)")
    p.add_argument("--spec", default=None,
                   help="TOML spec: [scene], [grid], [tolerances], [settings] (default: none, the kind's built-in spec)")
    p.add_argument("--scheduler", default=None,
                   help="address of an existing Dask scheduler (tcp://HOST:PORT; default: a local cluster)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: one per core)")
    p.add_argument("--resume", action="store_true", help="continue the study in --out; recompute nothing written")
    p.add_argument("--quick", action="store_true", help="a small version of the kind (under a minute on 2 cores)")
    p.add_argument("--engine", choices=["fmu", "core"], default=None,
                   help="fmu: the plant FMU under FMPy (default); core: the compiled kernel directly")
    p.add_argument("--fmu", default=None, help=FMU_HELP)


def run(args) -> int:
    from vibrofmu import study
    from vibrofmu.study.spec import SpecError

    # the checks every command makes, before the cluster starts: the output folder, a given FMU (the plant's);
    # the default one is build/'s, built there when missing (study.run: only for the fmu engine)
    writable_folder(args.out)
    if args.fmu is not None:
        plant_fmu(args.fmu)
    try:
        return study.run(args)
    except SpecError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2


def unused(args) -> list[Unused]:
    """--workers with --scheduler; --fmu with --engine core (a spec file's engine is checked by study.run)."""
    found = scheduler_workers(args)
    if args.engine == "core":
        found.append(Unused("fmu", "--engine core runs the compiled kernel, no FMU; leave it out"))
    return found


COMMAND = Command("study", "response map, basins or Monte Carlo on Dask; Parquet results, plots, and agreement "
                           "with the averaged prediction", options, run, unused)
