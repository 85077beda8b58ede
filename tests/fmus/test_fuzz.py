"""Bad-input fuzzing of the three FMUs (plant, controller, closed loop) with hypothesis, through FMPy, in
this process.

One extracted FMU; each generated case instantiates it, sets parameters (NaN, +-inf, 0, -0, negative,
huge, tiny or plausible values), initialises, and runs a few actions: doStep with good or bad step
sizes and current times, input values, setting parameters after initialisation, a state round trip.
Properties of every call: it returns a status and never fmi2Fatal (no exception escaped to
pythonfmu); after it, failed calls included, the outputs read with fmi2OK are finite (issue 15); every fmi2Error comes with an error message that
names the variable (or step argument) and its value, or says why the simulation stopped, or is the
shim's refusal after an earlier error. derandomize, with hypothesis pinned in pyproject.toml: the same cases
in every run and on every machine; database=None: nothing written outside the temporary folders.
"""
import math
import re
import time

import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir

from vibrofmu.hosts.run import FmuInstance
from vibromodel.closedloop import ERRATA_SCENE
from vibromodel.control import ERRATA_INITIAL_ESTIMATES, ESTIMATE_NAMES, GAIN_NAMES, Gains
from vibromodel.parameters import Scene
from vibromodel.tracking import ReferenceSettings

pytestmark = pytest.mark.fmu  # every test here asks for FMUs by name (request.getfixturevalue)

OK, WARNING, ERROR, FATAL = 0, 1, 3, 4
MIN_CASES = 2000  # the plant's; the controller and the closed loop (no OAFM fit, few parameters) get fewer
MIN_CONTROL_CASES = 300
PLANT_OUTPUTS = ["x", "v", "a", "F_contact", "F_electrostatic"]
CONTROLLER_INPUTS = ["x", "v", "x_ref", "v_ref", "a_ref"]
CONTROLLER_OUTPUTS = ["U", "e1", "e2", "V", *ESTIMATE_NAMES]
LOOP_OUTPUTS = ["x", "v", "x_ref", "U", "e1", "e2", "V", "V_rate", "V_rate_promised", *ESTIMATE_NAMES]
NASTY = [math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, -1e300, 1e300, 5e-324, 1e-300, 1.7976931348623157e308]
REJECTED_AT_ONCE = [math.nan, math.inf, -math.inf, -1.0, -1e300]  # OAFM domains: valid ones mean a new fit
NASTY_INTEGERS = [-2**31, -1, 0, 1, 2, 3, 4, 5, 9, 2**31 - 1]
SCENE = ["mu", "Delta", "omega", "Omega", "alpha", "beta", "gamma", "R", "x_start", "v_start"]
SETTINGS = ["rtol", "max_step"]
CONTROL = [*GAIN_NAMES, "k_damping", *(f"{name}_start" for name in ESTIMATE_NAMES)]
REFERENCE_STARTS = ["x_ref_start", "v_ref_start"]
OAFM = ["oafm_order", "tau_star", "oafm_tau_end"]
STEP_ARGUMENTS = ("communicationStepSize", "currentCommunicationPoint")
MESSAGE = re.compile(r"parameter (\S+) = (\S+?):")

DEFAULTS = {**Scene().as_dict(), "v_start": 0.1, "rtol": 1e-8, "max_step": 0.05,
            **dict(zip(GAIN_NAMES, Gains().lambdas)), "k_damping": Gains().k_damping,
            **{f"{name}_start": value for name, value in zip(ESTIMATE_NAMES, ERRATA_INITIAL_ESTIMATES)}}
LOOP_DEFAULTS = {**DEFAULTS, **ERRATA_SCENE.as_dict(), "x_ref_start": ReferenceSettings().x_start,
                 "v_ref_start": ReferenceSettings().v_start}

nasty_real = st.sampled_from(NASTY)
# Huge finite steps are left out: the adaptive solver without max_step would take 10^6 steps (a minute)
# before its step budget stops it.
step_size = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, -1e300, 5e-324, 1e-300, 1e-9, 0.01,
                             0.1, 1.0, 10.0])


