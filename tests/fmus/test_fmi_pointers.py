"""Pointer arguments and instance pointers, every FMU (pythonfmu, native FMI 2.0 co-simulation and Model Exchange,
native FMI 3.0 co-simulation and Model Exchange: every native FMU offers both), each FMU in a subprocess of the probe host (vibrofmu.hosts.probe
pointers / pointers3, vibrofmu.hosts.pointers) so that a crash fails the test instead of ending the run:
  - a NULL array with n > 0 or a NULL result pointer in any FMI function is fmi2Error / fmi3Error with a log line
    naming the function and the argument (fmi2GetReal(c, NULL, 2, buf), fmi2GetReal(c, vr, 2, NULL) and
    fmi2SetReal(c, NULL, 2, v) crashed all six FMI 2.0 FMUs, fmi2GetStatus(c, fmi2DoStepStatus, NULL) the native
    ones); NULL arrays with n = 0 are fmi2OK; the instance steps on afterwards;
  - a pointer that is no instance, a freed instance and a second FreeInstance are refused or ignored, never used.
"""
import pytest

from vibrofmu.hosts.probe import run_probe

pytestmark = pytest.mark.fmu  # the FMUs are asked for by name (request.getfixturevalue)

FMI2 = ["plant_fmu", "controller_fmu", "closed_loop_fmu",
        "native_plant_fmu", "native_controller_fmu", "native_closed_loop_fmu"]
FMI3 = ["plant", "controller", "closed_loop"]


@pytest.fixture(scope="module")
def fmi3_fmus(request):
    return {name: request.getfixturevalue(f"{name}_fmi3") for name in FMI3}  # (tests/conftest.py: built once)


def check(code, lines, stderr, expected_cases):
    last = lines[-1]["case"] if lines else None
    assert code == 0, f"the host died (exit {code}) after case {last!r}:\n{stderr}"
    case = {line["case"]: line for line in lines}
    assert case["start"]["ok"], case["start"]
    assert expected_cases <= set(case), expected_cases - set(case)
    for line in lines[1:]:
        assert line["status"] == line["expected"], line
        if line["argument"] is not None:  # one log line naming the function and the argument
            assert any(line["call"] in text and line["argument"] in text for text in line["log"]), line
    return case


@pytest.mark.parametrize("fixture", FMI2)
def test_fmi2_null_pointers_and_dead_instances(request, fixture):
    fmu = request.getfixturevalue(fixture)
    code, lines, stderr = run_probe("pointers", fmu)
    expected = {"fmi2GetReal(vr NULL)", "fmi2GetReal(value NULL)", "fmi2SetReal(vr NULL)", "fmi2GetStatus(value NULL)",
                "fmi2GetDirectionalDerivative(dvUnknown NULL)", "doStep after the refusals", "fmi2GetReal(freed)",
                "fmi2DoStep(not an instance)", "second fmi2FreeInstance"}
    if fixture.startswith("native"):  # they offer Model Exchange (the controller: no event indicators, so
        # fmi2GetEventIndicators(NULL) with 0 of them is fmi2OK)
        expected |= {"fmi2GetDerivatives(NULL)", "fmi2SetContinuousStates(NULL)", "fmi2NewDiscreteStates(NULL)",
                     "fmi2GetEventIndicators(NULL)"}
    case = check(code, lines, stderr, expected)
    assert case["doStep after the refusals"]["x"] == case["doStep after the refusals"]["x"]  # a number, not NaN


@pytest.mark.parametrize("name", FMI3)
def test_fmi3_null_pointers_and_dead_instances(fmi3_fmus, name):
    code, lines, stderr = run_probe("pointers3", fmi3_fmus[name])
    expected = {"fmi3GetFloat64(valueReferences NULL)", "fmi3SetFloat64(values NULL)", "fmi3DoStep(outputs NULL)",
                "fmi3SetDebugLogging(categories NULL)", "fmi3DoStep after the refusals", "fmi3GetFloat64(freed)",
                "fmi3GetFloat64(not an instance)", "second fmi3FreeInstance"}
    # every native FMU offers Model Exchange
    expected |= {"fmi3GetContinuousStateDerivatives(NULL)", "fmi3UpdateDiscreteStates(NULL)",
                 "fmi3GetEventIndicators(NULL)"}
    check(code, lines, stderr, expected)
