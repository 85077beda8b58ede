"""Pointer arguments and instance pointers a clumsy or hostile host passes, called through ctypes in the probe host's
subprocess (`python -m vibrofmu.hosts.probe pointers FMU` for FMI 2.0, `pointers3 FMU` for FMI 3.0), so that a
crash is counted rather than suffered:
  - every FMI function with an array argument called with that array NULL and n > 0, and with every result pointer
    NULL: fmi2Error / fmi3Error and a log line naming the function and the argument, the instance usable after;
  - NULL arrays with n = 0 (allowed: nothing to read or write);
  - a freed instance, a pointer that is no instance (a buffer of garbage) and a second FreeInstance: refused or
    ignored, never used.
One JSON line per case: {"case", "call", "argument", "status", "expected", "log"}; "argument" is the word the log
line must name (None: no log line expected, e.g. for a pointer that is no instance: there is no logger to use).
"""
from __future__ import annotations

import ctypes

from vibrofmu.hosts.forge import emit

OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
MODEL_EXCHANGE, CO_SIMULATION = 0, 1
c_double_p, c_uint_p, c_int_p = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_uint), \
    ctypes.POINTER(ctypes.c_int)
V, S = ctypes.c_void_p, ctypes.c_size_t


def _declare(lib, spec: dict[str, list]) -> None:
    for name, argtypes in spec.items():
        function = getattr(lib, name, None)
        if function is not None:
            function.argtypes = argtypes
            function.restype = ctypes.c_int


FMI2 = {
    "fmi2SetDebugLogging": [V, ctypes.c_int, S, V],
    "fmi2GetReal": [V, V, S, V], "fmi2GetInteger": [V, V, S, V], "fmi2GetBoolean": [V, V, S, V],
    "fmi2GetString": [V, V, S, V], "fmi2SetReal": [V, V, S, V], "fmi2SetInteger": [V, V, S, V],
    "fmi2SetBoolean": [V, V, S, V], "fmi2SetString": [V, V, S, V],
    "fmi2GetStatus": [V, ctypes.c_int, V], "fmi2GetRealStatus": [V, ctypes.c_int, V],
    "fmi2GetIntegerStatus": [V, ctypes.c_int, V], "fmi2GetBooleanStatus": [V, ctypes.c_int, V],
    "fmi2GetStringStatus": [V, ctypes.c_int, V],
    "fmi2GetDirectionalDerivative": [V, V, S, V, S, V, V],
    "fmi2SetRealInputDerivatives": [V, V, S, V, V], "fmi2GetRealOutputDerivatives": [V, V, S, V, V],
    "fmi2DoStep": [V, ctypes.c_double, ctypes.c_double, ctypes.c_int],
    "fmi2GetDerivatives": [V, V, S], "fmi2GetEventIndicators": [V, V, S], "fmi2GetContinuousStates": [V, V, S],
    "fmi2SetContinuousStates": [V, V, S], "fmi2GetNominalsOfContinuousStates": [V, V, S],
    "fmi2NewDiscreteStates": [V, V], "fmi2CompletedIntegratorStep": [V, ctypes.c_int, V, V],
    "fmi2EnterContinuousTimeMode": [V], "fmi2EnterEventMode": [V], "fmi2SetTime": [V, ctypes.c_double],
}


def _buffers(n: int = 4):
    vr = (ctypes.c_uint * n)(*range(n))
    return vr, (ctypes.c_double * n)(), (ctypes.c_int * n)(), (ctypes.c_char_p * n)(*([b""] * n))


def _case(probe, case: str, call: str, argument: str | None, status: int, expected: int = ERROR) -> None:
    emit(case=case, call=call, argument=argument, status=status, expected=expected, log=probe.take_log())