def mostly(good, bad):
    """good three times in four, else bad: most cases get past initialisation and exercise doStep."""
    return st.integers(0, 3).flatmap(lambda k: bad if k == 0 else good)


def real(name, defaults=DEFAULTS):
    return mostly(st.floats(0.5, 1.5).map(lambda f: f * defaults[name]), st.one_of(nasty_real, st.floats(-2.0, 2.0)))


def some(draw, names, max_size, defaults=DEFAULTS):
    """Values for up to max_size of names."""
    return {name: draw(real(name, defaults)) for name in draw(st.lists(st.sampled_from(names), max_size=max_size,
                                                                      unique=True))}


@st.composite
def start_values(draw):
    """Parameters to set: fidelity 4 keeps the default scene and OAFM settings valid or rejected at
    once (a new OAFM fit takes a second; the default one is packed in the FMU)."""
    fidelity = draw(mostly(st.sampled_from([0, 1, 2, 4]), st.sampled_from(NASTY_INTEGERS)))
    values = {"fidelity": fidelity, "solver": draw(mostly(st.sampled_from([0, 1]), st.sampled_from(NASTY_INTEGERS)))}
    if fidelity != 4:
        values.update(some(draw, SCENE, 3))
    values.update(some(draw, SETTINGS, 2))
    for name in draw(st.lists(st.sampled_from(OAFM), max_size=1)):
        values[name] = draw(st.sampled_from([-1, 0, 9, 100] if name == "oafm_order" else REJECTED_AT_ONCE))
    return values


@st.composite
def controller_values(draw):
    """The controller's parameters: law, gains, initial estimates and the plant model's parameters."""
    values = {"law": draw(mostly(st.sampled_from([0, 1, 2]), st.sampled_from(NASTY_INTEGERS)))}
    values.update(some(draw, CONTROL, 3))
    values.update(some(draw, [name for name in SCENE if name not in ("x_start", "v_start")], 2))
    return values


@st.composite
def loop_values(draw):
    """The closed loop's: the controller's and the plant's; the OAFM reference (0) keeps the default scene
    and reference start (its fit is packed in the FMU)."""
    values = draw(controller_values())
    values.update({"fidelity": draw(mostly(st.sampled_from([0, 1, 2]), st.sampled_from(NASTY_INTEGERS))),
                   "solver": draw(mostly(st.sampled_from([0, 1]), st.sampled_from(NASTY_INTEGERS))),
                   "reference": draw(mostly(st.sampled_from([0, 1, 2]), st.sampled_from(NASTY_INTEGERS)))})
    values.update(some(draw, SETTINGS, 2))
    if values["reference"] == 0:
        return {name: value for name, value in values.items() if name not in SCENE}
    values.update(some(draw, SCENE, 2, LOOP_DEFAULTS))
    values.update(some(draw, REFERENCE_STARTS, 1, LOOP_DEFAULTS))
    return values


def actions(inputs, parameters):
    """doStep, setting an input, setting a parameter after initialisation, a state round trip."""
    kinds = [st.tuples(st.just("step"), mostly(st.sampled_from([0.01, 0.1, 0.5]), step_size),
                       mostly(st.none(), st.sampled_from([math.nan, math.inf, -1.0, 1e-3, 5.0]))),
             st.tuples(st.just("set"), st.sampled_from(parameters), st.one_of(nasty_real, st.floats(-2.0, 2.0))),
             st.tuples(st.just("state"), st.none(), st.none())]
    if inputs:
        kinds.insert(1, st.tuples(st.just("input"), st.sampled_from(inputs), mostly(st.floats(-0.1, 0.1), nasty_real)))
    return st.lists(st.one_of(kinds), min_size=1, max_size=4)


