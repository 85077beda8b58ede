"""`vibrofmu bench --peers`: the plant beside the ODE solvers a researcher would pick, at equal accuracy.

Contenders, each on the exact model (Eq. 3) of two scenes -- the paper's and a contact-loss scene (x_start = -1.3,
v_start = -0.8, R = 2: the mass leaves the contact and comes back) -- over tau in [0, 200] with 2,000 outputs:
- the native plant FMU in a plain C host (speed/timing_host.c; the doStep + getReal loop), and the Python API
  (vibrofmu.api.simulate asked for time, x and v, as the peers compute them: outputs=api.STATE), each with the
  drive's step ceiling (the default) and without it (max_step = 1000);
- numbalsoda's LSODA and DOP853 on a numba cfunc right-hand side; diffrax's Tsit5 and Dopri8 (JAX, jit, CPU, 64-bit);
  SUNDIALS CVODE, Adams (fixed-point) and BDF (Newton, dense), driven from C (speed/cvode_peer.c on the core's
  vm_accel: the FMU's own right-hand side) against the system's SUNDIALS; SciPy's solve_ivp (LSODA, RK45, DOP853);
- the pythonfmu plant FMU from Python: fmpy.simulate_fmu, and the cheapest FMPy path (hosts.fmpy_loop.FmpyLoop).
Each runs at rtol 1e-4 ... 1e-12 (atol = 1e-2 rtol, as everywhere here); the error is max |x - x_ref| on the output
grid against a DOP853 rtol 1e-13 reference with the contact located (analyses.reference). Every (contender, rtol)
runs once per round, the rounds interleaved (the contenders' order rotated each round); a setting's time is its
minimum over the rounds. A contender's cost at an error level is its cheapest setting that reaches it. One-off
costs (numba compilation, JAX tracing and compilation, compiling the C driver, building the native FMU) are timed
apart, never inside a run.

Then 1,000 short scenes (tau in [0, 20], 200 outputs, omega spread over [0.95, 1.05]): vibrofmu.api.simulate_many
in one call against a Python loop of numbalsoda LSODA calls, each at its cheapest setting for 1e-6 on the paper
scene (the API on its cheaper line: with the drive's ceiling or without).

The peers are an optional extra (`pip install -e '.[peers]'`; CVODE needs SUNDIALS >= 6 headers and libraries,
e.g. Debian's libsundials-dev); a missing one is named in one line and left out.
"""
from __future__ import annotations

import importlib.util
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from vibromodel.integrate import ATOL_PER_RTOL
from vibromodel.parameters import Scene
from vibromodel.plant import Settings

from vibrofmu import api, paths
from vibrofmu.analyses.reference import reference_solution
from vibrofmu.analyses.simulate import start_values
from vibrofmu.fmus import toolchain
from vibrofmu.speed import child

STOP, INTERVAL = 200.0, 0.1
SCENES = {"paper": Scene(), "contact loss": Scene(x_start=-1.3, v_start=-0.8, R=2.0)}
RTOLS = tuple(10.0 ** -k for k in range(4, 13))
QUICK_RTOLS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
THRESHOLDS = (1e-6, 1e-9)
REFERENCE_RTOL = 1e-13
ROUNDS = 3
NO_CEILING = 1000.0  # max_step: in effect no step ceiling (bench.NO_CEILING)
SHORT_SCENES, SHORT_STOP = 1000, 20.0
OURS = ("native FMU, C host", "Python API")
OWN = ("native FMU", "Python API", "pythonfmu FMU")  # the project's lines (not peers)  # the contenders the acceptance is about (with the default ceiling)
CVODE_SOURCE = Path(__file__).with_name("cvode_peer.c")
CVODE_LIBS = ("-lsundials_cvode", "-lsundials_nvecserial", "-lsundials_sunlinsoldense", "-lsundials_sunmatrixdense",
              "-lsundials_sunnonlinsolfixedpoint", "-lm")
PEER_PACKAGES = {"numbalsoda": ("numbalsoda", "numba"), "diffrax": ("diffrax", "jax")}