def _array_cases(probe, c) -> None:
    """The variable getters and setters, the logging categories, the status family, the derivatives."""
    f = probe.lib
    _declare(f, FMI2)
    vr, real, integer, text = _buffers()
    a_real = probe.real_output_vr()
    vr[0] = vr[1] = a_real
    for kind, values in (("Real", real), ("Integer", integer), ("Boolean", integer), ("String", text)):
        for direction in ("Get", "Set"):
            call = f"fmi2{direction}{kind}"
            _case(probe, f"{call}(vr NULL)", call, "vr", getattr(f, call)(c, None, 2, values))
            _case(probe, f"{call}(value NULL)", call, "value", getattr(f, call)(c, vr, 2, None))
            _case(probe, f"{call}(both NULL, n = 0)", call, None, getattr(f, call)(c, None, 0, None), OK)
    _case(probe, "fmi2SetDebugLogging(categories NULL)", "fmi2SetDebugLogging", "cats",
          f.fmi2SetDebugLogging(c, 1, 2, None))
    for name in ("Status", "RealStatus", "IntegerStatus", "BooleanStatus", "StringStatus"):
        call = f"fmi2Get{name}"
        _case(probe, f"{call}(value NULL)", call, "value", getattr(f, call)(c, 0, None))
    seed = (ctypes.c_double * 2)(1.0, 0.0)
    dd = f.fmi2GetDirectionalDerivative
    for label, args in (("vUnknown", (None, 1, vr, 1, seed, real)), ("dvUnknown", (vr, 1, vr, 1, seed, None)),
                        ("vKnown", (vr, 1, None, 1, seed, real)), ("dvKnown", (vr, 1, vr, 1, None, real))):
        _case(probe, f"fmi2GetDirectionalDerivative({label} NULL)", "fmi2GetDirectionalDerivative",
              {"vUnknown": "vU", "dvUnknown": "dvU", "vKnown": "vK", "dvKnown": "dvK"}[label], dd(c, *args))
    order = (ctypes.c_int * 2)(1, 1)
    for call in ("fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives"):
        _case(probe, f"{call}(vr NULL)", call, "vr", getattr(f, call)(c, None, 1, order, real))
        _case(probe, f"{call}(order NULL)", call, "order", getattr(f, call)(c, vr, 1, None, real))
        _case(probe, f"{call}(value NULL)", call, "value", getattr(f, call)(c, vr, 1, order, None))


def _instance_cases(probe, make) -> None:
    """A pointer that is no instance, a freed one, a second FreeInstance (make() -> a fresh live instance)."""
    f = probe.lib
    garbage = ctypes.create_string_buffer(b"\xab" * 65536)
    address = ctypes.addressof(garbage)
    vr, real, _, _ = _buffers()
    vr[0] = probe.real_output_vr()
    _case(probe, "fmi2GetReal(not an instance)", "fmi2GetReal", None, f.fmi2GetReal(address, vr, 1, real))
    _case(probe, "fmi2DoStep(not an instance)", "fmi2DoStep", None, f.fmi2DoStep(address, 0.0, 0.1, 1))
    f.fmi2FreeInstance(address)
    emit(case="fmi2FreeInstance(not an instance)", call="fmi2FreeInstance", argument=None, status=OK, expected=OK,
         log=probe.take_log())
    c = make()
    f.fmi2FreeInstance(c)
    probe.take_log()
    _case(probe, "fmi2GetReal(freed)", "fmi2GetReal", None, f.fmi2GetReal(c, vr, 1, real))
    _case(probe, "fmi2DoStep(freed)", "fmi2DoStep", None, f.fmi2DoStep(c, 0.0, 0.1, 1))
    f.fmi2FreeInstance(c)  # a second free: ignored
    emit(case="second fmi2FreeInstance", call="fmi2FreeInstance", argument=None, status=OK, expected=OK,
         log=probe.take_log())


def scenario_pointers(probe) -> None:
    """FMI 2.0 co-simulation (every FMU) and, where the FMU offers it, Model Exchange."""
    f = probe.lib
    c = probe.start()
    emit(case="start", ok=bool(c), log=probe.take_log())
    if not c:
        return
    _array_cases(probe, c)
    status, x = probe.steps(c, 0.0, 3)
    emit(case="doStep after the refusals", call="fmi2DoStep", argument=None, status=status, expected=OK, x=x,
         log=probe.take_log())
    f.fmi2FreeInstance(c)
    if probe.md.modelExchange is not None:
        _model_exchange_cases(probe)
    _instance_cases(probe, probe.start)