CONTROLLER_PARAMETERS = CONTROL + ["law", "mu", "R"]
FMUS = {  # outputs, names a doStep error may give, start values, actions, cases
    "plant": (PLANT_OUTPUTS, ("U", "max_step"), start_values(),
              actions(["U"], SCENE + SETTINGS + OAFM + ["fidelity", "solver"]), MIN_CASES),
    "controller": (CONTROLLER_OUTPUTS, tuple(CONTROLLER_INPUTS), controller_values(),
                   actions(CONTROLLER_INPUTS, CONTROLLER_PARAMETERS), MIN_CONTROL_CASES),
    "closed_loop": (LOOP_OUTPUTS, ("max_step",), loop_values(),
                    actions([], CONTROLLER_PARAMETERS + SCENE + SETTINGS + REFERENCE_STARTS + ["reference"]),
                    MIN_CONTROL_CASES),
}


class Case:
    """One instance under test: each call's status and new error messages are checked."""

    def __init__(self, fmu, unzipped, variables, outputs):
        self.instance = FmuInstance(fmu, unzip_dir=unzipped)
        self.variables = variables
        self.outputs = outputs
        self.t = 0.0
        self.failed = False  # an fmi2Error happened: from now on the shim refuses most calls
        self.initialising = False  # in Initialization Mode: outputs follow the start values set so far

    def call(self, name, *args, expect=()):
        """Call fmu.name(*args); check the properties; return the status."""
        log = self.instance.log.messages
        before = len(log)
        try:
            getattr(self.instance.fmu, name)(*args)
            status = OK
        except FMICallException as error:
            status = error.status
        errors = [m for m in log[before:] if m.startswith(("[error]", "[fatal]"))]
        assert status in (OK, WARNING, ERROR), (name, args, status, errors)
        if status == ERROR:
            assert errors, (name, args)
            self._check_message(name, errors[-1], expect)
            self.failed = True
        else:
            assert not errors, (name, args, errors)
        if name == "enterInitializationMode":
            self.initialising = status != ERROR
        elif name == "exitInitializationMode":
            self.initialising = False
        if name != "setupExperiment":  # FMI 2.0: no getters in the instantiated state
            self._check_outputs(name, args, status)
        return status

    def _check_outputs(self, name, args, status):
        """After every call, failed ones included: the outputs read with fmi2OK are finite; a getter may fail
        (fmi2Error, with a message) only after a failed call, or in Initialization Mode when a parameter set so far
        breaks its rule (the message names it: the output cannot be defined), never with fmi2Fatal."""
        log = self.instance.log.messages
        before = len(log)
        try:
            outputs = self.instance.fmu.getReal(self.instance.value_references(self.outputs))
        except FMICallException as error:
            assert error.status == ERROR, (name, args, status, error.status)
            if status != ERROR:
                assert self.initialising and not self.failed, (name, args, status)
                errors = [m for m in log[before:] if m.startswith("[error]")]
                assert errors and all(" in the initialization mode state: " in m for m in errors), errors
                match = MESSAGE.search(errors[0])
                assert match and match.group(1) in self.variables, errors[0]
                self.failed = True
            return
        assert all(map(math.isfinite, outputs)), (name, args, status, outputs)

    def _check_message(self, call, message, expect):
        if self.failed:  # the shim's refusal, or a restored state saved after the error
            assert f"call fmi2{call[0].upper()}{call[1:]} not allowed after an error" in message \
                or "restored a state saved after an error" in message, message
            return
        if "simulation stopped: " in message:
            assert "tau = " in message, message
            return
        match = MESSAGE.search(message)
        assert match, message
        assert match.group(1) in self.variables or match.group(1) in STEP_ARGUMENTS, message
        if expect:
            assert match.group(1) in expect, (expect, message)

    def set(self, name, value):
        kind = self.variables[name]
        vr = [self.instance.variables[name].valueReference]
        if kind == "Integer":
            value = int(value) if math.isfinite(value) else -1
            return name, value, ("setInteger", vr, [value])
        return name, value, ("setReal", vr, [value])