def parameters(scene: Scene) -> np.ndarray:
    """The exact model's constants as the peers' right-hand sides take them."""
    return np.array([scene.mu, scene.Delta, scene.omega, scene.Omega, scene.alpha, scene.beta, scene.gamma, scene.R])


def grid(stop: float = STOP) -> np.ndarray:
    return INTERVAL * np.arange(round(stop / INTERVAL) + 1)


def missing_peers() -> dict[str, str]:
    """{peer: what is missing} for the peers that cannot run here."""
    missing = {}
    for peer, modules in PEER_PACKAGES.items():
        absent = [m for m in modules if importlib.util.find_spec(m) is None]
        if absent:
            missing[peer] = f"no module {', '.join(absent)} (pip install -e '.[peers]')"
    if not Path("/usr/include/cvode/cvode.h").is_file() and not os.environ.get("SUNDIALS_DIR"):
        missing["CVODE"] = "no SUNDIALS headers (Debian: apt-get install libsundials-dev; or set SUNDIALS_DIR)"
    return missing


def accel(t, x, v, p):
    """x'' of the exact model (models.ExactModel.accel at U = 0) on the constants `parameters(scene)`: the peers'
    right-hand side (numba compiles this function; diffrax_contenders has its JAX twin)."""
    a = 1.0 - p[0] * v
    s = 1.0 + 2.0 * x / 3.0
    if s > 0.0:
        a -= s * math.sqrt(s)
    a += p[1] * math.cos(p[2] * t)
    u = 2.0 * x / (3.0 * p[7])
    f3 = 1.0 / ((1.0 - u) * (1.0 - u))
    return a + p[4] * (f3 - 1.0 / ((1.0 + u) * (1.0 + u))) + (p[5] * math.sin(p[3] * t)
                                                              + p[6] * (1.0 - math.cos(2.0 * p[3] * t))) * f3


# ---- the contenders: make(scene) -> run(rtol) -> x on the grid; each maker's own one-off cost is timed apart -------

def numbalsoda_contenders() -> dict:
    import numba
    from numbalsoda import dop853, lsoda, lsoda_sig

    compiled_accel = numba.njit(inline="always")(accel)

    @numba.cfunc(lsoda_sig)
    def rhs(t, u, du, p):
        du[0] = u[1]
        du[1] = compiled_accel(t, u[0], u[1], p)

    address = rhs.address
    y0, t, p = np.array([0.04, 0.0]), grid(1.0), parameters(Scene())
    lsoda(address, y0, t, data=p)  # the first calls load what numbalsoda compiles lazily
    dop853(address, y0, t, data=p)

    def maker(solve):
        def make(scene: Scene, stop: float = STOP):
            y0, t, p = np.array([scene.x_start, scene.v_start]), grid(stop), parameters(scene)

            def run(rtol):
                x, ok = solve(address, y0, t, data=p, rtol=rtol, atol=ATOL_PER_RTOL * rtol)
                return x[:, 0] if ok else None
            return run
        return make

    def lsoda_solve(address, y0, t, data, rtol, atol):
        return lsoda(address, y0, t, data=data, rtol=rtol, atol=atol, mxstep=1_000_000)

    return {"numbalsoda LSODA": maker(lsoda_solve), "numbalsoda DOP853": maker(dop853)}