def _model_exchange_cases(probe) -> None:
    """The Model Exchange calls' arrays and result pointers, each on a fresh instance (a refusal there is an error
    of the instance: the next one's log line is its own)."""
    f = probe.lib
    nx, ni = len(probe.md.derivatives), probe.md.numberOfEventIndicators
    info, flag = ctypes.create_string_buffer(64), ctypes.c_int(0)

    def me(continuous: bool = False):
        c = probe.instantiate(probe.resources_uri(), kind=MODEL_EXCHANGE)
        f.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0)
        f.fmi2EnterInitializationMode(c)
        f.fmi2ExitInitializationMode(c)
        if continuous:
            f.fmi2NewDiscreteStates(c, info)
            f.fmi2EnterContinuousTimeMode(c)
        probe.take_log()
        return c

    # (call, in continuous-time mode, the call, its array's size: NULL with size 0 is fine, fmi2OK)
    cases = [(call, False, lambda c, call=call, n=n: getattr(f, call)(c, None, n), n)
             for call, n in (("fmi2GetEventIndicators", ni), ("fmi2GetContinuousStates", nx),
                             ("fmi2GetNominalsOfContinuousStates", nx), ("fmi2GetDerivatives", nx))]
    cases += [("fmi2NewDiscreteStates", False, lambda c: f.fmi2NewDiscreteStates(c, None), 1),
              ("fmi2SetContinuousStates", True, lambda c: f.fmi2SetContinuousStates(c, None, nx), nx),
              ("fmi2CompletedIntegratorStep", True,
               lambda c: f.fmi2CompletedIntegratorStep(c, 1, None, ctypes.byref(flag)), 1)]
    for call, continuous, make_call, n in cases:
        c = me(continuous)
        _case(probe, f"{call}(NULL)", call, "NULL" if n else None, make_call(c), ERROR if n else OK)
        f.fmi2FreeInstance(c)


# ---- FMI 3.0 ----

FMI3 = {
    "fmi3InstantiateCoSimulation": None, "fmi3InstantiateModelExchange": None,
    "fmi3EnterInitializationMode": [V, ctypes.c_bool, ctypes.c_double, ctypes.c_double, ctypes.c_bool,
                                    ctypes.c_double],
    "fmi3ExitInitializationMode": [V], "fmi3EnterStepMode": [V], "fmi3EnterContinuousTimeMode": [V],
    "fmi3GetFloat64": [V, V, S, V, S], "fmi3SetFloat64": [V, V, S, V, S], "fmi3GetInt32": [V, V, S, V, S],
    "fmi3SetInt32": [V, V, S, V, S], "fmi3GetBoolean": [V, V, S, V, S], "fmi3SetBoolean": [V, V, S, V, S],
    "fmi3GetString": [V, V, S, V, S], "fmi3SetString": [V, V, S, V, S],
    "fmi3SetDebugLogging": [V, ctypes.c_bool, S, V],
    "fmi3DoStep": [V, ctypes.c_double, ctypes.c_double, ctypes.c_bool, V, V, V, V],
    "fmi3GetFMUState": [V, V], "fmi3SetFMUState": [V, V], "fmi3FreeFMUState": [V, V],
    "fmi3SerializedFMUStateSize": [V, V, V], "fmi3SerializeFMUState": [V, V, V, S],
    "fmi3DeserializeFMUState": [V, V, S, V],
    "fmi3GetDirectionalDerivative": [V, V, S, V, S, V, S, V, S],
    "fmi3GetContinuousStateDerivatives": [V, V, S], "fmi3GetEventIndicators": [V, V, S],
    "fmi3GetContinuousStates": [V, V, S], "fmi3SetContinuousStates": [V, V, S],
    "fmi3GetNominalsOfContinuousStates": [V, V, S], "fmi3GetNumberOfEventIndicators": [V, V],
    "fmi3GetNumberOfContinuousStates": [V, V], "fmi3CompletedIntegratorStep": [V, ctypes.c_bool, V, V],
    "fmi3UpdateDiscreteStates": [V, V, V, V, V, V, V], "fmi3Reset": [V], "fmi3Terminate": [V],
}
LOG3 = ctypes.CFUNCTYPE(None, V, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)


