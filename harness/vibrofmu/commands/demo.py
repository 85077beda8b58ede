"""`vibrofmu demo`: the paper's example, FMU beside the reference."""
from vibrofmu.commands.common import FMU_HELP, Command, built_plant, out_folder, plant_fmu


def options(p):
    p.add_argument("--out", default="out/demo", help="output folder (result.csv, summary.json, x.png)")
    p.add_argument("--fmu", default=None, help=FMU_HELP)


def run(args) -> int:
    from vibrofmu.analyses.demo import run_demo

    fmu = plant_fmu(args.fmu)
    out = out_folder(args.out)
    return run_demo(out, built_plant(fmu))


COMMAND = Command("demo", "simulate and compare on the paper's example (Omega = 2); builds the plant FMU when missing",
                  options, run)
