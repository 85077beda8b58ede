"""Bad-input fuzzing of the plant FMU with hypothesis, through FMPy, in this process.

One extracted FMU; each generated case instantiates it, sets parameters (NaN, +-inf, 0, -0, negative,
huge, tiny or plausible values), initialises, and runs a few actions: doStep with good or bad step
sizes and current times, input values, setting parameters after initialisation, a state round trip.
Properties of every call: it returns a status and never fmi2Fatal (no exception escaped to
pythonfmu); after fmi2OK the outputs are finite; every fmi2Error comes with an error message that
names the variable (or step argument) and its value, or says why the simulation stopped, or is the
shim's refusal after an earlier error. derandomize: the same cases in every run; database=None:
nothing written outside the temporary folders.
"""
import math
import re
import time

from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir

from vibrofmu.run import FmuInstance
from vibromodel.parameters import Scene

OK, WARNING, ERROR, FATAL = 0, 1, 3, 4
MIN_CASES = 2000
OUTPUTS = ["x", "v", "a", "F_contact", "F_electrostatic"]
NASTY = [math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, -1e300, 1e300, 5e-324, 1e-300, 1.7976931348623157e308]
REJECTED_AT_ONCE = [math.nan, math.inf, -math.inf, -1.0, -1e300]  # OAFM domains: valid ones mean a new fit
NASTY_INTEGERS = [-2**31, -1, 0, 1, 2, 3, 4, 5, 9, 2**31 - 1]
SCENE = ["mu", "Delta", "omega", "Omega", "alpha", "beta", "gamma", "R", "x_start", "v_start"]
SETTINGS = ["rtol", "max_step"]
OAFM = ["oafm_order", "tau_star", "oafm_tau_end"]
STEP_ARGUMENTS = ("communicationStepSize", "currentCommunicationPoint")
MESSAGE = re.compile(r"parameter (\S+) = (\S+?):")

DEFAULTS = {**Scene().as_dict(), "v_start": 0.1, "rtol": 1e-8, "max_step": 0.05}

nasty_real = st.sampled_from(NASTY)
# Huge finite steps are left out: the adaptive solver without max_step would take 10^6 steps (a minute)
# before its step budget stops it.
step_size = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, -1.0, -1e300, 5e-324, 1e-300, 1e-9, 0.01,
                             0.1, 1.0, 10.0])


def mostly(good, bad):
    """good three times in four, else bad: most cases get past initialisation and exercise doStep."""
    return st.integers(0, 3).flatmap(lambda k: bad if k == 0 else good)


def real(name):
    return mostly(st.floats(0.5, 1.5).map(lambda f: f * DEFAULTS[name]), st.one_of(nasty_real, st.floats(-2.0, 2.0)))


@st.composite
def start_values(draw):
    """Parameters to set: fidelity 4 keeps the default scene and OAFM settings valid or rejected at
    once (a new OAFM fit takes a second; the default one is packed in the FMU)."""
    fidelity = draw(mostly(st.sampled_from([0, 1, 2, 4]), st.sampled_from(NASTY_INTEGERS)))
    values = {"fidelity": fidelity, "solver": draw(mostly(st.sampled_from([0, 1]), st.sampled_from(NASTY_INTEGERS)))}
    if fidelity != 4:
        for name in draw(st.lists(st.sampled_from(SCENE), max_size=3, unique=True)):
            values[name] = draw(real(name))
    for name in draw(st.lists(st.sampled_from(SETTINGS), max_size=2, unique=True)):
        values[name] = draw(real(name))
    for name in draw(st.lists(st.sampled_from(OAFM), max_size=1)):
        values[name] = draw(st.sampled_from([-1, 0, 9, 100] if name == "oafm_order" else REJECTED_AT_ONCE))
    return values


action = st.one_of(
    st.tuples(st.just("step"), mostly(st.sampled_from([0.01, 0.1, 0.5]), step_size),
              mostly(st.none(), st.sampled_from([math.nan, math.inf, -1.0, 1e-3, 5.0]))),
    st.tuples(st.just("input"), mostly(st.floats(-0.1, 0.1), nasty_real)),
    st.tuples(st.just("set"), st.sampled_from(SCENE + SETTINGS + OAFM + ["fidelity", "solver"]),
              st.one_of(nasty_real, st.floats(-2.0, 2.0))),
    st.tuples(st.just("state"), st.none()),
)


class Case:
    """One instance under test: each call's status and new error messages are checked."""

    def __init__(self, fmu, unzipped, variables):
        self.instance = FmuInstance(fmu, unzip_dir=unzipped)
        self.variables = variables
        self.t = 0.0
        self.failed = False  # an fmi2Error happened: from now on the shim refuses most calls

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
            outputs = self.instance.fmu.getReal(self.instance.value_references(OUTPUTS))
            assert all(map(math.isfinite, outputs)), (name, args, outputs)
        return status

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


def run_case(fmu, unzipped, variables, tolerance, values, actions):
    case = Case(fmu, unzipped, variables)
    try:
        case.call("setupExperiment", tolerance, 0.0, 200.0, expect=("rtol",))
        case.call("enterInitializationMode")
        for name, value in values.items():
            _, value, (setter, vr, vals) = case.set(name, value)
            case.call(setter, vr, vals, expect=(name,))
        case.call("exitInitializationMode")
        for kind, *args in actions:
            if kind == "step":
                h, wrong_time = args
                t = case.t if wrong_time is None else wrong_time
                if case.call("doStep", t, h, expect=STEP_ARGUMENTS + ("U", "max_step")) == OK:
                    case.t = t + h
            elif kind == "input":
                case.call("setReal", case.instance.value_references(["U"]), [args[0]])
            elif kind == "set":  # fixed parameters: refused after initialisation, before it accepted
                name, value, (setter, vr, vals) = case.set(*args)
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


def test_fuzz_bad_input_never_escapes_and_always_explains(plant_fmu, plant_unzipped, tmp_path):
    set_hypothesis_home_dir(tmp_path / "hypothesis")  # its caches too go to a temporary folder
    variables = {v.name: v.type for v in read_model_description(str(plant_fmu)).modelVariables}
    cases = []

    @settings(max_examples=MIN_CASES, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(tolerance=mostly(st.none(), nasty_real), values=start_values(),
           actions=st.lists(action, min_size=1, max_size=4))
    def fuzz(tolerance, values, actions):
        cases.append(1)
        run_case(plant_fmu, plant_unzipped, variables, tolerance, values, actions)

    started = time.perf_counter()
    fuzz()
    print(f"\nfuzz: {len(cases)} cases in {time.perf_counter() - started:.1f} s")
    assert len(cases) >= MIN_CASES