class Probe3:
    """One FMI 3.0 FMU's binary loaded with ctypes, its log collected."""

    def __init__(self, unzipped, md):
        from pathlib import Path

        self.unzipped, self.md = Path(unzipped), md
        identifier = (md.coSimulation or md.modelExchange).modelIdentifier
        self.lib = ctypes.CDLL(str(self.unzipped / "binaries" / "x86_64-linux" / f"{identifier}.so"))
        self.log: list[str] = []
        self.logger = LOG3(lambda env, status, category, message: self.log.append(
            f"[{status}] {(message or b'').decode(errors='replace')}"))
        _declare(self.lib, {k: v for k, v in FMI3.items() if v is not None})
        self.lib.fmi3InstantiateCoSimulation.restype = V
        self.lib.fmi3InstantiateCoSimulation.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p,
                                                         ctypes.c_bool, ctypes.c_bool, ctypes.c_bool, ctypes.c_bool,
                                                         V, S, V, LOG3, V]
        self.lib.fmi3InstantiateModelExchange.restype = V
        self.lib.fmi3InstantiateModelExchange.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p,
                                                          ctypes.c_bool, ctypes.c_bool, V, LOG3]
        self.lib.fmi3FreeInstance.argtypes = [V]
        self.lib.fmi3FreeInstance.restype = None

    def take_log(self) -> list[str]:
        log, self.log = self.log, []
        return log

    def real_output_vr(self) -> int:
        return next(v.valueReference for v in self.md.modelVariables if v.causality == "output"
                    and v.type == "Float64")

    def start(self, model_exchange: bool = False, event_mode: bool = False):
        """An instance after fmi3ExitInitializationMode (co-simulation: in step mode), or None."""
        f, resources = self.lib, str(self.unzipped / "resources") + "/"
        token = self.md.instantiationToken.encode()
        if model_exchange:
            c = f.fmi3InstantiateModelExchange(b"probe", token, resources.encode(), False, False, None, self.logger)
        else:
            c = f.fmi3InstantiateCoSimulation(b"probe", token, resources.encode(), False, False, event_mode, False,
                                              None, 0, None, self.logger, None)
        if not c:
            return None
        f.fmi3EnterInitializationMode(c, False, 0.0, 0.0, False, 0.0)
        if f.fmi3ExitInitializationMode(c) > WARNING:
            f.fmi3FreeInstance(c)
            return None
        return c


def scenario_pointers3(probe: Probe3) -> None:
    """FMI 3.0: each refusal on a fresh instance (an FMI 3.0 refusal is an error of the instance)."""
    f = probe.lib
    c = probe.start()
    emit(case="start", ok=bool(c), log=probe.take_log())
    if not c:
        return
    f.fmi3FreeInstance(c)
    vr, real, integer, text = _buffers()
    vr[0] = vr[1] = probe.real_output_vr()
    flags = (ctypes.c_bool * 4)()
    b, t, size = ctypes.c_bool(), ctypes.c_double(), ctypes.c_size_t()

    def once(case, call, argument, make_call, model_exchange=False, expected=ERROR):
        c = probe.start(model_exchange=model_exchange)
        _case(probe, case, call, argument, make_call(c), expected)
        f.fmi3FreeInstance(c)

    for kind, values in (("Float64", real), ("Int32", integer), ("Boolean", flags), ("String", text)):
        for direction in ("Get", "Set"):
            call = f"fmi3{direction}{kind}"
            once(f"{call}(valueReferences NULL)", call, "valueReferences",
                 lambda c, call=call, values=values: getattr(f, call)(c, None, 2, values, 2))
            once(f"{call}(values NULL)", call, "values", lambda c, call=call: getattr(f, call)(c, vr, 2, None, 2))
    once("fmi3SetDebugLogging(categories NULL)", "fmi3SetDebugLogging", "categories",
         lambda c: f.fmi3SetDebugLogging(c, True, 2, None))
    once("fmi3DoStep(outputs NULL)", "fmi3DoStep", "NULL",
         lambda c: f.fmi3DoStep(c, 0.0, 0.1, True, None, None, None, None))
    once("fmi3GetFMUState(NULL)", "fmi3GetFMUState", "NULL", lambda c: f.fmi3GetFMUState(c, None))
    once("fmi3SerializedFMUStateSize(NULL)", "fmi3SerializedFMUStateSize", "NULL",
         lambda c: f.fmi3SerializedFMUStateSize(c, None, ctypes.byref(size)))
    once("fmi3DeserializeFMUState(NULL)", "fmi3DeserializeFMUState", "NULL",
         lambda c: f.fmi3DeserializeFMUState(c, None, 100, ctypes.byref(ctypes.c_void_p())))
    if probe.md.modelExchange is not None:
        nx, ni = len(probe.md.derivatives), probe.md.numberOfEventIndicators
        for call, n in (("fmi3GetEventIndicators", ni), ("fmi3GetContinuousStates", nx),
                        ("fmi3GetNominalsOfContinuousStates", nx), ("fmi3GetContinuousStateDerivatives", nx)):
            once(f"{call}(NULL)", call, "NULL" if n else None, lambda c, call=call, n=n: getattr(f, call)(c, None, n),
                 True, ERROR if n else OK)  # NULL with size 0 (a model without event indicators) is fine
        for call in ("fmi3GetNumberOfEventIndicators", "fmi3GetNumberOfContinuousStates"):
            once(f"{call}(NULL)", call, "NULL", lambda c, call=call: getattr(f, call)(c, None), True)
        once("fmi3UpdateDiscreteStates(NULL)", "fmi3UpdateDiscreteStates", "NULL",
             lambda c: f.fmi3UpdateDiscreteStates(c, None, None, None, None, None, None), True)
    c = probe.start()
    status = f.fmi3DoStep(c, 0.0, 0.1, True, ctypes.byref(b), ctypes.byref(b), ctypes.byref(b), ctypes.byref(t))
    emit(case="fmi3DoStep after the refusals", call="fmi3DoStep", argument=None, status=status, expected=OK,
         log=probe.take_log())
    f.fmi3FreeInstance(c)
    # instance pointers: not an instance, freed, freed twice
    garbage = ctypes.create_string_buffer(b"\xab" * 65536)
    address = ctypes.addressof(garbage)
    _case(probe, "fmi3GetFloat64(not an instance)", "fmi3GetFloat64", None, f.fmi3GetFloat64(address, vr, 1, real, 1))
    f.fmi3FreeInstance(address)
    emit(case="fmi3FreeInstance(not an instance)", call="fmi3FreeInstance", argument=None, status=OK, expected=OK,
         log=probe.take_log())
    c = probe.start()
    f.fmi3FreeInstance(c)
    probe.take_log()
    _case(probe, "fmi3GetFloat64(freed)", "fmi3GetFloat64", None, f.fmi3GetFloat64(c, vr, 1, real, 1))
    _case(probe, "fmi3DoStep(freed)", "fmi3DoStep", None, f.fmi3DoStep(c, 0.0, 0.1, True, ctypes.byref(b),
                                                                       ctypes.byref(b), ctypes.byref(b),
                                                                       ctypes.byref(t)))
    f.fmi3FreeInstance(c)
    emit(case="second fmi3FreeInstance", call="fmi3FreeInstance", argument=None, status=OK, expected=OK,
         log=probe.take_log())


