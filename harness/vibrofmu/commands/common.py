"""What every sub-command shares: the Command record each command module exports, the parser with one-line
errors, option types, checks of user-given files and folders, progress lines, and `run` (the error handling
of one command).

A user mistake (a bad option value, a missing or wrong file, an output folder that cannot be made) ends the
command with one line `error: ...` on stderr and exit code 2, before anything long runs; a run that stops
early (pull-in, a failing FMU) exits with 1. This module imports only the standard library, vibromodel's
parameters and vibrofmu.paths, so that `vibrofmu --help` stays fast: each command imports what it needs
(numpy, scipy, matplotlib, FMPy) when it runs.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable
from xml.etree import ElementTree

from vibromodel.parameters import ParameterError

from vibrofmu import paths
from vibrofmu.fmus.toolchain import NoCompiler, RegistryNotBuildable
from vibrofmu.paths import CLOSED_LOOP_NAME, CONTROLLER_NAME, PLANT_MODEL, PLANT_NAME  # noqa: F401 (re-exported)


@dataclass(frozen=True)
class Unused:
    """An option given on the command line that the run would not read: `dest` (its argparse dest), `why` (the
    option's values or the other options that make it unused, and what to do). `harmless`: ignoring it changes
    nothing the user asked for (a `warning:` line); otherwise the command stops with `error:` and exit code 2."""

    dest: str
    why: str
    harmless: bool = False
    shown: str | None = None  # how the message names it (default: the option and its value as given)


@dataclass(frozen=True)
class Command:
    """One sub-command: `name` on the command line, `help` its one-line description, `options(parser)` defines
    its options (called only when the command is on the command line), `run(args) -> exit code`;
    `unused(args) -> [Unused]`: the options the run would ignore given the others (checked by `run` for the
    options given on the command line only, before the command runs)."""

    name: str
    help: str
    options: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    unused: Callable[[argparse.Namespace], list[Unused]] | None = None


class UserError(Exception):
    """A mistake in the command line or its files: printed as one line, exit code 2."""


class HelpFormatter(argparse.HelpFormatter):
    """Appends "(default: X)" to an option's help unless the help already says its default or the option is
    a flag (off by default)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("default" in text or not action.option_strings or action.default is None or action.default is False
                or action.default == [] or action.default is argparse.SUPPRESS):
            return text
        return f"{text} (default: %(default)s)"


GIVEN = "_given"  # Namespace attribute: [(action, option string, value)] of every option on the command line
UNUSED = "_unused"  # Namespace attribute: the command's Command.unused (Parser.set_command)


def _recording(action_class):
    """`action_class` that also appends (itself, the option string typed, the value) to the namespace's GIVEN list:
    what the command line gave, as opposed to a default (argparse does not tell them apart)."""

    class Recording(action_class):
        def __call__(self, parser, namespace, values, option_string=None):
            if option_string is not None:  # (a positional with nargs="?" is called with its default too)
                vars(namespace).setdefault(GIVEN, []).append((self, option_string, values))
            super().__call__(parser, namespace, values, option_string)

    Recording.__name__ = action_class.__name__
    return Recording


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit code 2) and HelpFormatter; sub-commands use the same class. Every
    option records that it was given (GIVEN), for check_given."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        for name, action in (("store", argparse._StoreAction), (None, argparse._StoreAction),
                             ("store_const", argparse._StoreConstAction), ("store_true", argparse._StoreTrueAction),
                             ("store_false", argparse._StoreFalseAction), ("append", argparse._AppendAction)):
            self.register("action", name, _recording(action))

    def error(self, message):
        self.exit(2, f"error: {self.prog}: {message} (see {self.prog} --help)\n")

    def set_command(self, command: "Command") -> None:
        """This parser runs `command`: its run (func) and its unused options' rule."""
        self.set_defaults(func=command.run, **{UNUSED: command.unused})


