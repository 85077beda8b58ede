"""The FMI state machine is ONE table (slave_support.STATE_TABLES, generated into fmu_src/fmi/fmi2_calls.h): FMI 2.0
co-simulation (read by the Python slaves, the status shim and the native FMUs), FMI 2.0 Model Exchange (fmi2_me.c
and fmi2_native.c) and FMI 3.0 both (fmi3_native.c).

- the tables against the standards' state machines, transcribed here independently of the project's data: FMI 2.0
  section 4.2.4 (co-simulation) and 3.2.3 (Model Exchange), FMI 3.0's state machine (as the Modelica Reference-FMUs
  encode both in their MASK_<call> definitions). A table may allow a call in fewer states than the standard (a
  refusal is always safe); every state it allows beyond the standard is listed in DEVIATIONS with its reason, and
  the list is exact (a deviation fixed or added fails the test until the list says so);
- the C layers consult nothing else: every exported FMI function that takes an instance asks the table first (its
  own mask, by name), and no FMI source compares the instance's state by hand, outside the few places listed in
  STATE_READS (each says why it is not a call-permission question).
"""
import re

from vibrofmu import paths
from vibrofmu.fmus.entry import importable

with importable(paths.FMU_SRC):
    from slave_support import (CONTINUOUS_TIME_MODE as CT, ERROR as ERR, EVENT_MODE as EV, GET_ANY_VARIABLE,
                               INITIALIZATION_MODE as INIT, INSTANTIATED as INST, STATE_TABLES, STEP_MODE as STEP,
                               TERMINATED as TERM)

# ---- the standards (states the FMUs never enter are left out: FMI 2.0's stepInProgress/stepFailed/stepCanceled --
# doStep is synchronous and ends in step mode or the error state --, FMI 3.0's configuration, reconfiguration,
# clock activation, intermediate update and step discarded modes) ----

ALL2 = {INST, INIT, EV, CT, STEP, TERM, ERR}
GETTERS2 = {INIT, EV, CT, STEP, TERM, ERR}  # 4.2.4 / 3.2.3: fmi2GetXXX from initialization mode on
FMI2_COMMON = {
    "fmi2SetDebugLogging": ALL2,
    "fmi2SetupExperiment": {INST},
    "fmi2EnterInitializationMode": {INST},
    "fmi2ExitInitializationMode": {INIT},
    "fmi2Terminate": {EV, CT, STEP},
    "fmi2Reset": ALL2,
    **{f"fmi2Get{kind}": GETTERS2 for kind in ("Real", "Integer", "Boolean", "String")},
    "fmi2SetReal": {INST, INIT, EV, CT, STEP},
    **{f"fmi2Set{kind}": {INST, INIT, EV, STEP} for kind in ("Integer", "Boolean", "String")},
    **{name: ALL2 for name in ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize",
                               "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate")},
    "fmi2GetDirectionalDerivative": GETTERS2,
}
FMI2_CS_ONLY = {
    "fmi2SetRealInputDerivatives": {INST, INIT, STEP},
    "fmi2GetRealOutputDerivatives": {STEP, TERM, ERR},
    "fmi2DoStep": {STEP},
    "fmi2CancelStep": set(),  # stepInProgress only
    **{f"fmi2Get{kind}Status": {STEP, TERM} for kind in ("", "Real", "Integer", "Boolean", "String")},
}
FMI2_ME_ONLY = {
    "fmi2EnterEventMode": {EV, CT},
    "fmi2NewDiscreteStates": {EV},
    "fmi2EnterContinuousTimeMode": {EV},
    "fmi2CompletedIntegratorStep": {CT},
    "fmi2SetTime": {EV, CT},
    "fmi2SetContinuousStates": {CT},
    "fmi2GetEventIndicators": {INIT, EV, CT, TERM, ERR},
    "fmi2GetContinuousStates": {INIT, EV, CT, TERM, ERR},
    "fmi2GetDerivatives": {EV, CT, TERM, ERR},
    "fmi2GetNominalsOfContinuousStates": {INST, EV, CT, TERM, ERR},
}

ALL3 = {INST, INIT, EV, STEP, CT, TERM}
TYPES3 = ("Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Boolean",
          "String", "Binary")