# ---- FMU states: the Model Exchange block forged, states of another FMU or freed ----

def _serialize(probe, c, state) -> bytes:
    f = probe.lib
    size = ctypes.c_size_t(0)
    f.fmi2SerializedFMUstateSize(c, state, ctypes.byref(size))
    buffer = ctypes.create_string_buffer(size.value)
    f.fmi2SerializeFMUstate(c, state, buffer, size.value)
    return buffer.raw


def _restore(probe, c, data: bytes) -> tuple[int, int]:
    """(deserialize status, set status; -1: not reached)"""
    f = probe.lib
    state = ctypes.c_void_p()
    st = f.fmi2DeSerializeFMUstate(c, data, len(data), ctypes.byref(state))
    if st > WARNING:
        return st, -1
    status = f.fmi2SetFMUstate(c, state)
    f.fmi2FreeFMUstate(c, ctypes.byref(state))
    return st, status


def scenario_me_block(probe) -> None:
    """A native FMU with Model Exchange: the ME block of a serialized state (me_data.h: mode, stopped, t, x[],
    event_pending, event_t, reached, step_event, locals_stale) found by its values in a Model Exchange instance's
    state (continuous-time mode, known states), each field forged with the checksum recomputed, restored into a
    Model Exchange and a Co-Simulation instance: {"case", "instance", "deserialize", "set", "after", "log"}; after:
    what the instance then answers (x and its status; a refused state leaves the instance as it was)."""
    import struct

    from vibrofmu.hosts.forge import NATIVE_HEADER, fnv1a

    f = probe.lib
    _declare(f, FMI2)
    info = ctypes.create_string_buffer(64)
    nx = len(probe.md.derivatives)

    def me_instance():
        c = probe.instantiate(probe.resources_uri(), kind=MODEL_EXCHANGE)
        f.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0)
        f.fmi2EnterInitializationMode(c)
        f.fmi2ExitInitializationMode(c)
        f.fmi2NewDiscreteStates(c, info)
        f.fmi2EnterContinuousTimeMode(c)
        return c

    me = me_instance()
    x = (ctypes.c_double * nx)()
    f.fmi2GetContinuousStates(me, x, nx)
    x[0], x[1] = 0.123456789, 0.987654321  # distinctive values to find the block by
    f.fmi2SetTime(me, 0.5)
    f.fmi2SetContinuousStates(me, x, nx)
    state = ctypes.c_void_p()
    f.fmi2GetFMUstate(me, ctypes.byref(state))
    data = _serialize(probe, me, state)
    f.fmi2FreeFMUstate(me, ctypes.byref(state))
    pattern = struct.pack("<qqddd", 2, 0, 0.5, x[0], x[1])  # mode ME_CONTINUOUS_TIME_MODE, stopped 0, t, x[0], x[1]
    payload = data[NATIVE_HEADER:]
    where = payload.find(pattern)
    emit(case="found the block", ok=where >= 0 and payload.count(pattern) == 1, log=probe.take_log())
    if where < 0:
        return
    n_max = 16  # ME_MAX_STATES
    offsets = {"mode": 0, "stopped": 8, "t": 16, "x[0]": 24, "x[1]": 32, "x[15]": 24 + 8 * 15}
    tail = 24 + 8 * n_max
    offsets.update({"event_pending": tail, "event_t": tail + 8, "reached": tail + 16, "step_event": tail + 24,
                    "locals_stale": tail + 32})
    forgeries = [("mode", "<q", 7), ("mode", "<q", -1), ("stopped", "<q", 5), ("t", "<d", float("inf")),
                 ("x[0]", "<d", float("nan")), ("x[1]", "<d", float("inf")), ("x[15]", "<d", float("nan")),
                 ("x[0]", "<d", 5.0), ("x[0]", "<d", -9.0), ("event_pending", "<q", 2), ("event_t", "<d", float("nan")),
                 ("reached", "<d", float("-inf")), ("step_event", "<q", 2**62), ("locals_stale", "<q", -1)]

    def forged(base: bytes, changes) -> bytes:
        body = bytearray(base[NATIVE_HEADER:])
        for field, fmt, value in changes:
            body[where + offsets[field]:where + offsets[field] + 8] = struct.pack(fmt, value)
        header = bytearray(base[:NATIVE_HEADER])
        header[72:80] = struct.pack("<Q", fnv1a(bytes(body)))
        return bytes(header + body)

    def answer(c, model_exchange: bool):
        if model_exchange:
            out = (ctypes.c_double * nx)()
            return f.fmi2GetContinuousStates(c, out, nx), out[0]
        status, value = probe.steps(c, 0.5, 1)  # a doStep from where the state is, then x
        return status, value

    cs = probe.start()
    f.fmi2DoStep(cs, 0.0, 0.5, 1)
    cs_state = ctypes.c_void_p()
    f.fmi2GetFMUstate(cs, ctypes.byref(cs_state))
    cs_data = _serialize(probe, cs, cs_state)
    f.fmi2FreeFMUstate(cs, ctypes.byref(cs_state))
    f.fmi2FreeInstance(cs)
    probe.take_log()
    for field, fmt, value in forgeries:
        for kind, base in (("ME", data), ("CS", cs_data)):
            c = me_instance() if kind == "ME" else probe.start()
            if kind == "CS":
                f.fmi2DoStep(c, 0.0, 0.5, 1)
            probe.take_log()
            changes = [(field, fmt, value)] if kind == "ME" else [("mode", "<q", 2), (field, fmt, value)]
            deserialize, status = _restore(probe, c, forged(base, changes))
            after = answer(c, kind == "ME")
            emit(case=f"{field} = {value!r}", instance=kind, deserialize=deserialize, set=status, after=after,
                 log=probe.take_log())
            f.fmi2FreeInstance(c)
    # each interface's own state given to the other's instance
    cs = probe.start()
    probe.take_log()
    emit(case="an ME state into a CS instance", instance="CS", **dict(zip(("deserialize", "set"),
                                                                            _restore(probe, cs, data))),
         after=answer(cs, False), log=probe.take_log())
    f.fmi2FreeInstance(cs)
    me2 = me_instance()
    probe.take_log()
    emit(case="a CS state into an ME instance", instance="ME", **dict(zip(("deserialize", "set"),
                                                                            _restore(probe, me2, cs_data))),
         after=answer(me2, True), log=probe.take_log())
    emit(case="its own state into the ME instance", instance="ME", **dict(zip(("deserialize", "set"),
                                                                                _restore(probe, me2, data))),
         after=answer(me2, True), log=probe.take_log())
    # a live state of the ME instance (its own, got; and one it deserialized) set into a CS instance of the same
    # binary: fmi2SetFMUstate checks the interface of the instance it sets (the content was checked when it became
    # live)
    for case, make in (("got", lambda s: f.fmi2GetFMUstate(me, ctypes.byref(s))),
                       ("deserialized", lambda s: f.fmi2DeSerializeFMUstate(me2, data, len(data), ctypes.byref(s)))):
        state = ctypes.c_void_p()
        made = make(state)
        cs = probe.start()
        f.fmi2DoStep(cs, 0.0, 0.5, 1)
        probe.take_log()
        emit(case=f"an ME state {case} by an ME instance set into a CS instance", instance="CS", made=made,
             set=f.fmi2SetFMUstate(cs, state), after=answer(cs, False), log=probe.take_log())
        f.fmi2FreeFMUstate(me, ctypes.byref(state))
        f.fmi2FreeInstance(cs)
    f.fmi2FreeInstance(me2)
    f.fmi2FreeInstance(me)


