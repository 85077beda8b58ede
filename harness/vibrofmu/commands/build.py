"""`vibrofmu build`: the three pythonfmu FMUs and their native twins."""
from vibrofmu.commands.common import Command, out_folder, say_compiled_parts


def options(p):
    p.add_argument("--out-dir", default="build", help="folder the FMUs are written to")
    p.add_argument("--no-win64", action="store_true",
                   help="leave out the native FMUs' win64 binaries even where mingw-w64 is installed "
                        "(a quicker build for Linux hosts: half the compiling)")


def run(args) -> int:
    from vibrofmu.fmus.build import build_all

    folder = out_folder(args.out_dir)  # the user's arguments checked before any warning
    say_compiled_parts(natives=not args.no_win64)
    for fmu in build_all(folder, win64=False if args.no_win64 else None):
        print(f"built {fmu}")
    return 0


COMMAND = Command("build", "build the plant, controller and closed-loop FMUs into ./build", options, run)
