"""The `vibrofmu` command: build, simulate, closed-loop, oafm, stability, bench, demo, doctor, ssp, container,
report, study, continuation, diagram.

This module parses the command line and dispatches; each sub-command is one module of vibrofmu.commands that
exports COMMAND (name, help, options, run). `vibrofmu --help` stays fast: the command modules import only the
standard library at their top, and the options of a sub-command are only defined when that sub-command is on the
command line (make_parser). A user mistake ends with one line `error: ...` and exit code 2 (commands.common.run).
"""
from __future__ import annotations

import argparse
import importlib
import sys

# The standard library only at the top: the model and the commands' modules are imported inside main's try, so a
# Ctrl-C during start-up (those imports take ~0.5 s) ends with `error: interrupted` and 130, not a traceback.

COMMANDS = ("build", "simulate", "closed_loop", "oafm", "stability", "bench", "demo", "doctor", "ssp", "container",
            "report", "study", "continuation", "diagram")  # modules of vibrofmu.commands, in `vibrofmu --help`'s order


def commands():
    """The Command of every module in COMMANDS."""
    return [importlib.import_module(f"vibrofmu.commands.{module}").COMMAND for module in COMMANDS]


def make_parser(selected=None) -> argparse.ArgumentParser:
    """The parser; `selected` names the sub-commands whose options are defined (None: all). The options import
    the model (choices, defaults), so `vibrofmu --help` defines none."""
    from vibrofmu.commands.common import Parser

    parser = Parser(prog="vibrofmu", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"vibrofmu {version()}",
                        help="print the version of vibrofmu and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in commands():
        p = sub.add_parser(command.name, help=command.help, description=command.help)
        p.set_command(command)
        if selected is None or command.name in selected:
            command.options(p)
    return parser


def version() -> str:
    """The installed package's version (its metadata: pyproject.toml's version)."""
    from importlib import metadata

    try:
        return metadata.version("vibrofmu")
    except metadata.PackageNotFoundError:  # run from a checkout that pip never installed
        return "(not installed: no package metadata)"


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((arg for arg in argv if not arg.startswith("-")), None)
    try:
        from vibrofmu import interrupts
        from vibrofmu.commands.common import run

        try:
            args = make_parser({command}).parse_args(argv)  # (imports the command's modules: Ctrl-C may land here)
        except SystemExit as stop:  # --help (0) or a bad command line (2, one line printed by Parser.error)
            return stop.code
        with interrupts.install():  # counted: a host answers an FMU call failed by Ctrl-C with KeyboardInterrupt
            return run(args.func, args)
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130


def console() -> int:
    """The `vibrofmu` program (pyproject.toml's entry point): main, and after a Ctrl-C (130) an exit that skips the
    interpreter's teardown of its modules: with numpy, SciPy, FMPy and Matplotlib loaded that took 1.0-1.5 s on a
    loaded 2-core machine (0.05 s without it), past the 1 s a Ctrl-C is answered in. Everything a command cleans
    up has run by then (its finally blocks and context managers unwound with the KeyboardInterrupt), and the
    atexit handlers run (temporary folders, logging, multiprocessing's children); only the modules' own
    deallocation is skipped. Tests call main, which always returns."""
    code = main()
    if code == 130:
        import atexit
        import os

        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    return code


if __name__ == "__main__":
    sys.exit(console())