def _foreign_state_calls(lib, version: str, state: str, size, buffer) -> list:
    """(case, function name, call(instance, state pointer)) for each state function of `lib` handed a state:
    version "fmi2" or "fmi3", state the standard's spelling ("FMUstate", "FMUState")."""
    get, set_, size_of, serialize, free = (getattr(lib, f"{version}{name}") for name in (
        f"Get{state}", f"Set{state}", f"Serialized{state}Size", f"Serialize{state}", f"Free{state}"))
    return [(f"{version}Get{state} into another FMU's state", f"{version}Get{state}",
             lambda i, s: get(i, ctypes.byref(s))),
            (f"{version}Set{state} of another FMU's state", f"{version}Set{state}", lambda i, s: set_(i, s)),
            (f"{version}Serialized{state}Size of another FMU's state", f"{version}Serialized{state}Size",
             lambda i, s: size_of(i, s, ctypes.byref(size))),
            (f"{version}Serialize{state} of another FMU's state", f"{version}Serialize{state}",
             lambda i, s: serialize(i, s, buffer, len(buffer))),
            (f"{version}Free{state} of another FMU's state", f"{version}Free{state}",
             lambda i, s: free(i, ctypes.byref(s)))]


def scenario_foreign_states(probe, other) -> None:
    """Two FMUs' binaries in one process: a state of the other FMU (and a freed state of this one) given to every
    state call of this one; {"case", "status", "expected", "log"}; the other FMU's state must survive intact."""
    f, g = probe.lib, other.lib
    for lib in (f, g):
        _declare(lib, FMI2)
    a, b = probe.start(), other.start()
    emit(case="start", ok=bool(a) and bool(b), log=probe.take_log() + other.take_log())
    theirs, ours = ctypes.c_void_p(), ctypes.c_void_p()
    g.fmi2GetFMUstate(b, ctypes.byref(theirs))
    before = _serialize(other, b, theirs)
    size = ctypes.c_size_t()
    buffer = ctypes.create_string_buffer(1 << 16)
    for case, call, make_call in _foreign_state_calls(f, "fmi2", "FMUstate", size, buffer):
        pointer = ctypes.c_void_p(theirs.value)
        _case(probe, case, call, "FMUstate", make_call(a, pointer))
    emit(case="the other FMU's state intact", ok=_serialize(other, b, theirs) == before,
         status=g.fmi2SetFMUstate(b, theirs), expected=OK, log=other.take_log())
    f.fmi2GetFMUstate(a, ctypes.byref(ours))
    freed = ours.value
    f.fmi2FreeFMUstate(a, ctypes.byref(ours))
    probe.take_log()
    _case(probe, "fmi2SetFMUstate of a freed state", "fmi2SetFMUstate", "FMUstate", f.fmi2SetFMUstate(a, freed))
    _case(probe, "fmi2FreeFMUstate of a freed state", "fmi2FreeFMUstate", "FMUstate",
          f.fmi2FreeFMUstate(a, ctypes.byref(ctypes.c_void_p(freed))))
    status, x = probe.steps(a, 0.0, 2)
    emit(case="doStep after the refusals", status=status, expected=OK, x=x, log=probe.take_log())
    g.fmi2FreeFMUstate(b, ctypes.byref(theirs))
    f.fmi2FreeInstance(a)
    g.fmi2FreeInstance(b)