def diffrax_contenders() -> dict:
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    import jax

    jax.config.update("jax_enable_x64", True)
    import diffrax
    import jax.numpy as jnp

    def field(t, y, p):
        x, v = y[0], y[1]
        s = 1.0 + 2.0 * x / 3.0
        a = 1.0 - p[0] * v - jnp.where(s > 0.0, s * jnp.sqrt(jnp.maximum(s, 0.0)), 0.0) + p[1] * jnp.cos(p[2] * t)
        u = 2.0 * x / (3.0 * p[7])
        f3 = 1.0 / ((1.0 - u) * (1.0 - u))
        a = a + p[4] * (f3 - 1.0 / ((1.0 + u) * (1.0 + u))) + (p[5] * jnp.sin(p[3] * t)
                                                               + p[6] * (1.0 - jnp.cos(2.0 * p[3] * t))) * f3
        return jnp.stack([v, a])

    term = diffrax.ODETerm(field)

    def maker(solver):
        solvers = {}

        def make(scene: Scene, stop: float = STOP):
            if stop not in solvers:  # one compilation per grid (rtol, atol, y0 and the parameters are traced)
                ts = jnp.asarray(grid(stop))

                @jax.jit
                def solve(y0, p, rtol, atol):
                    solution = diffrax.diffeqsolve(
                        term, solver, t0=0.0, t1=stop, dt0=None, y0=y0, args=p, saveat=diffrax.SaveAt(ts=ts),
                        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol), max_steps=2_000_000,
                        throw=False)
                    return solution.ys[:, 0], solution.result == diffrax.RESULTS.successful

                solvers[stop] = solve
                solve(jnp.array([scene.x_start, scene.v_start]), jnp.asarray(parameters(scene)), 1e-6,
                      1e-8)[0].block_until_ready()  # compile now: a one-off cost
            solve = solvers[stop]
            y0, p = jnp.array([scene.x_start, scene.v_start]), jnp.asarray(parameters(scene))

            def run(rtol):
                x, ok = solve(y0, p, rtol, ATOL_PER_RTOL * rtol)
                x = np.asarray(x.block_until_ready())
                return x if bool(ok) else None
            return run
        return make

    return {"diffrax Tsit5": maker(diffrax.Tsit5()), "diffrax Dopri8": maker(diffrax.Dopri8())}


def cvode_contenders(work: Path) -> dict:
    include = [f"-I{paths.FMU_SRC / 'core'}"]
    libs = list(CVODE_LIBS)
    if os.environ.get("SUNDIALS_DIR"):
        root = Path(os.environ["SUNDIALS_DIR"])
        include.append(f"-I{root / 'include'}")
        libs = [f"-L{root / 'lib'}", f"-Wl,-rpath,{root / 'lib'}", *libs]
    program = work / "cvode_peer"
    cmd = [*toolchain.c_compiler(), "-O2", *include, "-o", str(program), str(CVODE_SOURCE),
           str(paths.FMU_SRC / "core" / "model.c"), str(paths.FMU_SRC / "core" / "pyfloat.c"), *libs]
    proc = child.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling cvode_peer.c failed ({' '.join(cmd)}):\n{proc.stderr}")

    def maker(method):
        def make(scene: Scene, stop: float = STOP):
            values = [scene.mu, scene.Delta, scene.omega, scene.Omega, scene.alpha, scene.beta, scene.gamma, scene.R,
                      scene.x_start, scene.v_start]

            def run(rtol):
                proc = child.run([str(program), method, repr(rtol), repr(ATOL_PER_RTOL * rtol), repr(stop),
                                       repr(INTERVAL), "1", *map(repr, values)], capture_output=True, text=True)
                if proc.returncode != 0:
                    return None
                lines = proc.stdout.splitlines()
                run.seconds = float(lines[0].split()[1])  # the C driver's own clock (no process start)
                return np.array([scene.x_start] + [float(line.split()[2]) for line in lines[1:]])
            return run
        return make

    return {"CVODE Adams": maker("adams"), "CVODE BDF": maker("bdf")}


def scipy_contenders() -> dict:
    from scipy.integrate import solve_ivp

    from vibromodel.fidelities import Fidelity, make_model

    def maker(method):
        def make(scene: Scene, stop: float = STOP):
            accel = make_model(scene, Fidelity.EXACT).accel

            def f(t, y):
                return [y[1], accel(t, y[0], y[1], 0.0)]

            def run(rtol):
                solution = solve_ivp(f, (0.0, stop), [scene.x_start, scene.v_start], method=method, t_eval=grid(stop),
                                     rtol=rtol, atol=ATOL_PER_RTOL * rtol)
                return solution.y[0] if solution.success else None
            return run
        return make

    return {f"SciPy {method}": maker(method) for method in ("LSODA", "RK45", "DOP853")}


