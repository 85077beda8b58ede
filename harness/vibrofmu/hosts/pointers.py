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

    cases = [(call, False, lambda c, call=call, n=n: getattr(f, call)(c, None, n))
             for call, n in (("fmi2GetEventIndicators", ni), ("fmi2GetContinuousStates", nx),
                             ("fmi2GetNominalsOfContinuousStates", nx), ("fmi2GetDerivatives", nx))]
    cases += [("fmi2NewDiscreteStates", False, lambda c: f.fmi2NewDiscreteStates(c, None)),
              ("fmi2SetContinuousStates", True, lambda c: f.fmi2SetContinuousStates(c, None, nx)),
              ("fmi2CompletedIntegratorStep", True,
               lambda c: f.fmi2CompletedIntegratorStep(c, 1, None, ctypes.byref(flag)))]
    for call, continuous, make_call in cases:
        c = me(continuous)
        _case(probe, f"{call}(NULL)", call, "NULL", make_call(c))
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

    def once(case, call, argument, make_call, model_exchange=False):
        c = probe.start(model_exchange=model_exchange)
        _case(probe, case, call, argument, make_call(c))
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
            once(f"{call}(NULL)", call, "NULL", lambda c, call=call, n=n: getattr(f, call)(c, None, n), True)
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
