"""`vibrofmu doctor`: a C host with an empty environment runs an FMU as FMPy does; the Python environment file."""
import shlex
import sys
from pathlib import Path

from vibrofmu.commands.common import Command, UserError, checked_fmu


def options(p):
    p.add_argument("fmu", nargs="?", help="the FMU to check (not needed with --env-file)")
    p.add_argument("--env-file", help="write the file VIBROFMU_PYTHON_ENV names (the Python a pythonfmu FMU uses) "
                                      "instead of checking (default: check)")
    p.add_argument("--python", help="with --env-file: the Python to describe (default: this one)")


def run(args) -> int:
    import tempfile

    from vibrofmu.hosts import doctor

    if args.python is not None and not args.env_file:
        raise UserError(f"--python {args.python}: only with --env-file FILE (it names the Python to describe)")
    if args.env_file:
        python = args.python and checked_python(args.python)
        try:
            record = doctor.write_env_file(Path(args.env_file), python,
                                           checked_fmu(Path(args.fmu)) if args.fmu else None)
        except RuntimeError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        except OSError as error:  # the file cannot be written, or the Python cannot be run
            what = (f"cannot run --python {args.python}" if error.filename == python
                    else f"cannot write {error.filename or args.env_file}")
            print(f"error: {what}: {error.strerror or error}", file=sys.stderr)
            return 2
        print(f"wrote {args.env_file} (Python {record['python_version']} at {record['home']}); a C host uses it with")
        print(f"export {doctor.ENV_VARIABLE}={shlex.quote(str(Path(args.env_file).resolve()))}")
        return 0
    if not args.fmu:
        raise UserError("give an FMU to check, or --env-file FILE")
    fmu = checked_fmu(Path(args.fmu))
    with tempfile.TemporaryDirectory() as work_dir:
        env, result = doctor.check(fmu, Path(work_dir))
    print(doctor.export_lines(env))
    if not result.ok:
        print(f"error: {result.message}", file=sys.stderr)
        return 1
    print(f"# ok: {result.message}")
    return 0


def checked_python(given: str) -> str:
    """The program --python names (a path, or a name on $PATH), if it exists and can be run; UserError otherwise."""
    import os
    import shutil

    found = shutil.which(given)
    if found is None:
        path = Path(given)
        reason = ("no such file" if not path.exists() else "is a folder" if path.is_dir()
                  else "not executable" if not os.access(path, os.X_OK) else "cannot be run")
        raise UserError(f"--python {given}: {reason} (give a Python interpreter, e.g. --python /usr/bin/python3)")
    return found


COMMAND = Command("doctor", "check that a C host started with an empty environment runs an FMU as FMPy does; "
                            "--env-file: write the Python environment file for another machine or Python", options, run)
