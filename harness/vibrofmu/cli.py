"""The `vibrofmu` command: build, simulate, demo."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vibromodel.parameters import ParameterError, Scene
from vibromodel.plant import Settings

from .build import PLANT_FMU, build_plant
from .demo import run_demo
from .simulate import FIDELITIES, SOLVERS, simulate


def parse_set(items: list[str]) -> dict[str, float]:
    """NAME=VALUE pairs -> {name: float}; unknown names and non-numbers raise ParameterError."""
    values = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep:
            raise ParameterError(item, None, "expected NAME=VALUE")
        try:
            values[name.strip()] = float(text)
        except ValueError:
            raise ParameterError(name.strip(), text, "not a number") from None
    Scene().with_values(**values)  # unknown names fail here
    return values


def progress_printer(label: str):
    """Print progress every 10 % on stderr for long runs."""
    state = {"next": 10}

    def progress(done: int, total: int):
        if total >= 20000 and 100 * done >= state["next"] * total:
            print(f"{label}: {state['next']} %", file=sys.stderr, flush=True)
            state["next"] += 10

    return progress


def ensure_fmu(path: Path) -> Path:
    if not path.exists():
        print(f"building {path} ...", file=sys.stderr)
        build_plant(path.parent)
    return path


def cmd_build(args) -> int:
    fmu = build_plant(Path(args.out_dir))
    print(f"built {fmu}")
    return 0


def cmd_simulate(args) -> int:
    scene = Scene().with_values(**parse_set(args.set))
    settings = Settings(fidelity=FIDELITIES[args.fidelity], solver=SOLVERS[args.solver], rtol=args.rtol,
                        max_step=args.max_step)
    fmu = ensure_fmu(Path(args.fmu))
    run, summary, _ = simulate(fmu, scene, settings, args.stop_time, args.output_interval, Path(args.out),
                            compare=args.compare, progress=progress_printer("simulate"))
    print(f"wrote {args.out}/result.csv, summary.json, x.png ({len(run.time)} points, "
          f"wall time {run.wall_time:.3f} s)")
    if "error" in summary:
        e = summary["error"]
        print(f"max |x - x_ref| = {e['max_abs_error_x']:.3e}, RMS = {e['rms_error_x']:.3e}; "
              f"max |v - v_ref| = {e['max_abs_error_v']:.3e}")
    if not run.completed:
        print(f"error: the FMU stopped at tau = {run.end_time:g} before the stop time {args.stop_time:g}: "
              f"{run.stop_reason}", file=sys.stderr)
        return 1
    return 0


def cmd_demo(args) -> int:
    return run_demo(Path(args.out))


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vibrofmu", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("build", help="build build/HertzEAOscillator.fmu")
    p.add_argument("--out-dir", default=str(PLANT_FMU.parent))
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("simulate", help="run the plant FMU under FMPy and export the results")
    p.add_argument("--fidelity", choices=list(FIDELITIES), default="exact")
    p.add_argument("--solver", choices=list(SOLVERS), default="adaptive")
    p.add_argument("--rtol", type=float, default=1e-8)
    p.add_argument("--max-step", type=float, default=0.0, help="RK4 step / adaptive ceiling; 0 = automatic")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="scene parameter (mu, Delta, omega, Omega, alpha, beta, gamma, R, x_start, v_start)")
    p.add_argument("--stop-time", type=float, default=200.0)
    p.add_argument("--output-interval", type=float, default=0.1)
    p.add_argument("--compare", action="store_true", help="compare with the DOP853 rtol 1e-12 reference")
    p.add_argument("--fmu", default=str(PLANT_FMU))
    p.add_argument("--out", required=True)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("demo", help="build + simulate + compare on the paper's example (Omega = 2)")
    p.add_argument("--out", default="out/demo")
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv=None) -> int:
    args = make_parser().parse_args(argv)
    try:
        return args.func(args)
    except ParameterError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