def scenario_foreign_states3(probe: Probe3, other: Probe3) -> None:
    """scenario_foreign_states in FMI 3.0 (fmi3GetFMUState into another model's state corrupted the heap)."""
    f, g = probe.lib, other.lib
    a, b = probe.start(), other.start()
    emit(case="start", ok=bool(a) and bool(b), log=probe.take_log() + other.take_log())
    theirs, ours, size = ctypes.c_void_p(), ctypes.c_void_p(), ctypes.c_size_t()
    g.fmi3GetFMUState(b, ctypes.byref(theirs))
    buffer = ctypes.create_string_buffer(1 << 16)
    for case, call, make_call in _foreign_state_calls(f, "fmi3", "FMUState", size, buffer):
        _case(probe, case, call, "FMUState", make_call(a, ctypes.c_void_p(theirs.value)))
        f.fmi3FreeInstance(a)  # a refusal is an error of the instance: a fresh one for the next
        a = probe.start()
    emit(case="the other FMU's state intact", ok=True, status=g.fmi3SetFMUState(b, theirs), expected=OK,
         log=other.take_log())
    f.fmi3GetFMUState(a, ctypes.byref(ours))
    freed = ours.value
    f.fmi3FreeFMUState(a, ctypes.byref(ours))
    probe.take_log()
    _case(probe, "fmi3SetFMUState of a freed state", "fmi3SetFMUState", "FMUState", f.fmi3SetFMUState(a, freed))
    g.fmi3FreeFMUState(b, ctypes.byref(theirs))
    f.fmi3FreeInstance(a)
    g.fmi3FreeInstance(b)


