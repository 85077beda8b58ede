"""The C host's cost of the native plant FMU beside the pythonfmu one (the plain C host of tests/c_host/fmi2_host.c,
started with an empty environment): `python -m vibrofmu.speed.native_timing [BUILD_DIR]`."""
from __future__ import annotations

import math
import tempfile
from vibrofmu.speed import child
from pathlib import Path


def host_timing(host: Path, fmu: Path, repeats: int = 3, stop: float = 200.0, step: float = 0.1) -> dict:
    """Best of `repeats` runs of the C host (tests/c_host/fmi2_host.c, started with an empty environment) on the
    plant FMU's x: {'instantiate_s': load + fmi2Instantiate + initialization, 'per_output_s': doStep + getReal
    per communication point}."""
    import re

    from fmpy import extract, read_model_description

    best = {"instantiate_s": math.inf, "per_output_s": math.inf}
    with tempfile.TemporaryDirectory() as tmp:
        unzipped = Path(extract(str(fmu), unzipdir=tmp))
        md = read_model_description(str(unzipped))
        vr = {v.name: v.valueReference for v in md.modelVariables}["x"]
        library = unzipped / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
        for _ in range(repeats):
            proc = child.run([str(host), str(library), (unzipped / "resources").as_uri(), md.guid, "0.0",
                                   repr(stop), repr(step), str(vr)], capture_output=True, text=True,
                                  env={"FMI2_HOST_TIMING": "1", "FMI2_HOST_QUIET": "1"})
            match = re.search(r"instantiate_s=(\S+) per_output_s=(\S+)", proc.stderr)
            if proc.returncode != 0 or match is None:
                raise RuntimeError(f"the C host failed on {fmu}: {proc.stderr.strip()}")
            best["instantiate_s"] = min(best["instantiate_s"], float(match.group(1)))
            best["per_output_s"] = min(best["per_output_s"], float(match.group(2)))
    return best


FMI_VERSIONS_HOST_SOURCE = Path(__file__).with_name("fmi_versions_host.c")
FMI3_OVER_FMI2_LIMIT = 1.1  # issue 23: FMI 3 CS per output <= 1.1 x FMI 2 CS (paper scene, interval 0.1)