FMI3_COMMON = {
    "fmi3SetDebugLogging": ALL3,
    "fmi3EnterInitializationMode": {INST},
    "fmi3ExitInitializationMode": {INIT},
    "fmi3Reset": ALL3,
    **{f"fmi3Get{kind}": ALL3 for kind in TYPES3},
    **{f"fmi3Set{kind}": ALL3 if kind.startswith("Float") else ALL3 - {CT} for kind in TYPES3},
    **{f"fmi3{name}": ALL3 for name in (
        "GetClock", "SetClock", "GetIntervalDecimal", "GetIntervalFraction", "SetIntervalDecimal",
        "SetIntervalFraction", "GetShiftDecimal", "GetShiftFraction", "SetShiftDecimal", "SetShiftFraction",
        "GetNumberOfVariableDependencies", "GetVariableDependencies", "GetFMUState", "SetFMUState", "FreeFMUState",
        "SerializedFMUStateSize", "SerializeFMUState", "DeserializeFMUState", "GetNumberOfEventIndicators",
        "GetNumberOfContinuousStates")},
    "fmi3GetDirectionalDerivative": {INIT, EV, STEP, CT, TERM},
    "fmi3GetAdjointDerivative": {INIT, EV, STEP, CT, TERM},
    "fmi3EnterConfigurationMode": {INST, EV, STEP},
    "fmi3ExitConfigurationMode": set(),  # configuration / reconfiguration mode
    "fmi3ActivateModelPartition": set(),  # clock activation mode (Scheduled Execution only)
    "fmi3UpdateDiscreteStates": {EV},
    "fmi3EnterEventMode": {CT, STEP},
    "fmi3Terminate": {EV, CT, STEP},
}
FMI3_CS_ONLY = {
    "fmi3EnterStepMode": {INIT, EV},
    "fmi3GetOutputDerivatives": {STEP, TERM},
    "fmi3DoStep": {STEP},
}
FMI3_ME_ONLY = {
    "fmi3EnterContinuousTimeMode": {EV},
    "fmi3CompletedIntegratorStep": {CT},
    "fmi3SetTime": {EV, CT},
    "fmi3SetContinuousStates": {CT},
    **{f"fmi3{name}": {INIT, EV, CT, TERM} for name in (
        "GetContinuousStateDerivatives", "GetEventIndicators", "GetContinuousStates", "GetNominalsOfContinuousStates")},
}
# Calls the reference gives no mask for; these FMUs do not provide them (fmi3Error and why, in every state).
UNCITED3 = {"fmi3EvaluateDiscreteStates"}


def interface(common, own, states):
    return {**{call: allowed & states for call, allowed in common.items()}, **own}


STANDARD = {
    "FMI2": interface(FMI2_COMMON, FMI2_CS_ONLY, {INST, INIT, STEP, TERM, ERR}),
    "FMI2ME": interface(FMI2_COMMON, FMI2_ME_ONLY, {INST, INIT, EV, CT, TERM, ERR}),
    "FMI3CS": interface(FMI3_COMMON, FMI3_CS_ONLY, {INST, INIT, EV, STEP, TERM}),
    "FMI3ME": interface(FMI3_COMMON, FMI3_ME_ONLY, {INST, INIT, EV, CT, TERM}),
}
STATUS_GETTERS = [f"fmi2Get{kind}Status" for kind in ("", "Real", "Integer", "Boolean", "String")]
VALUE_GETTERS = [f"fmi2Get{kind}" for kind in ("Real", "Integer", "Boolean", "String")]
# (call, state) the project allows beyond the standard, and why
DEVIATIONS = {
    # the status flag fmi_status is read from fmi2Instantiate on (the status shim reads it after every call); any other
    # variable is refused there, per variable (GET_ANY_VARIABLE: checked below)
    "FMI2": {(call, INST) for call in VALUE_GETTERS}
    # fmi2CancelStep answers in every phase with fmi2Error and why (doStep is synchronous: nothing to cancel)
    | {("fmi2CancelStep", state) for state in (INST, INIT, STEP, TERM)}
    # the status queries change nothing: answered (fmi2Discard, or the last doStep's status) in every state
    | {(call, state) for call in STATUS_GETTERS for state in (INST, INIT, ERR)},
    "FMI2ME": {(call, INST) for call in VALUE_GETTERS},
    "FMI3CS": set(),
    "FMI3ME": set(),
}