def api_contenders() -> dict:
    api.default_library()

    def maker(max_step):
        def make(scene: Scene, stop: float = STOP):
            def run(rtol):
                result = api.simulate(scene, stop, INTERVAL, Settings(rtol=rtol, max_step=max_step),
                                      outputs=api.STATE)  # x and v, as the peers compute them
                return result.x if not result.stopped else None
            return run
        return make

    return {"Python API": maker(0.0), "Python API, no drive ceiling": maker(NO_CEILING)}


def native_contenders(plant_fmu: Path, work: Path) -> dict:
    from fmpy import extract

    from vibrofmu.fmus.native import build_native
    from vibrofmu.speed.ladder import compile_timing_host, host_run

    native = build_native(plant_fmu, work / "native", win64=False, reference=False)
    unzipped = Path(extract(str(native), unzipdir=str(work / "native-unzipped")))
    host = compile_timing_host(work)

    def maker(max_step):
        def make(scene: Scene, stop: float = STOP):
            def run(rtol):
                start = start_values(scene, Settings(rtol=rtol, max_step=max_step))
                start = {k: v for k, v in start.items() if k not in ("oafm_order", "tau_star", "oafm_tau_end")}
                try:
                    record = host_run(host, unzipped, start, stop, INTERVAL, 1)
                except RuntimeError:
                    return None
                run.seconds = record["loop"][0]  # the host's own clock: the doStep + getReal loop
                return np.concatenate([[scene.x_start], record["x"]])
            return run
        return make

    return {"native FMU, C host": maker(0.0), "native FMU, C host, no drive ceiling": maker(NO_CEILING)}


def fmpy_contenders(plant_fmu: Path) -> dict:
    """The pythonfmu plant FMU from Python: FMPy's simulate_fmu, and the cheapest FMPy path (hosts.fmpy_loop: one
    extracted copy, one instance reset between runs, the FMI functions called directly)."""
    from fmpy import simulate_fmu

    from vibrofmu.hosts.fmpy_loop import FmpyLoop

    runner = FmpyLoop(plant_fmu)

    def start(scene, rtol):
        return {**scene.as_dict(), "rtol": rtol}

    def make_loop(scene: Scene, stop: float = STOP):
        def run(rtol):
            return np.concatenate([[scene.x_start], runner.run(start(scene, rtol), stop, INTERVAL)])
        return run

    def make_simulate(scene: Scene, stop: float = STOP):
        def run(rtol):
            result = simulate_fmu(str(plant_fmu), stop_time=stop, output_interval=INTERVAL,
                                  start_values=start(scene, rtol), output=["x"])
            return result["x"]
        return run

    return {"pythonfmu FMU, FMPy loop (one instance, reset)": make_loop,
            "pythonfmu FMU, fmpy.simulate_fmu": make_simulate}


# ---- the measurement ------------------------------------------------------------------------------------------

def timed(run, rtol):
    """(seconds, x): the run's own clock where it has one (C drivers), else the wall time around the call."""
    run.seconds = None
    started = time.perf_counter()
    x = run(rtol)
    elapsed = time.perf_counter() - started
    return (run.seconds if run.seconds is not None else elapsed), x


def gather(plant_fmu: Path, work: Path, say) -> tuple[dict, dict, dict]:
    """({contender: make}, {contender group: one-off seconds}, {peer: why missing})."""
    missing = missing_peers()
    makers, one_off = {}, {}
    groups = [("native FMU (build, C host compile)", lambda: native_contenders(plant_fmu, work)),
              ("Python API (kernel load)", api_contenders),
              ("numbalsoda (numba cfunc compile, first calls)", numbalsoda_contenders),
              ("diffrax (import)", diffrax_contenders),
              ("CVODE (compile the C driver)", lambda: cvode_contenders(work)),
              ("SciPy", scipy_contenders),
              ("pythonfmu FMU (extract, instantiate once)", lambda: fmpy_contenders(plant_fmu))]
    for name, factory in groups:
        peer = name.split(" ")[0]
        if peer in missing:  # numbalsoda, diffrax, CVODE
            continue
        started = time.perf_counter()
        try:
            makers.update(factory())
        except Exception as error:  # noqa: BLE001 - a peer that cannot start is reported, the others go on
            missing[peer] = f"{type(error).__name__}: {str(error).strip().splitlines()[0][:200]}"
            continue
        one_off[name] = time.perf_counter() - started
        say(f"peers: {name} ready ({one_off[name]:.2f} s)")
    return makers, one_off, missing


