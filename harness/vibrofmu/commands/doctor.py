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

    if args.env_file:
        try:
            record = doctor.write_env_file(Path(args.env_file), args.python,
                                           checked_fmu(Path(args.fmu)) if args.fmu else None)
        except (RuntimeError, OSError) as error:
            print(f"error: {error}", file=sys.stderr)
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


COMMAND = Command("doctor", "check that a C host started with an empty environment runs an FMU as FMPy does; "
                            "--env-file: write the Python environment file for another machine or Python", options, run)
