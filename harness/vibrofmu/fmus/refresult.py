"""Reference results inside the FMU, as the Modelica Reference-FMUs ship them.

`vibrofmu build` simulates the finished FMU's default experiment with FMPy and packs the outputs as
documentation/<model>_ref.csv, with the settings and tool versions that made them in
documentation/<model>_ref.json. Anyone can re-simulate the FMU and compare with FMPy's
validate_result: the fraction of samples outside a band around the reference, 0 = all inside.
"""
from __future__ import annotations

import json
import platform
import sys
import tempfile
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import scipy
from fmpy import read_model_description, simulate_fmu
from fmpy.util import read_csv, validate_result

from vibrofmu.output.export import write_csv

DOCUMENTATION = "documentation"


def reference_names(model_identifier: str) -> tuple[str, str]:
    """Paths of the reference CSV and its settings JSON inside the FMU."""
    return f"{DOCUMENTATION}/{model_identifier}_ref.csv", f"{DOCUMENTATION}/{model_identifier}_ref.json"


def simulate_experiment(fmu: Path, experiment: dict) -> np.ndarray:
    """The outputs over `experiment` (reference_settings' "experiment"), start values at their defaults."""
    return simulate_fmu(str(fmu), start_time=experiment["startTime"], stop_time=experiment["stopTime"],
                        output_interval=experiment["stepSize"], relative_tolerance=experiment["tolerance"])


def reference_settings(fmu: Path) -> dict:
    """The FMU's DefaultExperiment (as numbers) and what simulated it."""
    md = read_model_description(str(fmu))
    experiment = md.defaultExperiment

    def number(text):
        return None if text is None else float(text)

    return {
        "experiment": {"startTime": number(experiment.startTime), "stopTime": number(experiment.stopTime),
                       "stepSize": number(experiment.stepSize), "tolerance": number(experiment.tolerance)},
        "simulator": "fmpy.simulate_fmu, co-simulation, output interval = stepSize, start values = defaults",
        "outputs": [v.name for v in md.modelVariables if v.causality == "output"],
        "versions": {"fmpy": fmpy.__version__, "numpy": np.__version__, "scipy": scipy.__version__,
                     "python": sys.version.split()[0], "platform": platform.platform()},
    }


def pack_reference(fmu: Path) -> None:
    """Simulate fmu's default experiment and add the result and its settings to fmu's documentation."""
    settings = reference_settings(fmu)
    result = simulate_experiment(fmu, settings["experiment"])
    csv_name, json_name = reference_names(read_model_description(str(fmu)).coSimulation.modelIdentifier)
    with tempfile.TemporaryDirectory() as tmp:
        csv_path = Path(tmp) / "ref.csv"
        write_csv(csv_path, result["time"], {name: result[name] for name in result.dtype.names[1:]})
        with zipfile.ZipFile(fmu, "a", zipfile.ZIP_DEFLATED) as archive:
            archive.write(csv_path, csv_name)
            archive.writestr(json_name, json.dumps(settings, indent=2) + "\n")


def read_reference(fmu: Path) -> tuple[np.ndarray, dict]:
    """The packed reference result (structured array) and its settings."""
    csv_name, json_name = reference_names(read_model_description(str(fmu)).coSimulation.modelIdentifier)
    with zipfile.ZipFile(fmu) as archive, tempfile.TemporaryDirectory() as tmp:
        csv_path = Path(tmp) / "ref.csv"
        csv_path.write_bytes(archive.read(csv_name))
        return read_csv(csv_path), json.loads(archive.read(json_name))


def validate_against_reference(fmu: Path) -> float:
    """Re-simulate fmu and score it against its packed reference (fmpy.util.validate_result; 0 = pass)."""
    reference, settings = read_reference(fmu)
    result = simulate_experiment(fmu, settings["experiment"])
    return float(validate_result(result, reference, stop_time=settings["experiment"]["stopTime"]))
