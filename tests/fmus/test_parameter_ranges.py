"""Valid ranges (issue 15, item 3): one table of rules (vibromodel.parameters.RULES) covers every parameter of the
three FMUs, is checked up front at fmi2ExitInitializationMode with the parameter named, and turns the issue's
raw exceptions, wrong names and non-finite outputs into named refusals."""
import json
import math

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException

from vibromodel.parameters import RULES, ParameterError, check_parameters, rules_as_records

FMUS = ("plant", "controller", "closed_loop")


def parameter_names(fmu):
    return [v.name for v in read_model_description(str(fmu)).modelVariables if v.causality == "parameter"]


@pytest.mark.fmu  # asks for its FMU by name (request.getfixturevalue)
@pytest.mark.parametrize("which", FMUS)
def test_every_parameter_of_every_fmu_has_a_rule(request, which):
    ruled = {rule.name for rule in RULES}
    missing = [name for name in parameter_names(request.getfixturevalue(f"{which}_fmu")) if name not in ruled]
    assert missing == []


@pytest.mark.fmu  # asks for its FMU by name (request.getfixturevalue)
@pytest.mark.parametrize("which", FMUS)
def test_the_default_parameters_obey_the_rules(request, which):
    variables = read_model_description(str(request.getfixturevalue(f"{which}_fmu"))).modelVariables
    values = {v.name: (int(v.start) if v.type == "Integer" else float(v.start))
              for v in variables if v.causality == "parameter"}
    check_parameters(values)


@pytest.mark.parametrize("rule", RULES, ids=lambda rule: f"{rule.name}{'' if rule.when is None else '-when'}")
def test_each_rule_accepts_its_ends_and_refuses_just_beyond(rule):
    """The ends (inclusive or not) and the next double (or whole number) beyond them; NaN and inf always refused."""
    context = {} if rule.when is None else {rule.when[0]: rule.when[1][0]}
    step_out = (lambda x, d: x + d) if rule.integer else (lambda x, d: float(np.nextafter(x, x + d)))
    for end, inclusive, outwards in ((rule.low, rule.low_inclusive, -1), (rule.high, rule.high_inclusive, 1)):
        inside = end if inclusive else step_out(end, -outwards)
        check_parameters({**context, rule.name: inside})
        outside = step_out(end, outwards) if inclusive else end
        if outside == rule.automatic:
            continue
        with pytest.raises(ParameterError, match=f"parameter {rule.name} = ") as refused:
            check_parameters({**context, rule.name: outside})
        # this rule's reason, or that of an earlier rule of the same name (a conditional rule narrows one end)
        assert any(r.reason in str(refused.value) for r in RULES if r.name == rule.name), refused.value
    for bad in (math.nan, math.inf, -math.inf):
        with pytest.raises(ParameterError, match=f"parameter {rule.name} = "):
            check_parameters({**context, rule.name: bad})
    if rule.automatic is not None:
        check_parameters({**context, rule.name: rule.automatic})


def test_every_input_rule_contains_what_the_fast_path_sets_itself():
    """The shim's fast path sets inputs in [-FAST_INPUT_LIMIT, FAST_INPUT_LIMIT] without the slave's check."""
    from vibromodel.parameters import FAST_INPUT_LIMIT

    inputs = [rule for rule in RULES if rule.causality == "input"]
    assert inputs and all(rule.low <= -FAST_INPUT_LIMIT and FAST_INPUT_LIMIT <= rule.high for rule in inputs)


def test_rules_export_as_plain_json_records_in_checking_order():
    records = json.loads(json.dumps(rules_as_records()))
    assert [r["name"] for r in records] == [rule.name for rule in RULES]
    assert set(records[0]) == {"name", "low", "high", "low_inclusive", "high_inclusive", "reason", "integer",
                               "automatic", "when", "causality"}
    averaged = [r for r in records if r["when"] is not None]
    assert averaged and all(r["when"] == {"name": "fidelity", "values": [3, 4]} for r in averaged)


def initialisation_error(request, which, values, tolerance=None):
    """The error logged by fmi2ExitInitializationMode with these start values (it must fail with fmi2Error), after
    which the outputs read finite or the getter fails: never non-finite with fmi2OK."""
    from vibrofmu.hosts.run import FmuInstance

    fmu, unzipped = request.getfixturevalue(f"{which}_fmu"), request.getfixturevalue(f"{which}_unzipped")
    with FmuInstance(fmu, unzip_dir=unzipped) as instance:
        instance.fmu.setupExperiment(tolerance=tolerance, startTime=0.0)
        instance.fmu.enterInitializationMode()
        instance.set(values)
        with pytest.raises(FMICallException) as failure:
            instance.fmu.exitInitializationMode()
        assert failure.value.status == 3
        try:
            outputs = instance.read_outputs()
            assert all(map(math.isfinite, outputs)), outputs
        except FMICallException as error:
            assert error.status == 3
        return instance.log.errors()[-1]