def work_precision(makers: dict, one_off: dict, rtols, rounds: int, say) -> dict:
    """{scene: {contender: {rtol: {"seconds": min over rounds, "rounds": [...], "error": max |x - x_ref|}}}}."""
    results = {}
    for scene_name, scene in SCENES.items():
        t = grid()
        reference = reference_solution(scene, 0, STOP, rtol=REFERENCE_RTOL, atol=ATOL_PER_RTOL * REFERENCE_RTOL)
        x_ref = reference(t)[0]
        runs = {}
        for name, make in makers.items():
            started = time.perf_counter()
            runs[name] = make(scene)  # diffrax compiles here, once per grid
            spent = time.perf_counter() - started
            if spent > 0.05:
                one_off[f"{name} (set-up on the grid: {scene_name})"] = spent
        table = {name: {} for name in makers}
        names = list(makers)
        for k in range(rounds):
            order = names[k % len(names):] + names[:k % len(names)]
            for name in order:
                for rtol in rtols:
                    seconds, x = timed(runs[name], rtol)
                    entry = table[name].setdefault(rtol, {"rounds": [], "error": None})
                    entry["rounds"].append(seconds)
                    if x is not None and len(x) == len(x_ref):
                        entry["error"] = float(np.max(np.abs(x - x_ref)))
            say(f"peers: {scene_name}, round {k + 1} of {rounds} done")
        for name in table:
            for entry in table[name].values():
                entry["seconds"] = min(entry["rounds"])
        results[scene_name] = table
    return results


def cheapest(table: dict, threshold: float) -> tuple[float, dict] | None:
    """(rtol, entry) of the cheapest setting whose error is within threshold, or None."""
    within = [(rtol, e) for rtol, e in table.items() if e["error"] is not None and e["error"] <= threshold]
    return min(within, key=lambda item: item[1]["seconds"]) if within else None


def verdicts(results: dict) -> list[dict]:
    """Per scene and error level: each contender's cheapest time, the best peer, and ours over the best peer."""
    rows = []
    for scene_name, tables in results.items():
        for threshold in THRESHOLDS:
            best = {name: cheapest(table, threshold) for name, table in tables.items()}
            peers = {n: b for n, b in best.items() if b is not None and not n.startswith(OWN)}
            best_peer = min(peers, key=lambda n: peers[n][1]["seconds"]) if peers else None
            row = {"scene": scene_name, "threshold": threshold, "best_peer": best_peer,
                   "contenders": {n: None if b is None else {"rtol": b[0], "seconds": b[1]["seconds"],
                                                             "error": b[1]["error"]} for n, b in best.items()}}
            for ours in OURS:
                mine = best.get(ours)
                if mine is not None and best_peer is not None:
                    # per round: the ratio of the round's times at the chosen settings; the verdict on the minima
                    per_round = [a / b for a, b in zip(mine[1]["rounds"], peers[best_peer][1]["rounds"])]
                    row[ours] = {"over_best_peer": mine[1]["seconds"] / peers[best_peer][1]["seconds"],
                                 "per_round": per_round}
            rows.append(row)
    return rows


