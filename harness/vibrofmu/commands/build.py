"""`vibrofmu build`: the three pythonfmu FMUs and their native twins."""
from vibrofmu.commands.common import Command, out_folder, say_compiled_parts


def options(p):
    p.add_argument("--out-dir", default="build", help="folder the FMUs are written to")


def run(args) -> int:
    from vibrofmu.fmus.build import build_all

    folder = out_folder(args.out_dir)  # the user's arguments checked before any warning
    say_compiled_parts(natives=True)
    for fmu in build_all(folder):
        print(f"built {fmu}")
    return 0


COMMAND = Command("build", "build the plant, controller and closed-loop FMUs into ./build", options, run)