# The issue's cases: (FMU, start values, setupExperiment tolerance, the parameter the message must name)
ISSUE_CASES = [
    ("plant", {"fidelity": 1, "alpha": 1e308}, None, "alpha"),  # a = inf with fmi2OK
    ("plant", {"fidelity": 2, "alpha": 1e308}, None, "alpha"),
    ("plant", {"fidelity": 1, "gamma": 1.797e308}, None, "gamma"),  # a = NaN with fmi2OK
    ("plant", {"fidelity": 2, "gamma": 1.797e308}, None, "gamma"),
    ("controller", {"lambda3": 5e-324}, None, "lambda3"),  # overflow, then frozen outputs with fmi2OK
    ("plant", {"rtol": 1e308}, None, "rtol"),  # accepted silently, x = 1.68 past the electrode
    ("plant", {"rtol": 1e10}, None, "rtol"),
    ("plant", {}, 1e10, "rtol"),  # the same through setupExperiment's tolerance
    ("plant", {"fidelity": 3, "omega": 0.0}, None, "omega"),  # ZeroDivisionError
    ("plant", {"fidelity": 3, "Omega": 0.0}, None, "Omega"),
    ("plant", {"fidelity": 4, "omega": 5e-324}, None, "omega"),  # 150 s to initialise
    ("plant", {"fidelity": 4, "Omega": 5e-324}, None, "Omega"),
    ("plant", {"solver": 1, "max_step": 1e308}, None, "max_step"),  # math domain error
    ("plant", {"fidelity": 3, "R": 1e308}, None, "R"),  # OverflowError
    ("plant", {"fidelity": 4, "R": 1e308}, None, "R"),
    ("plant", {"fidelity": 3, "mu": 1e308}, None, "mu"),
    ("plant", {"fidelity": 4, "mu": 1e308}, None, "mu"),
    ("plant", {"fidelity": 4, "oafm_tau_end": 1e308}, None, "oafm_tau_end"),  # Maximum allowed size exceeded
    ("plant", {"fidelity": 4, "gamma": 1e308}, None, "gamma"),  # named "alpha"
    ("plant", {"fidelity": 4, "Delta": 1e308}, None, "Delta"),  # "tau_star = nan"
    ("plant", {"fidelity": 4, "beta": 1e308}, None, "beta"),
    ("controller", {"R": 5e-324}, None, "R"),  # named "x_start"
    ("closed_loop", {"reference": 1, "x_ref_start": math.nan}, None, "x_ref_start"),  # step size collapsed
    ("closed_loop", {"reference": 1, "v_ref_start": math.inf}, None, "v_ref_start"),
]


@pytest.mark.fmu  # asks for its FMU by name (request.getfixturevalue)
@pytest.mark.parametrize("which,values,tolerance,name", ISSUE_CASES)
def test_issue_cases_are_refused_up_front_naming_the_parameter(request, which, values, tolerance, name):
    message = initialisation_error(request, which, values, tolerance)
    value = values.get(name, tolerance)
    assert f"parameter {name} = {value!r}: must be" in message, message


def test_the_controller_at_its_smallest_weight_keeps_finite_outputs(start_controller):
    """lambda3 at the rule's low end: the update law runs with finite outputs (the rule's bound is not too loose)."""
    with start_controller(lambda3=1e-6, x=0.3, v=-0.2, x_ref=0.0) as instance:
        for k in range(20):
            instance.fmu.doStep(currentCommunicationPoint=0.1 * k, communicationStepSize=0.1)
        assert all(map(math.isfinite, instance.read_outputs()))


@pytest.mark.parametrize("name,value", [("x", -1e300), ("v", math.nan), ("a_ref", 1e9), ("x_ref", math.inf)])
def test_the_controller_refuses_inputs_out_of_range_naming_them(start_controller, name, value):
    """Found by the strengthened fuzzing: x = -1e300 made U overflow (the outputs are algebraic in the inputs)."""
    with start_controller() as instance:
        before = instance.read_outputs()
        with pytest.raises(FMICallException) as failure:
            instance.set({name: value})
        assert failure.value.status == 3
        assert f"parameter {name} = {value!r}: must be" in instance.log.errors()[-1]
        assert instance.read_outputs() == before


def test_a_non_finite_output_fails_the_call_naming_it_and_keeps_the_last_finite_values(monkeypatch):
    """Issue 15: slave_support skipped non-finite values silently (the controller then answered fmi2OK with frozen
    outputs). Now publishing one raises NonFiniteOutput, an ArithmeticError: doStep turns it into fmi2Error with
    "simulation stopped: ... tau = ..." (StatusSlave._guarded_step), initialisation into fmi2Error too."""
    from vibrofmu.fmus.build import FMU_SRC

    monkeypatch.syspath_prepend(str(FMU_SRC))
    from AdaptiveLyapunovController import AdaptiveLyapunovController
    from slave_support import NonFiniteOutput

    slave = AdaptiveLyapunovController(instance_name="direct")
    slave._set_finite({"U": 1.5, "e1": 0.25})
    with pytest.raises(NonFiniteOutput, match=r"output e1 = nan is not finite"):
        slave._set_finite({"U": 2.0, "e1": math.nan})
    assert (slave.U, slave.e1) == (1.5, 0.25)
    assert issubclass(NonFiniteOutput, ArithmeticError)