def _shown(value) -> str:
    """An option's value as the command line gave it (after its type: 1e-06, [0.9, 1.1, 11.0] -> 0.9 1.1 11)."""
    if isinstance(value, (list, tuple)):
        return " ".join(_shown(v) for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def check_given(args: argparse.Namespace) -> None:
    """Refuse (UserError) an option the run would ignore: given twice (the last value wins in argparse), a --set
    NAME given twice, or one the command's `unused` rule names; print a `warning:` line for a harmless one."""
    given = getattr(args, GIVEN, None) or []
    first: dict[str, tuple[str, object]] = {}
    for action, option, value in given:
        if isinstance(action, argparse._AppendAction) or action.nargs == 0:  # repeatable, or a flag said twice
            continue
        if action.dest in first:
            raise UserError(f"{option} given twice ({_shown(first[action.dest][1])}, then {_shown(value)}): only "
                            f"the last would be used; give it once")
        first[action.dest] = (option, value)
    names: dict[str, str] = {}
    for action, _, item in given:
        if action.dest == "set" and isinstance(item, str):
            name = item.partition("=")[0].strip()
            if name in names:
                raise UserError(f"--set {name} given twice ({names[name]}, then {item}): only the last would be "
                                f"used; give each name once")
            names[name] = item
    rule = getattr(args, UNUSED, None)
    if rule is None or not given:
        return
    options = {action.dest: (option, value, action.nargs == 0) for action, option, value in given}
    for unused in rule(args):
        if unused.dest not in options:
            continue
        option, value, flag = options[unused.dest]
        shown = unused.shown or (option if flag else f"{option} {_shown(value)}")
        if unused.harmless:
            print(f"warning: {shown}: {unused.why}", file=sys.stderr)
        else:
            raise UserError(f"{shown}: {unused.why}")


def run(command: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run one command: a user mistake is one line `error: ...` and exit code 2 (an option the run would ignore
    included: check_given). Ctrl-C is not caught here: it stops the whole `vibrofmu` process (cli.main answers
    it), also when one command runs another (invoke). An output folder the command created (out_folder) and left
    empty is removed when the command fails."""
    created = len(_CREATED)
    code = 2
    try:
        check_given(args)
        code = command(args)
        return code
    except (UserError, ParameterError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except NoCompiler as error:
        print(f"error: {error} (set $CC or install gcc)", file=sys.stderr)
        return 2
    except RegistryNotBuildable as error:  # the tree's fidelity registry and core/fidelity.h: what is missing
        print(f"error: {error}", file=sys.stderr)
        return 2
    except Exception as error:
        from vibrofmu.hosts.run import FmuUnusable  # (fmpy: imported only when something failed)

        if not isinstance(error, FmuUnusable):
            raise
        print(f"error: {error}", file=sys.stderr)  # an FMU that cannot serve: which and why, one line
        return 1
    finally:
        if code != 0:
            _remove_empty(_CREATED[created:])
        del _CREATED[created:]


_CREATED: list[Path] = []  # folders out_folder created in this process (innermost last), for run's clean-up


def _remove_empty(folders: list[Path]) -> None:
    """Remove each of `folders` (and the parents created with it) that is still empty."""
    for folder in reversed(folders):
        try:
            folder.rmdir()  # only an empty folder goes
        except OSError:
            pass


def invoke(command: Command, argv: list[str]) -> int:
    """Parse `argv` as the options of `command` and run it (another command's use of a command, e.g. report)."""
    parser = Parser(prog=f"vibrofmu {command.name}")
    command.options(parser)
    parser.set_command(command)
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:
        return stop.code
    return run(command.run, args)


# -- option types: each rejects a bad value with a one-line reason ------------------------------------------
def _number(kind, test, condition):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f"must be {condition}, got {text}")
        return value

    parse.__name__ = kind.__name__
    return parse


positive = _number(float, lambda v: v > 0, "a finite number > 0")
non_negative = _number(float, lambda v: v >= 0, "a finite number >= 0")
count = _number(int, lambda v: v >= 1, "an integer >= 1")
non_negative_int = _number(int, lambda v: v >= 0, "an integer >= 0")

FMU_HELP = f"plant FMU (default: ./build/{PLANT_NAME}, built when missing)"
SET_HELP = ("scene parameter, repeatable: mu, Delta, omega, Omega, alpha, beta, gamma, R, x_start, v_start "
            "(default: the paper's example)")
# FMU settings of fidelity 4 (the OAFM fit) that the FMU's messages name: `simulate --set` takes them too
OAFM_SETTINGS = {"oafm_order": "order", "tau_star": "tau_star", "oafm_tau_end": "tau_end"}
SIMULATE_SET_HELP = (SET_HELP[:-len(" (default: the paper's example)")] + "; or an OAFM setting of fidelity "
                     "analytic: " + ", ".join(OAFM_SETTINGS) + " (default: the paper's example, automatic fit)")


# -- checks of user-given paths --------------------------------------------------------------------------
def study_fmu_options(p: argparse.ArgumentParser, fmu_use: str, no_fmu_help: str, out_help: str) -> None:
    """The options a study that checks itself on the plant FMU ends with: --fmu (FMU_HELP + fmu_use), --no-fmu,
    --set (SET_HELP), --out (required)."""
    p.add_argument("--fmu", default=None, help=FMU_HELP + fmu_use)
    p.add_argument("--no-fmu", action="store_true", help=no_fmu_help)
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help=SET_HELP)
    p.add_argument("--out", required=True, help=out_help)


def checked_fmu(path: Path, model: str | None = None, fmi2_cs: bool = False) -> Path:
    """`path` if it is an FMU file (a zip archive with modelDescription.xml) of `model` (its modelName; None:
    any) and, with fmi2_cs, an FMI 2.0 co-simulation FMU (what the harness's FMPy runs drive); UserError
    otherwise."""
    if not path.exists():
        raise UserError(f"no FMU at {path}")
    if not path.is_file():
        raise UserError(f"{path} is not a file (an FMU is a .fmu file)")
    try:
        with zipfile.ZipFile(path) as archive:
            root = ElementTree.fromstring(archive.read("modelDescription.xml"))
    except (zipfile.BadZipFile, KeyError, ElementTree.ParseError):
        raise UserError(f"{path} is not an FMU (no zip archive with a modelDescription.xml)") from None
    except OSError as error:
        raise UserError(f"cannot read {path}: {error.strerror}") from None
    name = root.get("modelName")
    if model is not None and name != model:
        raise UserError(f"{path} is the FMU of {name}; this command needs {model}")
    if fmi2_cs and (root.get("fmiVersion") != "2.0" or root.find("CoSimulation") is None):
        kind = f"an FMI {root.get('fmiVersion')} FMU" if root.get("fmiVersion") != "2.0" else "a Model Exchange FMU"
        raise UserError(f"{path} is {kind}; this command runs FMI 2.0 co-simulation FMUs (vibrofmu build writes "
                        "them to build/ and build/native/)")
    return path


def plant_fmu(given: str | None) -> Path:
    """The plant FMU the user named (checked now: it must exist and be the plant's), or the default
    ./build/HertzEAOscillator.fmu (built_plant builds it when missing, once the other checks passed)."""
    if given is not None:
        return checked_fmu(Path(given), PLANT_MODEL, fmi2_cs=True)
    return paths.build_dir() / PLANT_NAME


def built_plant(path: Path) -> Path:
    """`path` (from plant_fmu), built first when it is the missing default (or the default an interrupted build of
    an earlier version left half-done: archive.finished; or the default built from other sources: archive.current,
    so that what a command measures or runs is the checkout's model; an FMU the user named is used as it is)."""
    default = path.resolve() == (paths.build_dir() / PLANT_NAME).resolve()
    if not path.exists() or (default and not _current(path)):
        from vibrofmu.fmus.build import build_plant

        print(f"building {path} ...{_half_done(path)}", file=sys.stderr)
        say_compiled_parts()
        build_plant(path.parent)
    return checked_fmu(path, PLANT_MODEL, fmi2_cs=True)


def _current(path: Path) -> bool:
    from vibrofmu.fmus.archive import current

    return current(path)


def _half_done(path: Path) -> str:
    """The note of a default FMU rebuilt because the one there is incomplete or of other sources, or ""."""
    from vibrofmu.fmus.archive import finished

    if not path.exists() or _current(path):
        return ""
    if not finished(path):
        return f" ({path} is incomplete: an interrupted build)"
    return f" ({path} was built from other sources)"


def built_all(fmu_dir: Path, names=(PLANT_NAME, CONTROLLER_NAME, CLOSED_LOOP_NAME)) -> Path:
    """`fmu_dir`, after building the three FMUs into it when one of `names` is missing there, half-done or built from
    other sources (archive.current)."""
    if not all((fmu_dir / name).exists() and _current(fmu_dir / name) for name in names):
        from vibrofmu.fmus.build import build_all

        half = "".join(dict.fromkeys(_half_done(fmu_dir / name) for name in names))
        print(f"building the FMUs into {fmu_dir} ...{half}", file=sys.stderr)
        say_compiled_parts(natives=True)
        build_all(fmu_dir)
    return fmu_dir


def say_compiled_parts(natives: bool = False) -> None:
    """The line saying what the FMUs are built without, if anything; natives: also whether win64 is skipped."""
    from vibrofmu.fmus.build import compiled_parts, win64_skipped

    for line in (compiled_parts(), win64_skipped() if natives else None):
        if line:
            print(line, file=sys.stderr)


def writable_folder(path: str) -> Path:
    """`path` if the output folder exists or can be created there (nothing is created); UserError otherwise."""
    folder = Path(path)
    for parent in (folder, *folder.parents):
        if parent.exists():
            if parent == folder and not folder.is_dir():
                raise UserError(f"cannot use {folder} as the output folder: a file of that name exists")
            if not parent.is_dir():
                raise UserError(f"cannot create the output folder {folder}: {parent} is not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise UserError(f"cannot create the output folder {folder}: {parent} is not writable")
            break
    return folder


def out_folder(path: str) -> Path:
    """The output folder, created now (a folder that cannot be made is a UserError before anything runs)."""
    folder = Path(path)
    new = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise UserError(f"cannot use {folder} as the output folder: a file of that name exists") from None
    except OSError as error:
        raise UserError(f"cannot create the output folder {folder}: {error.strerror}") from None
    _CREATED.extend(reversed(new))  # outermost first
    return folder


def split_set(items: list[str]) -> tuple[dict[str, float], dict[str, float]]:
    """`simulate --set`: (scene values, OAFM settings {OafmSettings field: value}) of NAME=VALUE pairs whose name
    is a scene parameter or one of OAFM_SETTINGS."""
    scene = [item for item in items if item.partition("=")[0].strip() not in OAFM_SETTINGS]
    settings = parse_set([item for item in items if item not in scene], names=OAFM_SETTINGS)
    if "oafm_order" in settings and settings["oafm_order"] != int(settings["oafm_order"]):
        raise ParameterError("oafm_order", settings["oafm_order"], "must be an integer 1..8")
    return parse_set(scene), {OAFM_SETTINGS[name]: (int(value) if name == "oafm_order" else value)
                              for name, value in settings.items()}


def parse_set(items: list[str], names=None) -> dict[str, float]:
    """NAME=VALUE pairs -> {name: float}; a missing '=', unknown names and non-numbers raise UserError.
    `names`: the names allowed (None: the scene's parameters)."""
    from vibromodel.parameters import Scene

    values = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep:
            raise UserError(f"--set {item}: expected NAME=VALUE, e.g. --set R=2")
        try:
            values[name.strip()] = float(text)
        except ValueError:
            raise ParameterError(name.strip(), text, "not a number") from None
        if name.strip() in OAFM_SETTINGS and names is None:
            raise UserError(f"--set {item}: {name.strip()} is an FMU setting of fidelity analytic; "
                            "`vibrofmu simulate --fidelity analytic --set` takes it")
    if names is None:
        Scene().with_values(**values)  # unknown names fail here (ParameterError)
    return values


def scheduler_workers(args) -> list[Unused]:
    """--workers starts a local cluster; with --scheduler the scheduler's workers run (study, diagram)."""
    return [Unused("workers", f"--scheduler {args.scheduler} runs on that scheduler's workers; leave --workers "
                              "out")] if args.scheduler else []


def progress_printer(label: str):
    """Print progress every 10 % on stderr for long runs."""
    state = {"next": 10}

    def progress(done: int, total: int):
        if total >= 20000 and 100 * done >= state["next"] * total:
            print(f"{label}: {state['next']} %", file=sys.stderr, flush=True)
            state["next"] += 10

    return progress


def failed(check: dict | None, label: str) -> bool:
    """A check that could not run (an FMU stopped): say why on stderr."""
    if check and "error" in check:
        print(f"error: {label}: {check['error']}", file=sys.stderr)
        return True
    return False