def run_case(fmu, unzipped, variables, outputs, step_names, tolerance, values, actions):
    case = Case(fmu, unzipped, variables, outputs)
    try:
        case.call("setupExperiment", tolerance, 0.0, 200.0, expect=("rtol",))
        case.call("enterInitializationMode")
        for name, value in values.items():
            _, value, (setter, vr, vals) = case.set(name, value)
            case.call(setter, vr, vals, expect=(name,))
        case.call("exitInitializationMode")
        for kind, first, second in actions:
            if kind == "step":
                h, wrong_time = first, second
                t = case.t if wrong_time is None else wrong_time
                if case.call("doStep", t, h, expect=STEP_ARGUMENTS + step_names) == OK:
                    case.t = t + h
            elif kind == "input":
                case.call("setReal", case.instance.value_references([first]), [second], expect=(first,))
            elif kind == "set":  # fixed parameters: refused after initialisation, before it accepted
                name, value, (setter, vr, vals) = case.set(first, second)
                status = case.call(setter, vr, vals, expect=(name,))
                assert status == ERROR
            else:
                state = case.instance.fmu.getFMUstate()
                data = case.instance.fmu.serializeFMUstate(state)
                case.instance.fmu.freeFMUstate(state)
                restored = case.instance.fmu.deSerializeFMUstate(data)
                case.call("setFMUstate", restored)
                case.instance.fmu.freeFMUstate(restored)
    finally:
        case.instance.close()


# The other paths with fewer cases (the same properties; the default suite stays short): the pure-Python kernel of
# each pythonfmu FMU (kernel = 1) and the native FMUs (fmu_src/native/). The pure-Python closed loop steps 11 states
# in Python: fewest cases.
VARIANTS = {"compiled": None, "kernel1": {"plant": 100, "controller": 80, "closed_loop": 40},
            "native": {"plant": 200, "controller": 120, "closed_loop": 100}}


# The plant's pythonfmu FMU with its compiled kernel (the FMU most users run) gets the most cases, MIN_CASES, in
# the slow tier (test_fuzz_campaign_of_the_compiled_plant below): its cases fit OAFM solutions and choose rungs at
# initialisation: 2000 of them were the default suite's longest test by far (a seventh of its time). The default runs the
# first DEFAULT_PLANT_CASES of the same derandomized search (the same properties, every kind of action).
DEFAULT_PLANT_CASES = 500


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("which", FMUS)
def test_fuzz_bad_input_never_escapes_and_always_explains(request, which, variant, tmp_path):
    default = DEFAULT_PLANT_CASES if (which, variant) == ("plant", "compiled") else None
    fuzz_fmu(request, which, variant, tmp_path, default)


@pytest.mark.slow
def test_fuzz_campaign_of_the_compiled_plant(request, tmp_path):
    fuzz_fmu(request, "plant", "compiled", tmp_path, MIN_CASES)


def fuzz_fmu(request, which, variant, tmp_path, cases_wanted):
    """The fuzzing of one FMU (which: a key of FMUS) on one path (variant: a key of VARIANTS): at least
    cases_wanted cases, or the variant's (FMUS's when None)."""
    outputs, step_names, values_strategy, actions_strategy, min_cases = FMUS[which]
    if variant == "native":
        from fmpy import extract

        fmu = request.getfixturevalue(f"native_{which}_fmu")
        unzipped = extract(str(fmu), str(tmp_path / "unzipped"))
    else:
        fmu, unzipped = request.getfixturevalue(f"{which}_fmu"), request.getfixturevalue(f"{which}_unzipped")
    if variant == "kernel1":
        values_strategy = values_strategy.map(lambda values: {**values, "kernel": 1})
    if VARIANTS[variant] is not None:
        min_cases = VARIANTS[variant][which]
    if cases_wanted is not None:
        min_cases = cases_wanted
    set_hypothesis_home_dir(tmp_path / "hypothesis")  # its caches too go to a temporary folder
    variables = {v.name: v.type for v in read_model_description(str(fmu)).modelVariables}
    cases = []

    @settings(max_examples=min_cases, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(tolerance=mostly(st.none(), nasty_real), values=values_strategy, actions=actions_strategy)
    def fuzz(tolerance, values, actions):
        cases.append(1)
        run_case(fmu, unzipped, variables, outputs, step_names, tolerance, values, actions)

    started = time.perf_counter()
    fuzz()
    print(f"\nfuzz {which} {variant}: {len(cases)} cases in {time.perf_counter() - started:.1f} s")
    assert len(cases) >= min_cases