def fmi_versions_timing(fmu2: Path, fmu3: Path, repeats: int = 5, stop: float = 200.0, step: float = 0.1) -> dict:
    """The native plant's cost per output as FMI 2.0 and FMI 3.0 Co-Simulation (plain and with event mode and early
    return), side by side: `repeats` interleaved rounds of the three in one C process (fmi_versions_host.c), best of
    each; and the ratios FMI 3 / FMI 2."""
    from fmpy import extract, read_model_description

    from vibrofmu.fmus import toolchain
    from vibrofmu.fmus.native import FMI3_PLATFORMS

    with tempfile.TemporaryDirectory() as tmp:
        host = toolchain.compile_host(FMI_VERSIONS_HOST_SOURCE, Path(tmp) / "fmi_versions_host")
        u2, u3 = Path(extract(str(fmu2), unzipdir=f"{tmp}/2")), Path(extract(str(fmu3), unzipdir=f"{tmp}/3"))
        md = read_model_description(str(u2))
        model_id = md.coSimulation.modelIdentifier
        vr = {v.name: v.valueReference for v in md.modelVariables}["x"]
        proc = child.run([str(host), str(u2 / "binaries" / "linux64" / f"{model_id}.so"),
                               str(u3 / "binaries" / FMI3_PLATFORMS[0] / f"{model_id}.so"), md.guid, repr(stop),
                               repr(step), str(repeats), str(vr)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"the FMI versions host failed: {proc.stderr.strip()}")
    best: dict = {}
    for line in proc.stdout.split("\n"):
        if line.strip():
            name, seconds, outputs, events = line.split()
            per_output = float(seconds) / int(outputs)
            best[name] = min(best.get(name, math.inf), per_output)
    return {"per_output_s": best, "fmi3_over_fmi2": best["fmi3"] / best["fmi2"],
            "fmi3_early_return_over_fmi2": best["fmi3er"] / best["fmi2"], "limit": FMI3_OVER_FMI2_LIMIT,
            "met": best["fmi3"] / best["fmi2"] <= FMI3_OVER_FMI2_LIMIT,
            "note": f"C host, paper scene, tau 0..{stop:g}, interval {step:g}, best of {repeats} interleaved rounds; "
                    "fmi3er: event mode and early return allowed"}


def me_beside_cs(fmu2: Path, repeats: int = 3, stop: float = 200.0, step: float = 0.1, rtol: float = 1e-8) -> dict:
    """The native plant under FMPy: Model Exchange with CVode (at rtol, FMPy's solver and loop) beside Co-Simulation
    (the FMU's DOP853 at the same rtol), seconds per output, best of `repeats` interleaved; no target."""
    import time

    from fmpy import extract, read_model_description, simulate_fmu

    with tempfile.TemporaryDirectory() as tmp:
        unzipped = extract(str(fmu2), unzipdir=tmp)
        md = read_model_description(unzipped)
        best = {"me_cvode": math.inf, "cs": math.inf}
        for _ in range(repeats):
            for name, options in (("me_cvode", {"fmi_type": "ModelExchange", "solver": "CVode"}),
                                  ("cs", {"fmi_type": "CoSimulation"})):
                started = time.perf_counter()
                result = simulate_fmu(unzipped, model_description=md, stop_time=stop, output_interval=step,
                                      relative_tolerance=rtol, output=["x"], record_events=False, **options)
                best[name] = min(best[name], (time.perf_counter() - started) / (len(result) - 1))
    return {"per_output_s": best, "me_over_cs": best["me_cvode"] / best["cs"],
            "note": f"FMPy 0.3.x simulate_fmu, paper scene, tau 0..{stop:g}, interval {step:g}, rtol {rtol:g}, best "
                    f"of {repeats}; ME: FMPy's CVode (BDF) and its Python loop, CS: the FMU's DOP853"}


def fmi_versions_record(pythonfmu_plant: Path, repeats: int = 5) -> dict:
    """`vibrofmu bench`'s FMI versions record: the native plant built as FMI 2.0 and FMI 3.0 from the pythonfmu FMU,
    fmi_versions_timing and me_beside_cs."""
    from vibrofmu.fmus.native import build_native

    with tempfile.TemporaryDirectory(prefix="vibrofmu-bench-fmi3-") as tmp:
        fmu2 = build_native(pythonfmu_plant, Path(tmp) / "fmi2", win64=False, reference=False)
        fmu3 = build_native(pythonfmu_plant, Path(tmp) / "fmi3", win64=False, reference=False, fmi_version=3)
        return {"cosimulation": fmi_versions_timing(fmu2, fmu3, repeats),
                "model_exchange": me_beside_cs(fmu2, max(1, repeats // 2))}


def fmi_versions_lines(record: dict) -> list[str]:
    cs, me = record["cosimulation"], record["model_exchange"]
    return [f"  FMI 3 CS / FMI 2 CS per output (native plant, C host): {cs['fmi3_over_fmi2']:.3f} (target <= "
            f"{cs['limit']:g}: {'met' if cs['met'] else 'NOT met'}); with event mode + early return "
            f"{cs['fmi3_early_return_over_fmi2']:.3f}",
            f"  ME (FMPy CVode) / CS (FMPy) per output: {me['me_over_cs']:.2f} ({1e6 * me['per_output_s']['me_cvode']:.1f}"
            f" vs {1e6 * me['per_output_s']['cs']:.1f} us; no target)"]


if __name__ == "__main__":  # python -m vibrofmu.speed.native_timing [BUILD_DIR]: native vs pythonfmu plant in the C host
    import sys

    from vibrofmu.hosts.doctor import compile_host

    build = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("build")
    with tempfile.TemporaryDirectory() as work:
        host = compile_host(Path(work))
        python = host_timing(host, build / "HertzEAOscillator.fmu")
        native = host_timing(host, build / "native" / "HertzEAOscillator.fmu")
    print("C host, plant fidelity 0, tau 0..200, interval 0.1, best of 3, empty environment:")
    for name, result in (("pythonfmu (C fast path)", python), ("native", native)):
        print(f"  {name:24s} instantiate {1e3 * result['instantiate_s']:8.2f} ms   per output "
              f"{1e6 * result['per_output_s']:.3f} us")
    print(f"  native / pythonfmu per output: {native['per_output_s'] / python['per_output_s']:.2f}")
