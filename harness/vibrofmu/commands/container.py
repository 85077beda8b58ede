"""`vibrofmu container`: the closed loop as an FMPy container FMU, optionally compared per H."""
import math
import sys
from pathlib import Path

from vibrofmu import paths
from vibrofmu.commands.common import Command, built_all

CONTAINER_NAME = "HertzEAClosedLoopContainer"  # hosts.container.CONTAINER_NAME (this module stays light)
DEFAULT_STEP = 0.1
STOP_TIME = 200.0


def options(p):
    p.add_argument("--fmu-dir", default=None, help="where the FMUs are (default: build/; built when missing)")
    p.add_argument("--out-dir", default=None, help="where to write the container (default: the FMU folder)")
    p.add_argument("--H", type=float, default=DEFAULT_STEP, help=f"fixed communication step (default {DEFAULT_STEP})")
    p.add_argument("--compare", type=float, nargs="*", default=None, metavar="H",
                   help="compare with the monolithic FMU and the master at these H (default: no comparison; "
                        "no value: 0.1 0.05 0.01)")


def run(args) -> int:
    from vibrofmu.analyses.container_check import compare, table_lines
    from vibrofmu.hosts.container import build_container

    steps = tuple(args.compare or (0.1, 0.05, 0.01)) if args.compare is not None else ()
    for H in (args.H, *steps):
        if not (math.isfinite(H) and H > 0 and abs(STOP_TIME / H - round(STOP_TIME / H)) < 1e-9):
            print(f"error: H = {H!r} must be > 0 and divide the stop time {STOP_TIME:g}", file=sys.stderr)
            return 2
    fmu_dir = built_all(Path(args.fmu_dir or paths.build_dir()))
    out = build_container(fmu_dir, Path(args.out_dir or fmu_dir) / f"{CONTAINER_NAME}.fmu", args.H)
    print(f"wrote {out}")
    if steps:
        for line in table_lines(compare(fmu_dir, steps)):
            print(line)
    return 0


COMMAND = Command("container", "write the closed loop as an FMPy container FMU "
                               f"(default: build/{CONTAINER_NAME}.fmu)", options, run)