def test_each_table_allows_a_call_only_where_the_standard_does():
    for prefix, (_, _, table) in STATE_TABLES.items():
        standard = STANDARD[prefix]
        beyond = {(call, state) for call, allowed in table.items() if call not in UNCITED3
                  for state in allowed if state not in standard.get(call, set())}
        assert beyond == DEVIATIONS[prefix], (prefix, beyond ^ DEVIATIONS[prefix])


def test_each_table_has_every_call_of_its_interface_and_no_other():
    for prefix, (_, _, table) in STATE_TABLES.items():
        assert set(table) - UNCITED3 == set(STANDARD[prefix]), (prefix, set(table) ^ set(STANDARD[prefix]))


def test_the_getters_read_any_variable_only_where_the_standard_allows_getters():
    """The getters' deviation (instantiated, for fmi_status) is confined to the status flag."""
    for prefix, states in GET_ANY_VARIABLE.items():
        assert set(states) == STANDARD[prefix]["fmi2GetReal"], prefix


# ---- the C layers ask the table, and nothing else ----

C_FILES = {name: paths.FMU_SRC / name for name in ("fmi2_status_shim.c", "native/fmi2_native.c", "native/fmi2_me.c",
                                                     "native/fmi3_native.c")}
# The calls' checks: the table's mask of the call itself, by name (macros: the name pasted from the generator's).
CHECK = re.compile(r"\b(?:ALLOWED|ME_CALL|W3_CALL)\((fmi[23][\w#]*)\)")
NO_INSTANCE = {"fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2Instantiate", "fmi2FreeInstance", "fmi3GetVersion",
               "fmi3InstantiateModelExchange", "fmi3InstantiateCoSimulation", "fmi3InstantiateScheduledExecution",
               "fmi3FreeInstance"}
# A comparison of the instance's state (its phase, Model Exchange mode, FMI 3.0 mode, the table's state) or a mask
# written by hand.
STATE_READ = re.compile(r"\bphase\s*(==|!=|<|>)|(==|!=)\s*PHASE_|\bmode\s*(==|!=)\s*(ME_|FMI2_(?!MODE_))"
                        r"|native_table_state\([^()]*\)\s*(==|!=)|(==|!=)\s*FMI2_(?!MODE_)[A-Z_]+\b|FMI2_BIT\(FMI2_")
# (file, function) where the state is read by hand, and why that is not a question of which call is allowed
STATE_READS = {
    # the accessor: the table's state of an instance (its phase; Model Exchange's mode while running)
    ("native/fmi2_native.c", "native_table_state"),
    # where an output's value comes from in initialization mode (the start values set so far), not whether it is read
    ("native/fmi2_native.c", "get_values"),
    # which refusal doStep logs in the terminated state (why the instance halted: StatusSlave._step_allowed's text)
    ("native/fmi2_native.c", "fmi2DoStep"),
    # a halted model (failed initialisation or step) has no current point to differentiate at; fmi2Terminate halts
    # too but leaves the point
    ("native/fmi2_me.c", "native_directional_derivative"),
    # a restored state's mode must be one of this instance's: co-simulation has event mode only with eventModeUsed
    ("native/fmi3_native.c", "fmi3SetFMUState"),
}


def functions(text):
    """(name, body) of each function definition in C source text (a definition: a line at column 0 ending a
    signature, then its braces), the FMI functions a macro defines included under the macro's pasted name."""
    found, name, depth, body = [], None, 0, []
    for line in text.splitlines():
        if name is None:
            m = re.match(r"(?:[A-Za-z_]\w*[\s\*]+)+([A-Za-z_][\w#]*)\s*\(", line)  # a type, then the name
            if m and not line.startswith((" ", "#", "/", "}")) and not line.rstrip().endswith(";"):
                name, depth, body = m.group(1), 0, []
            m = re.match(r"\s*EXPORT3?\s+\w+\s+(fmi[23][\w#]*)\(", line)  # inside a macro (GETTER, NO_TYPE, ...)
            if m and line.startswith(" "):
                name, depth, body = m.group(1), 0, []
        if name is not None:
            body.append(line)
            depth += line.count("{") - line.count("}")
            if depth <= 0 and "{" in "".join(body):
                found.append((name, "\n".join(body)))
                name = None
    return found