def short_scenes(makers: dict, results: dict, rounds: int) -> dict | None:
    """1,000 short scenes: simulate_many against a numbalsoda LSODA loop, each at its cheapest rtol for 1e-6 on
    the paper scene; the error of both over 5 of the scenes against references."""
    if "numbalsoda LSODA" not in makers:
        return None
    settings = {}
    for name in ("Python API", "Python API, no drive ceiling", "numbalsoda LSODA"):
        found = cheapest(results["paper"].get(name, {}), 1e-6)
        if found is not None:
            settings[name] = found
    if "numbalsoda LSODA" not in settings or not {"Python API", "Python API, no drive ceiling"} & set(settings):
        return None
    # the API at its cheaper line for 1e-6 on the paper scene (with the drive's ceiling or without)
    api_line = min((n for n in settings if n.startswith("Python API")), key=lambda n: settings[n][1]["seconds"])
    api_settings = Settings(rtol=settings[api_line][0], max_step=NO_CEILING if "no drive" in api_line else 0.0)
    settings = {"Python API": settings[api_line][0], "numbalsoda LSODA": settings["numbalsoda LSODA"][0]}
    omegas = np.linspace(0.95, 1.05, SHORT_SCENES)
    scenes = [Scene(omega=float(w)) for w in omegas]
    lsoda_make = makers["numbalsoda LSODA"]

    def batch():
        return api.simulate_many({"omega": omegas}, SHORT_STOP, INTERVAL, api_settings, outputs=api.STATE).x

    def loop():
        return [lsoda_make(scene, SHORT_STOP)(settings["numbalsoda LSODA"]) for scene in scenes]

    times = {"Python API, simulate_many": [], "numbalsoda LSODA loop": []}
    outputs = {}
    for k in range(rounds):
        for name, f in (("Python API, simulate_many", batch), ("numbalsoda LSODA loop", loop))[::1 if k % 2 == 0
                                                                                                   else -1]:
            started = time.perf_counter()
            outputs[name] = f()
            times[name].append(time.perf_counter() - started)
    errors = {name: 0.0 for name in times}
    for i in np.linspace(0, SHORT_SCENES - 1, 5).astype(int):
        x_ref = reference_solution(scenes[i], 0, SHORT_STOP, rtol=REFERENCE_RTOL,
                                   atol=ATOL_PER_RTOL * REFERENCE_RTOL)(grid(SHORT_STOP))[0]
        errors["Python API, simulate_many"] = max(errors["Python API, simulate_many"],
                                                  float(np.max(np.abs(outputs["Python API, simulate_many"][i] - x_ref))))
        errors["numbalsoda LSODA loop"] = max(errors["numbalsoda LSODA loop"],
                                              float(np.max(np.abs(outputs["numbalsoda LSODA loop"][i] - x_ref))))
    best = {name: min(t) for name, t in times.items()}
    return {"scenes": SHORT_SCENES, "stop": SHORT_STOP, "rtol": settings, "api_line": api_line, "seconds": best,
            "rounds": times,
            "max_error_5_scenes": errors,
            "api_over_numbalsoda": best["Python API, simulate_many"] / best["numbalsoda LSODA loop"]}


def run_peers(plant_fmu: Path, out_dir: Path, quick: bool = False, rounds: int | None = None, say=print) -> dict:
    """The peers comparison; writes out_dir/peers.json and peers.png; returns the record."""
    from vibrofmu.output import export
    from vibrofmu.speed.bench import machine_info

    started, machine = time.perf_counter(), machine_info()  # the load average before the bench loads the machine
    rounds = rounds or ROUNDS
    with tempfile.TemporaryDirectory(prefix="vibrofmu-peers-") as tmp:
        makers, one_off, missing = gather(Path(plant_fmu), Path(tmp), say)
        if missing:
            say("peers missing: " + "; ".join(f"{peer}: {why}" for peer, why in missing.items()))
        results = work_precision(makers, one_off, QUICK_RTOLS if quick else RTOLS, rounds, say)
        short = short_scenes(makers, results, rounds)
    record = {"peers": {"quick": quick, "rounds": rounds, "stop": STOP, "interval": INTERVAL,
                        "seconds": time.perf_counter() - started,
                        "command": f"vibrofmu bench --peers{' --quick' if quick else ''} --ladder-rounds {rounds}"},
              "machine": machine, "missing": missing, "one_off_seconds": one_off,
              "results": {scene: {name: {repr(rtol): entry for rtol, entry in table.items()}
                                  for name, table in tables.items()} for scene, tables in results.items()},
              "verdicts": verdicts(results), "short_scenes": short}
    export.write_json(out_dir / "peers.json", record)
    plot_peers(out_dir / "peers.png", results)
    return record


