"""The C host's cost of the native plant FMU beside the pythonfmu one (the plain C host of tests/c_host/fmi2_host.c,
started with an empty environment): `python -m vibrofmu.speed.native_timing [BUILD_DIR]`."""
from __future__ import annotations

import math
import subprocess
import tempfile
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
            proc = subprocess.run([str(host), str(library), (unzipped / "resources").as_uri(), md.guid, "0.0",
                                   repr(stop), repr(step), str(vr)], capture_output=True, text=True,
                                  env={"FMI2_HOST_TIMING": "1", "FMI2_HOST_QUIET": "1"})
            match = re.search(r"instantiate_s=(\S+) per_output_s=(\S+)", proc.stderr)
            if proc.returncode != 0 or match is None:
                raise RuntimeError(f"the C host failed on {fmu}: {proc.stderr.strip()}")
            best["instantiate_s"] = min(best["instantiate_s"], float(match.group(1)))
            best["per_output_s"] = min(best["per_output_s"], float(match.group(2)))
    return best


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
