"""The plant FMU's FMI contract (docs/fmu-reference.md): validation, variable names, start values."""
import math

from fmpy import read_model_description
from fmpy.validation import validate_fmu

from vibromodel.parameters import PAPER_OMEGA


def test_validate_fmu_has_no_messages(plant_fmu):
    assert validate_fmu(str(plant_fmu)) == []


def test_variables_follow_the_design_contract(plant_fmu):
    md = read_model_description(str(plant_fmu))
    variables = {v.name: v for v in md.modelVariables}
    for name in ("mu", "Delta", "omega", "Omega", "alpha", "beta", "gamma", "R", "x_start", "v_start",
                 "rtol", "max_step"):
        assert variables[name].causality == "parameter" and variables[name].type == "Real", name
    for name in ("fidelity", "solver"):
        assert variables[name].causality == "parameter" and variables[name].type == "Integer", name
    assert variables["U"].causality == "input" and variables["U"].type == "Real"
    for name in ("x", "v", "a", "F_contact", "F_electrostatic"):
        assert variables[name].causality == "output" and variables[name].type == "Real", name
        assert variables[name].initial == "exact", name
    assert variables["in_contact"].type == "Boolean" and variables["in_contact"].variability == "discrete"


def test_start_values_are_the_paper_example(plant_fmu):
    variables = {v.name: v for v in read_model_description(str(plant_fmu)).modelVariables}
    expected = {"mu": 0.1, "Delta": 0.0007, "Omega": 2.0, "alpha": 0.001, "beta": 0.0001, "gamma": 0.0002,
                "R": 1.0, "x_start": 0.04, "v_start": 0.0, "rtol": 1e-8}
    for name, value in expected.items():
        assert float(variables[name].start) == value, name
    # omega = sqrt(a1) + delta*epsilon with a1 = 1 - 8 alpha/3 - 4 gamma/3, delta = 0.02, epsilon = 0.01
    assert math.isclose(float(variables["omega"].start), math.sqrt(1 - 8e-3 / 3 - 8e-4 / 3) + 2e-4, rel_tol=1e-15)
    assert math.isclose(PAPER_OMEGA, 0.9987322562, abs_tol=1e-10)
    assert int(variables["fidelity"].start) == 0 and int(variables["solver"].start) == 0


def test_fmu_runs_on_the_vibromodel_packed_in_its_resources(plant_fmu, tmp_path):
    """In a fresh process that never imported vibromodel, the FMU imports its own packed copy."""
    import subprocess
    import sys

    script = (
        "import sys\n"
        "from fmpy import simulate_fmu\n"
        f"r = simulate_fmu({str(plant_fmu)!r}, stop_time=1.0, output_interval=0.1)\n"
        "print(sys.modules['vibromodel'].__file__)\n"
        "print(r['x'][-1])\n"
    )
    out = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, check=True)
    module_file, x_end = out.stdout.split()
    assert "/resources/vibromodel/" in module_file
    assert math.isfinite(float(x_end))