def _verdict(ratio: float) -> str:
    """The acceptance of a ratio to the best peer: at most 1."""
    return f"{'met' if ratio <= 1.0 else 'NOT met'}: <= 1.0"


def peers_lines(record: dict) -> list[str]:
    """The verdicts as text lines (the bench's output and the report block)."""
    lines = []
    if record.get("missing"):
        lines.append("peers missing: " + "; ".join(f"{p}: {w}" for p, w in record["missing"].items()))
    for row in record["verdicts"]:
        ranked = sorted(((c["seconds"], n, c) for n, c in row["contenders"].items() if c is not None))
        shown = ", ".join(f"{n} {1e3 * s:.3g}" for s, n, c in ranked)
        lines.append(f"{row['scene']} scene, error <= {row['threshold']:g} (ms per run, cheapest rtol reaching it): "
                     f"{shown}")
        for ours in OURS:
            if ours in row:
                ratio = row[ours]["over_best_peer"]
                lines.append(f"  {ours} / best peer ({row['best_peer']}): {ratio:.2f}x ({_verdict(ratio)}; per round "
                             f"{', '.join(f'{r:.2f}' for r in row[ours]['per_round'])})")
            else:
                lines.append(f"  {ours}: no setting reached the error, or no peer ran")
    short = record.get("short_scenes")
    if short:
        s, rtol, ratio = short["seconds"], short["rtol"], short["api_over_numbalsoda"]
        api = (f"{s['Python API, simulate_many']:.3f} s ({short.get('api_line', 'Python API')}, "
               f"rtol {rtol['Python API']:g})")
        lsoda = f"{s['numbalsoda LSODA loop']:.3f} s (rtol {rtol['numbalsoda LSODA']:g})"
        errors = ", ".join(f"{n} {e:.1e}" for n, e in short["max_error_5_scenes"].items())
        lines.append(f"{short['scenes']} short scenes (tau 0..{short['stop']:g}): simulate_many {api}, "
                     f"numbalsoda LSODA loop {lsoda}: {ratio:.2f}x ({_verdict(ratio)}); max error over 5 scenes {errors}")
    if record.get("one_off_seconds"):
        lines.append("one-off costs (s, not in the runs): " + ", ".join(
            f"{name} {seconds:.2f}" for name, seconds in record["one_off_seconds"].items()))
    return lines


def plot_peers(path: Path, results: dict) -> None:
    """Error against ms per run, one panel per scene, one line per contender."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(6.5 * len(results), 5), squeeze=False)
    colours = plt.get_cmap("tab20").colors
    for ax, (scene_name, tables) in zip(axes[0], results.items()):
        for k, (name, table) in enumerate(tables.items()):
            # in the order of the setting (rtol, loose to tight): a line per contender, as a work-precision diagram
            points = [(e["seconds"] * 1e3, e["error"]) for _, e in sorted(table.items(), key=lambda item: -item[0])
                      if e["error"] is not None]
            if points:
                ours = name.startswith(OWN)
                ax.loglog(*zip(*points), marker="o" if ours else ".", lw=2.0 if ours else 1.0, label=name,
                          color=colours[k % len(colours)])
        for threshold in THRESHOLDS:
            ax.axhline(threshold, color="grey", lw=0.5, ls=":")
        ax.set_xlabel("ms per run (minimum over the rounds)")
        ax.set_ylabel("max |x - x_ref| on the output grid")
        ax.set_title(f"{scene_name} scene, tau in [0, {STOP:g}], {round(STOP / INTERVAL)} outputs")
        ax.grid(True, which="both", lw=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
