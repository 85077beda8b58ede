"""FMU states a host should never be able to use wrongly, each FMU in a subprocess of the probe host
(vibrofmu.hosts.probe me_block / foreign_states, vibrofmu.hosts.pointers) so that a crash fails the test:
  - the Model Exchange / early-return block of a native state (me_data.h), each field forged and the checksum
    recomputed, is refused by fmi2DeSerializeFMUstate with a log line naming the field, in a Model Exchange and in a
    Co-Simulation instance, which then answers as before (forged x = 5.0 and x = -9.0, beyond the electrodes at
    +-3, and NaN states were taken with fmi2OK); a state of the other interface is refused; the instance's own is
    taken;
  - a state of another FMU (loaded in the same process) and a freed state are refused by every state call
    (fmi2GetFMUstate into another FMU's state overwrote it in place) and the other FMU's state stays intact.
"""
import math

import pytest

from vibrofmu.hosts.probe import run_probe

pytestmark = pytest.mark.fmu  # the FMUs are asked for by name (request.getfixturevalue)
OK, ERROR = 0, 3
ELECTRODE = 3.0  # 3R/2 for the default R = 2: every x the plant answers with fmi2OK is inside


def _check_exit(code, lines, stderr):
    last = lines[-1]["case"] if lines else None
    assert code == 0, f"the host died (exit {code}) after case {last!r}:\n{stderr}"


@pytest.mark.parametrize("fixture", ["native_plant_fmu", "native_closed_loop_fmu", "native_controller_fmu"])
def test_forged_model_exchange_blocks_are_refused(request, fixture):
    code, lines, stderr = run_probe("me_block", request.getfixturevalue(fixture))
    _check_exit(code, lines, stderr)
    assert lines[0]["case"] == "found the block" and lines[0]["ok"], lines[0]
    forged = [line for line in lines[1:] if "=" in line["case"]]
    assert len(forged) == 28  # 14 forgeries x (ME, CS)
    if fixture == "native_controller_fmu":
        # the controller's first state is the estimate mu^, which has no domain (no electrode, no event
        # indicator): x[0] = 5.0 and -9.0 are states it may reach, taken by the ME instance and answered as given
        domain = [line for line in forged if line["case"] in ("x[0] = 5.0", "x[0] = -9.0")]
        taken = [line for line in domain if line["instance"] == "ME"]
        assert len(taken) == 2
        for line in taken:
            assert (line["deserialize"], line["after"]) == (OK, [OK, float(line["case"].split(" = ")[1])]), line
        forged = [line for line in forged if line not in taken]
    for line in forged + [next(line for line in lines if line["case"].startswith(prefix))
                          for prefix in ("an ME state", "a CS state")]:
        assert line["deserialize"] == ERROR, line
        log = " ".join(line["log"])
        assert "refused" in log and ("model.me" in log or "domain" in log or "instance" in log), line
        status, x = line["after"]  # the instance as it was: no wrong answer with OK
        assert status > OK or (math.isfinite(x) and abs(x) < ELECTRODE), line
    own = next(line for line in lines if line["case"] == "its own state into the ME instance")
    assert (own["deserialize"], own["set"]) == (OK, OK) and own["after"] == [OK, 0.123456789], own
    # a live ME state (got, or deserialized by an ME instance) set into a CS instance: refused by fmi2SetFMUstate,
    # which checks the interface of the instance it sets (a state's content is checked once, when it becomes live)
    across = [line for line in lines if line["case"].endswith("set into a CS instance")]
    assert len(across) == 2
    for line in across:
        assert line["made"] == OK and line["set"] == ERROR, line
        assert any("fmi2SetFMUstate refused" in text and "Model Exchange state" in text for text in line["log"]), line
        status, x = line["after"]
        assert status == OK and math.isfinite(x), line  # the CS instance steps on as it was


@pytest.mark.parametrize("pair", [("plant_fmu", "controller_fmu"), ("native_plant_fmu", "native_controller_fmu"),
                                  ("native_closed_loop_fmu", "plant_fmu"), ("closed_loop_fmu", "native_plant_fmu")])
def test_states_of_another_fmu_or_freed_are_refused(request, pair):
    this, other = (request.getfixturevalue(name) for name in pair)
    code, lines, stderr = run_probe("foreign_states", this, str(other))
    _check_exit(code, lines, stderr)
    case = {line["case"]: line for line in lines}
    assert case["start"]["ok"]
    refusals = [line for line in lines if "another FMU's state" in line["case"] or "freed state" in line["case"]]
    assert len(refusals) == 7
    for line in refusals:
        assert line["status"] == ERROR and any(line["call"] in text and "FMUstate" in text for text in line["log"]), \
            line
    intact = case["the other FMU's state intact"]
    assert intact["ok"] and intact["status"] == OK, intact
    assert case["doStep after the refusals"]["status"] == OK


def test_fmi3_states_of_another_fmu_or_freed_are_refused(plant_fmi3, controller_fmi3):
    plant, controller = plant_fmi3, controller_fmi3
    code, lines, stderr = run_probe("foreign_states3", plant, str(controller))
    _check_exit(code, lines, stderr)
    refusals = [line for line in lines if "another FMU's state" in line["case"] or "freed state" in line["case"]]
    assert len(refusals) == 6
    for line in refusals:
        assert line["status"] == ERROR and any(line["call"] in text and "FMUState" in text for text in line["log"]), \
            line
    assert next(line for line in lines if line["case"] == "the other FMU's state intact")["status"] == OK