# ---- the pythonfmu loader: resources a partial or foreign extraction leaves ----

def scenario_loader(probe, other_unzipped) -> None:
    """fmi2Instantiate of a pythonfmu FMU on damaged copies of its resources folder (each a fresh copy): a folder
    name that is not UTF-8, slavemodule.txt naming a missing module, empty, or naming another module, a slave file
    missing (a partial extraction), another FMU's resources; then the intact copy. {"case", "accepted", "expected",
    "log"}."""
    import os
    import shutil
    import tempfile
    import urllib.parse
    from pathlib import Path

    resources = probe.unzipped / "resources"
    module = (resources / "slavemodule.txt").read_text().strip()
    root = Path(tempfile.mkdtemp(prefix="vibrofmu_loader_"))

    def copy(name: bytes, change=None) -> str:
        folder = os.path.join(os.fsencode(root), name)
        shutil.copytree(os.fsencode(resources), folder, symlinks=True)
        if change is not None:
            change(Path(os.fsdecode(folder)))
        return "file://" + urllib.parse.quote_from_bytes(folder)

    def rm(name):
        return lambda folder: (folder / name).unlink()

    def write(text):
        return lambda folder: (folder / "slavemodule.txt").write_text(text)

    cases = [("folder name not UTF-8", copy(b"res\xff\xfe"), False),
             ("slavemodule.txt names a missing module", copy(b"missing", write("NoSuchModule\n")), False),
             ("slavemodule.txt empty", copy(b"empty", write("")), False),
             ("slavemodule.txt names another module", copy(b"other", write("slave_support\n")), False),
             ("the slave's module file missing", copy(b"partial", rm(f"_slave_{module}.py")), False),
             ("a package file missing", copy(b"partial2", rm("vibromodel/plant.py")), False),
             ("the identity file missing", copy(b"noid", rm("vibrofmu_identity.txt")), False),
             ("another FMU's resources", (Path(other_unzipped) / "resources").resolve().as_uri(), False),
             ("intact copy", copy(b"intact"), True)]
    for label, uri, accept in cases:
        c = probe.instantiate(uri)
        if c:
            probe.lib.fmi2FreeInstance(c)
        emit(case=label, uri=uri, accepted=bool(c), expected=accept, log=probe.take_log())
    shutil.rmtree(root, ignore_errors=True)