def test_every_fmi_function_asks_the_table_for_itself():
    for label, path in C_FILES.items():
        text = path.read_text()
        seen = set()
        for name, body in functions(text):
            seen.add(name)
            if not name.startswith(("fmi2", "fmi3")) or name in NO_INSTANCE:
                continue
            asked = CHECK.findall(body)
            assert asked[:1] == [name], f"{label}: {name} asks {asked or 'no table check'} first"
        exported = set(re.findall(r"EXPORT3?\s+[\w\s\*]+?\b(fmi[23][\w#]*)\(", text))
        assert exported <= seen, (label, exported - seen)  # the parser skipped no FMI function


def test_no_fmi_source_reads_the_state_by_hand():
    reads = set()
    for label, path in C_FILES.items():
        for name, body in functions(path.read_text()):
            if STATE_READ.search(body):
                reads.add((label, name))
    assert reads == STATE_READS


def test_the_state_scan_finds_a_hand_written_check():
    """The scan is not blind: the comparison the FMI 3.0 layer made before the table (w->mode == W_STEP in its
    idiom of today) is found."""
    assert STATE_READ.search("    if (w->mode == FMI2_STEP_MODE) return refuse(w, ...);")
    assert STATE_READ.search("    if (I->s.phase != PHASE_STEP_MODE && ...)")
    assert not STATE_READ.search("    if (L->mode == FMI2_MODE_FATAL) return fmi2Fatal;")  # the error mode


# The Python slaves' own comparisons of their phase (slave_support.StatusSlave): the functions that may compare it
# with a named state, each not a call-permission question (those ask the table: _allowed, CALLS[...]).
PYTHON_STATE_READS = {
    "_get_values",  # an output read in initialization mode is computed from the start values (what, not whether)
}
PY_STATE_READ = re.compile(r"self\.phase\s*(?:==|!=)")


def test_the_python_slaves_ask_the_table_not_the_phase():
    """Whether a call (doStep, a setter) is allowed is the table's answer in the Python slaves too: no function of
    slave_support.py compares the phase with a state by hand outside PYTHON_STATE_READS."""
    text = (paths.FMU_SRC / "slave_support.py").read_text()
    methods = re.finditer(r"\n    def (\w+)\(.*?(?=\n    def |\n\S|\Z)", text, flags=re.S)  # to the next def
    reads = {m.group(1) for m in methods if PY_STATE_READ.search(m.group(0))}
    assert reads == PYTHON_STATE_READS
    assert PY_STATE_READ.search("        if self.phase == TERMINATED:")  # the scan is not blind


def test_the_python_slaves_setters_and_do_step_follow_the_table(monkeypatch):
    """A table that allowed the setters in the terminated state would let a terminated slave take a parameter's
    value, and one that allowed doStep in the instantiated state would refuse it only for what the step itself
    lacks: the slaves read the table (slave_support.CALLS), not a state of their own."""
    with importable(paths.FMU_SRC):
        import slave_support
        from AdaptiveLyapunovController import AdaptiveLyapunovController

        slave = AdaptiveLyapunovController(instance_name="table")
        logged = []
        monkeypatch.setattr(slave, "log", lambda message, status=None: logged.append(message))
        var = next(v for v in slave.vars.values() if v.name == "kernel")  # a parameter
        slave.phase = slave_support.TERMINATED
        assert slave._set_refusal(var) == "no variable may be set in the terminated state (FMI 2.0)"
        monkeypatch.setitem(slave_support.CALLS, "fmi2SetReal", slave_support.PHASES)
        assert slave._set_refusal(var) is None
        slave.phase = slave_support.INSTANTIATED
        assert not slave._step_allowed(0.0, 0.1) and "fmi2DoStep is not allowed in the instantiated state" in logged[-1]
        monkeypatch.setitem(slave_support.CALLS, "fmi2DoStep", slave_support.PHASES)
        assert slave._step_allowed(0.0, 0.1)
