"""The reference result packed in the FMU (documentation/, as the Modelica Reference-FMUs ship
<Model>_ref.csv): re-simulating the built FMU with FMPy passes fmpy.util.validate_result with score 0,
and on the machine that built it the result is the same bit for bit (deterministic FMU)."""
import numpy as np

from vibrofmu.fmus.refresult import read_reference, simulate_experiment, validate_against_reference


def test_packed_reference_describes_the_default_experiment(plant_fmu):
    reference, settings = read_reference(plant_fmu)
    assert settings["experiment"] == {"startTime": 0.0, "stopTime": 200.0, "stepSize": 0.1, "tolerance": None}
    assert list(reference.dtype.names) == ["time"] + settings["outputs"]
    assert len(reference) == 2001 and reference["time"][-1] == 200.0


def test_resimulation_validates_with_score_zero_and_is_identical_here(plant_fmu):
    assert validate_against_reference(plant_fmu) == 0.0
    reference, settings = read_reference(plant_fmu)
    result = simulate_experiment(plant_fmu, settings["experiment"])
    for name in reference.dtype.names:
        # the same FMU, start values and FMPy loop on the machine that wrote the reference (deterministic: no clock,
        # no randomness), and the CSV's digits round-trip to the same doubles: equal bits
        assert np.array_equal(result[name].astype(float), reference[name]), name
