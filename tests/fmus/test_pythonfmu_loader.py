"""The pythonfmu FMUs' loader (the status shim's checks before pythonfmu imports the slave, fmi2_status_shim.c
slave_files; resources/vibrofmu_identity.txt written by vibrofmu.fmus.shim): every resource or slave-module failure
gives NULL from fmi2Instantiate and one log line naming the resource location and what is wrong, never a crash --
a folder name that is not UTF-8, slavemodule.txt naming a missing module, empty or naming another module, a file of
the slave missing (a partial extraction), the identity file missing -- and the model loaded is the binary's own:
given another FMU's resources (whose slave ran under this FMU's GUID before) the binary refuses. Each FMU in a
subprocess of the probe host (vibrofmu.hosts.probe loader)."""
import pytest

from vibrofmu.hosts.probe import run_probe

pytestmark = pytest.mark.fmu  # the FMUs are asked for by name (request.getfixturevalue)

PAIRS = [("plant_fmu", "controller_fmu"), ("controller_fmu", "plant_fmu"), ("closed_loop_fmu", "plant_fmu")]


@pytest.mark.parametrize("pair", PAIRS)
def test_damaged_or_foreign_resources_are_refused(request, pair):
    this, other = (request.getfixturevalue(name) for name in pair)
    code, lines, stderr = run_probe("loader", this, str(other))
    last = lines[-1]["case"] if lines else None
    assert code == 0, f"the host died (exit {code}) after case {last!r}:\n{stderr}"
    assert len(lines) == 9 and lines[-1]["case"] == "intact copy"
    for line in lines:
        assert line["accepted"] == line["expected"], line
        if not line["expected"]:  # one log line, naming the argument
            errors = [text for text in line["log"] if text.startswith("[3]")]
            assert len(errors) == 1 and "fmi2Instantiate refused: fmuResourceLocation" in errors[0], line
    foreign = next(line for line in lines if line["case"] == "another FMU's resources")
    assert "another model's" in foreign["log"][-1]
