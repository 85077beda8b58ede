"""What every vibrofmu FMI slave shares: fixed parameters, the `fmi_status` flag read by the status shim
(fmu_src/fmi2_status_shim.c), error logging, the experiment's start/stop/tolerance, the FMU state
(fmi2GetFMUstate & co.), and the controller's parameters (law, gains, initial estimates) used by the
controller and the closed-loop FMUs.

No physics here. No Python exception may leave a callback (pythonfmu turns it into fmi2Fatal and destroys the
instance): errors are logged with the parameter and value, `fmi_status` is set to 3 and the shim returns
fmi2Error to the host.
"""
import functools
import json
import math
from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Initial, Fmi2Status

from vibromodel import snapshot
from vibromodel.control import ERRATA_INITIAL_ESTIMATES, ESTIMATE_NAMES, GAIN_NAMES, Gains, Law
from vibromodel.integrate import IntegrationError
from vibromodel.solvers import RULE_TEXT
from vibromodel.parameters import (NonFiniteOutput, ParameterError, Scene, check_finite, check_parameters,
                                   model_parameter_names, scene_names)
from vibromodel.settings import Settings

STATUS_OK, STATUS_ERROR = 0, 3
# A KeyboardInterrupt (the host's SIGINT, Ctrl-C, delivered while the slave's Python code ran) is never swallowed:
# the call ends in fmi2Error, the instance halts, and the flag reads STATUS_INTERRUPTED, on which the status shim
# re-raises SIGINT once the call has returned to the host (fmi2_status_shim.c, settle), so a Python host such as
# FMPy gets its KeyboardInterrupt. (Only a host with Python's SIGINT handler can interrupt Python code: the shim
# leaves a C host's signal handling alone.)
STATUS_INTERRUPTED = 130
INTERRUPTED = "interrupted (SIGINT, Ctrl-C): the host's interrupt is passed back to it"
# The pythonfmu callbacks guarded against KeyboardInterrupt, with what each returns when interrupted.
_INTERRUPTIBLE = {
    "setup_experiment": None, "enter_initialization_mode": None, "exit_initialization_mode": None,
    "terminate": None, "do_step": False, "_set_fmu_state": None,
    **{f"set_{kind}": None for kind in ("real", "integer", "boolean", "string")},
    **{f"get_{kind}": placeholder for kind, placeholder in (("real", 0.0), ("integer", 0), ("boolean", False),
                                                            ("string", ""))},
}


def _interruptible(name, method):
    """`method` (a pythonfmu callback) with a KeyboardInterrupt turned into an interrupted, halted instance."""
    placeholder = _INTERRUPTIBLE[name]

    @functools.wraps(method)
    def call(self, *args):
        try:
            return method(self, *args)
        except KeyboardInterrupt:
            self._interrupted(name)
            if name.startswith("get_"):  # the status flag itself read as it is (the shim reads it after a call)
                return [self.fmi_status if getattr(self.vars.get(vr), "name", None) == "fmi_status" else placeholder
                        for vr in args[0]]
            return placeholder
    call._interruptible = True
    return call
# FMI 2.0 co-simulation states the slave tracks (the error state is the C layer's -- fmu_src/fmi/fmi2_layer.c, in
# the status shim and the native FMUs -- and `halted`'s).
INSTANTIATED, INITIALIZATION_MODE, STEP_MODE, TERMINATED = ("instantiated", "initialization mode", "step mode",
                                                            "terminated")
PHASES = (INSTANTIATED, INITIALIZATION_MODE, STEP_MODE, TERMINATED)
ERROR = "error"  # after a call ended in fmi2Error (kept by the C layer; a Python-only FMU has no error state)
# The FMI 2.0 co-simulation state machine, ONE table: the states in which each call is allowed (cf. the Modelica
# Reference-FMUs' ASSERT_STATE masks). Getters and setters are allowed in every phase at this level; the rules per
# variable follow in _get_values and _set_refusal. The slaves read it here (_allowed); the C layer reads it as
# fmu_src/fmi/fmi2_calls.h, generated from it (python3 -m vibrofmu.fmus.fmi_calls; tests/fmus/test_c_toolchain.py checks
# that the header is current). A Python-only FMU (built without a C compiler) has only this Python side.
_ANYWHERE = (*PHASES, ERROR)
CALLS = {
    "fmi2SetDebugLogging": _ANYWHERE,
    "fmi2SetupExperiment": (INSTANTIATED,),
    "fmi2EnterInitializationMode": (INSTANTIATED,),
    "fmi2ExitInitializationMode": (INITIALIZATION_MODE,),
    "fmi2Terminate": (STEP_MODE,),
    "fmi2Reset": _ANYWHERE,
    **{f"fmi2Get{kind}": _ANYWHERE for kind in ("Real", "Integer", "Boolean", "String")},
    # a terminated instance takes no values (FMI 2.0)
    **{f"fmi2Set{kind}": (INSTANTIATED, INITIALIZATION_MODE, STEP_MODE) for kind in ("Real", "Integer", "Boolean",
                                                                                      "String")},
    **{name: _ANYWHERE for name in ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate",
                                    "fmi2SerializedFMUstateSize", "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate")},
    "fmi2GetRealOutputDerivatives": (STEP_MODE, TERMINATED, ERROR),
    # the model's partial derivatives exist at its current point: after initialisation (and in the error state)
    "fmi2GetDirectionalDerivative": (STEP_MODE, TERMINATED, ERROR),
    "fmi2SetRealInputDerivatives": (INSTANTIATED, INITIALIZATION_MODE, STEP_MODE),
    "fmi2DoStep": (STEP_MODE,),
    "fmi2CancelStep": PHASES,  # answered in every phase with why it has nothing to cancel (doStep is synchronous)
    **{f"fmi2Get{kind}Status": _ANYWHERE for kind in ("", "Real", "Integer", "Boolean", "String")},
}
# The same state machine for the other interfaces of the native FMUs (fmu_src/native: fmi2_native.c, fmi2_me.c,
# fmi3_native.c), in the same table: Model Exchange splits the running phase (co-simulation's step mode) into event
# mode and continuous-time mode; FMI 3.0 has both interfaces. The C enum of fmi2_calls.h lists STATES in this order
# (the first five are the co-simulation states, whose numbers are in the serialized FMU states). A call missing from
# an interface's table is not part of that interface (refused in every state). tests/fmus/test_fmi_state_table.py
# compares each table with the standard's state machine and checks that the C layers consult nothing else.
EVENT_MODE, CONTINUOUS_TIME_MODE = "event mode", "continuous-time mode"
STATES = (*PHASES, ERROR, EVENT_MODE, CONTINUOUS_TIME_MODE)
_RUNNING_ME = (EVENT_MODE, CONTINUOUS_TIME_MODE)
_AFTER_INITIALISATION_ME = (*_RUNNING_ME, TERMINATED)
_CO_SIMULATION_ONLY = ("fmi2DoStep", "fmi2CancelStep", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
                       *(f"fmi2Get{kind}Status" for kind in ("", "Real", "Integer", "Boolean", "String")))
ME_CALLS = {  # FMI 2.0 Model Exchange: the common calls with step mode split in two, then Model Exchange's own
    **{call: tuple(s for state in states for s in ((state,) if state != STEP_MODE else _RUNNING_ME))
       for call, states in CALLS.items() if call not in _CO_SIMULATION_ONLY},
    # in continuous-time mode only Reals are set (FMI 2.0, 3.2.3)
    **{f"fmi2Set{kind}": (INSTANTIATED, INITIALIZATION_MODE, EVENT_MODE) for kind in ("Integer", "Boolean", "String")},
    "fmi2EnterEventMode": _RUNNING_ME,
    "fmi2NewDiscreteStates": (EVENT_MODE,),
    "fmi2EnterContinuousTimeMode": (EVENT_MODE,),
    "fmi2CompletedIntegratorStep": (CONTINUOUS_TIME_MODE,),
    "fmi2SetTime": _RUNNING_ME,
    "fmi2SetContinuousStates": (CONTINUOUS_TIME_MODE,),
    **{name: (*_AFTER_INITIALISATION_ME, ERROR)
       for name in ("fmi2GetDerivatives", "fmi2GetEventIndicators", "fmi2GetContinuousStates")},
    "fmi2GetNominalsOfContinuousStates": (INSTANTIATED, *_AFTER_INITIALISATION_ME, ERROR),
}
# FMI 3.0 (fmi3_native.c, over the FMI 2.0 calls: the error state is the FMI 2.0 instance's, so no FMI 3.0 call
# lists it). Co-Simulation's event mode exists only with eventModeUsed (an instance flag, not a state).
_CS3 = (INSTANTIATED, INITIALIZATION_MODE, EVENT_MODE, STEP_MODE, TERMINATED)
_ME3 = (INSTANTIATED, INITIALIZATION_MODE, EVENT_MODE, CONTINUOUS_TIME_MODE, TERMINATED)
_TYPES3 = ("Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Boolean",
           "String", "Binary")


def _fmi3_common(every):
    """The FMI 3.0 calls both interfaces have, for an interface with the states `every`."""
    return {
        "fmi3SetDebugLogging": every,
        "fmi3EnterInitializationMode": (INSTANTIATED,),
        "fmi3ExitInitializationMode": (INITIALIZATION_MODE,),
        "fmi3Reset": every,
        **{f"fmi3Get{kind}": every for kind in _TYPES3},
        # in continuous-time mode only continuous (Float) variables may be set
        **{f"fmi3Set{kind}": every if kind.startswith("Float") else
           tuple(s for s in every if s != CONTINUOUS_TIME_MODE) for kind in _TYPES3},
        **{f"fmi3{name}": every for name in (
            "GetClock", "SetClock", "GetIntervalDecimal", "GetIntervalFraction", "GetShiftDecimal",
            "GetShiftFraction", "SetIntervalDecimal", "SetIntervalFraction", "SetShiftDecimal", "SetShiftFraction",
            "GetNumberOfVariableDependencies", "GetVariableDependencies", "GetFMUState", "SetFMUState",
            "FreeFMUState", "SerializedFMUStateSize", "SerializeFMUState", "DeserializeFMUState",
            "EvaluateDiscreteStates", "GetNumberOfEventIndicators", "GetNumberOfContinuousStates")},
        "fmi3UpdateDiscreteStates": (EVENT_MODE,),
        # the model's partial derivatives exist at its current point: after initialisation
        **{f"fmi3Get{kind}Derivative": tuple(s for s in every if s not in (INSTANTIATED, INITIALIZATION_MODE))
           for kind in ("Directional", "Adjoint")},
        "fmi3EnterConfigurationMode": tuple(s for s in every if s in (INSTANTIATED, EVENT_MODE, STEP_MODE)),
        # configuration and clock activation modes: these FMUs have neither (no structural parameter, no clock)
        "fmi3ExitConfigurationMode": (),
        "fmi3ActivateModelPartition": (),
    }


FMI3_CO_SIMULATION = {
    **_fmi3_common(_CS3),
    "fmi3GetOutputDerivatives": (STEP_MODE, TERMINATED),
    "fmi3EnterEventMode": (STEP_MODE,),
    "fmi3Terminate": (EVENT_MODE, STEP_MODE),
    "fmi3EnterStepMode": (EVENT_MODE,),
    "fmi3DoStep": (STEP_MODE,),
}
FMI3_MODEL_EXCHANGE = {
    **_fmi3_common(_ME3),
    "fmi3EnterEventMode": (CONTINUOUS_TIME_MODE,),
    "fmi3Terminate": _RUNNING_ME,
    "fmi3EnterContinuousTimeMode": (EVENT_MODE,),
    "fmi3CompletedIntegratorStep": (CONTINUOUS_TIME_MODE,),
    "fmi3SetTime": _RUNNING_ME,
    "fmi3SetContinuousStates": (CONTINUOUS_TIME_MODE,),
    **{f"fmi3{name}": _AFTER_INITIALISATION_ME
       for name in ("GetContinuousStateDerivatives", "GetEventIndicators", "GetContinuousStates",
                    "GetNominalsOfContinuousStates")},
}
# The tables by interface, in the order fmi2_calls.h defines their masks (prefix FMI2_MASK_, FMI2ME_MASK_, ...).
# The states in which an FMI 2.0 getter reads any variable (the standard's getter states): the table lets the getters
# run in every state only so that the status flag fmi_status is read (by the status shim) from fmi2Instantiate on.
GET_ANY_VARIABLE = {"FMI2": (INITIALIZATION_MODE, STEP_MODE, TERMINATED, ERROR),
                    "FMI2ME": (INITIALIZATION_MODE, *_AFTER_INITIALISATION_ME, ERROR)}
# (name in the messages, interface, table)
STATE_TABLES = {"FMI2": ("FMI 2.0", "Co-Simulation", CALLS),
                "FMI2ME": ("FMI 2.0 Model Exchange", "Model Exchange", ME_CALLS),
                "FMI3CS": ("FMI 3.0 Co-Simulation", "Co-Simulation", FMI3_CO_SIMULATION),
                "FMI3ME": ("FMI 3.0 Model Exchange", "Model Exchange", FMI3_MODEL_EXCHANGE)}
RUN_FIELDS = ("phase", "halted", "initialised", "start_time", "stop_time", "experiment_tolerance")  # in the FMU state
# A doStep may end this far (relative) past the declared stop time: hosts compute the last communication point
# as start + n*h, which can land an ulp or so beyond the stop time (the plant's time-matching tolerance).
STOP_TIME_TOLERANCE = 1e-9
# The scene's parameters without the plant's initial state (the controller's view of the plant).
MODEL_PARAMETERS = tuple(model_parameter_names())


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _same(a, b) -> bool:
    """Equal as plain data, NaN equal to NaN (a host may give a NaN stop time or tolerance)."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


class StatusSlave(Fmi2Slave):
    """Base of the vibrofmu slaves: subclasses register their variables and call _error/_halt on failure.

    FMU state: every FMI variable, the fields in RUN_FIELDS and the snapshot of the subclass's `model`
    (None before initialisation). A subclass names its state format (`state_format`, changed whenever
    its state changes shape) and supplies _make_model(), the model of the current parameters and
    experiment; the model supplies snapshot() (plain data, see vibromodel.snapshot) and restore().
    pythonfmu keeps the object _get_fmu_state returns as the state and hands it to _set_fmu_state as is,
    possibly several times, so both sides copy. fmi2Reset makes a new slave object (pythonfmu), i.e. the
    state after fmi2Instantiate.
    """
    state_format = None  # "<slave> state <version>"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.fmi_status = STATUS_OK
        self.register_variable(Integer("fmi_status", causality=Fmi2Causality.local,
                                       variability=Fmi2Variability.discrete,
                                       description="0 ok, 3 error, 130 interrupted (read by the status shim)"))
        self.phase = INSTANTIATED  # FMI 2.0 state (state machine of the co-simulation interface)
        self.halted = "the FMU has not been initialised"  # why doStep refuses, or None
        self.initialised = False  # exitInitializationMode was called: only inputs may be set
        self.start_time, self.stop_time, self.experiment_tolerance = 0.0, None, None
        self.model = None  # built by _make_model() at exitInitializationMode
        self._published = {}  # the outputs last published (all finite)
        self._built_with = None  # _fingerprint() of the parameters the model was built from

    def _parameter(self, kind, name, value, description=None):
        """A fixed parameter with its start value."""
        setattr(self, name, value)
        self.register_variable(kind(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                                    description=description))

    def _plant_parameters(self, scene, settings, fidelity_text):
        """The plant's parameters (the plant and the closed loop): the scene's, the fidelity and the integrator's
        (solver, rtol, max_step)."""
        for name in scene_names():
            self._parameter(Real, name, getattr(scene, name))
        self._parameter(Integer, "fidelity", int(settings.fidelity), fidelity_text)
        self._parameter(Integer, "solver", int(settings.solver), RULE_TEXT)
        self._parameter(Real, "rtol", settings.rtol, "relative tolerance (setupExperiment's tolerance wins)")
        self._parameter(Real, "max_step", settings.max_step, "RK4 step / adaptive step ceiling; 0 = automatic")

    def _plant_values(self, **settings):
        """(the Scene, the Settings) of the current values of _plant_parameters and `kernel` (setupExperiment's
        tolerance, when given, as rtol); `settings`: the other fields of Settings."""
        scene = Scene(**{name: float(getattr(self, name)) for name in scene_names()})
        rtol = self.rtol if self.experiment_tolerance is None else self.experiment_tolerance
        return scene, Settings(fidelity=int(self.fidelity), solver=int(self.solver), rtol=float(rtol),
                               max_step=float(self.max_step), kernel=int(self.kernel), **settings)

    def _outputs(self, names, values, description=None):
        """Real outputs (initial exact) with their start values."""
        for name, value in zip(names, values):
            setattr(self, name, value)
            self.register_variable(Real(name, causality=Fmi2Causality.output, initial=Fmi2Initial.exact,
                                        description=description))

    def _set_finite(self, values: dict) -> None:
        """Publish outputs only when all are finite: an FMU never shows NaN with fmi2OK. A non-finite one raises
        NonFiniteOutput naming it (the caller's doStep or initialisation fails with fmi2Error); the outputs then
        keep their last finite values (written back: on the compiled plant the kernel wrote them already)."""
        try:
            check_finite(values)
        except NonFiniteOutput:
            for name, value in self._published.items():
                setattr(self, name, value)
            raise
        for name, value in values.items():
            setattr(self, name, value)
        self._published = dict(values)

    def _error(self, message):
        self.fmi_status = STATUS_ERROR
        self.log(message, Fmi2Status.error)

    def _halt(self, message):
        self.halted = message
        self._error(message)

    def _interrupted(self, call):
        """A KeyboardInterrupt during `call`: halt (fmi2Error) and flag it for the shim to re-raise SIGINT."""
        self._halt(f"{call}: {INTERRUPTED}")
        self.fmi_status = STATUS_INTERRUPTED

    # -- the FMI 2.0 state machine (co-simulation): each call only in the states the standard allows --------
    def _allowed(self, call) -> bool:
        """True if `call` is allowed in the current state (CALLS); otherwise log an error naming both and say False."""
        phases = [state for state in CALLS[call] if state in PHASES]
        if self.phase in phases:
            return True
        self._error(f"{call} is not allowed in the {self.phase} state (FMI 2.0 allows it in: "
                    f"{', '.join(phases)})")
        return False

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        if not self._allowed("fmi2SetupExperiment"):
            return
        self.start_time, self.stop_time = start_time, stop_time
        self.experiment_tolerance = tolerance

    def enter_initialization_mode(self):
        if self._allowed("fmi2EnterInitializationMode"):
            self.phase = INITIALIZATION_MODE

    def terminate(self):
        if self._allowed("fmi2Terminate"):
            self.phase = TERMINATED
            self.halted = "fmi2Terminate was called (FMI 2.0: only fmi2Reset or fmi2FreeInstance may follow)"
            self._enable_fast_path()

    def _enable_fast_path(self):
        """A slave with a C fast path (re)decides here whether the shim may use it (after every state change)."""

    def _cache_dirs(self):
        """OAFM solutions packed at build time (resources/oafm_cache)."""
        return (Path(self.resources) / "oafm_cache",) if self.resources else ()

    def _initialise(self, start):
        """exitInitializationMode: run start() (builds the model, publishes the outputs); errors -> fmi2Error."""
        self.initialised = True
        try:
            check_parameters(self._parameter_values())  # every range up front, the parameter named
            self._built_with = self._fingerprint()
            start()
            self.halted = None
        except ParameterError as error:
            self._halt(f"{error}")
        except IntegrationError as error:  # the model cannot even start (e.g. beyond its numerical range)
            self._halt(f"simulation stopped: {error}")
        except Exception as error:  # never let an exception reach pythonfmu (fmi2Fatal)
            self._halt(f"initialisation failed: {error!r}")

    def _guarded_step(self, current_time, step, stopped=None) -> bool:
        """doStep: run step(); a bad step or input -> fmi2Error (the instance stays usable); an integration
        failure -> stopped(error) (e.g. publish the last state), then halt; anything else -> halt."""
        if self.halted is not None:
            self._error(f"doStep refused: {self.halted}")
            return False
        try:
            step()
            return True
        except ParameterError as error:
            self._error(f"doStep refused: {error}")
        except IntegrationError as error:
            if stopped is not None:
                stopped(error)
            self._halt(f"simulation stopped: {error}")
        except ArithmeticError as error:  # e.g. a scene of 1e300-sized parameters
            self._halt(f"simulation stopped: floating-point failure after tau = {current_time!r} ({error!r}); "
                       "the parameters are beyond the model's numerical range")
        except Exception as error:
            self._halt(f"doStep failed at tau = {current_time!r}: {error!r}")
        return False

    def __init_subclass__(cls, **kwargs):
        """Every slave's do_step runs behind _step_allowed (state machine, stop time) first."""
        super().__init_subclass__(**kwargs)
        step = cls.__dict__.get("do_step")
        if step is not None and not getattr(step, "_checked", False):
            @functools.wraps(step)
            def do_step(self, current_time, step_size):
                return self._step_allowed(current_time, step_size) and step(self, current_time, step_size)
            do_step._checked = True
            cls.do_step = do_step
        for name in _INTERRUPTIBLE:  # outermost: a KeyboardInterrupt anywhere in the call
            method = getattr(cls, name)
            if not getattr(method, "_interruptible", False):
                setattr(cls, name, _interruptible(name, method))

    def _parameter_values(self) -> dict:
        """name -> value of every parameter, rtol being the experiment's tolerance when setupExperiment gave one."""
        values = {var.name: getattr(self, var.local_name) for var in self.vars.values()
                  if var.causality == Fmi2Causality.parameter}
        if self.experiment_tolerance is not None and "rtol" in values:
            values["rtol"] = self.experiment_tolerance
        return values

    def _step_allowed(self, t, h) -> bool:
        """fmi2DoStep only in step mode (not before initialisation, not after fmi2Terminate), and not beyond the
        stop time declared in fmi2SetupExperiment; otherwise fmi2Error naming the call and the state."""
        if self.phase not in CALLS["fmi2DoStep"] and self.initialised and self.halted:
            # the table refuses it after initialisation (terminated): the refusal says why the instance halted
            self._error(f"doStep refused: {self.halted}")
            return False
        if not self._allowed("fmi2DoStep"):
            return False
        stop = self.stop_time
        end = None if stop is None else stop + STOP_TIME_TOLERANCE * max(1.0, abs(stop))
        # a t beyond the stop is a wrong currentCommunicationPoint: the model's own check names it
        if end is not None and math.isfinite(t) and math.isfinite(h) and t <= end < t + h:
            reason = (f"the step from tau = {t!r} would end at tau = {t + h!r}, beyond the stop time {stop!r} "
                      "declared in fmi2SetupExperiment")
            self._error(f"{ParameterError('communicationStepSize', h, reason)}")
            return False
        return True

    def exit_initialization_mode(self):
        if not self._allowed("fmi2ExitInitializationMode"):
            return
        self.phase = STEP_MODE
        self._initialise(self._start)

    def _start(self):
        """Build the model, log its notes (fmi2OK) and warnings (fmi2Warning: e.g. rtol clamped, an RK4 step that
        does not resolve the forcing), publish its first outputs (the controller, without either, overrides)."""
        self.model = self._make_model()
        for note in self.model.notes:
            self.log(note, Fmi2Status.ok)
        for warning in self.model.warnings:
            self.log(warning, Fmi2Status.warning)
        self._publish(self.model.outputs())

    # -- FMU state -----------------------------------------------------------------------------------
    def _make_model(self):
        """The model of the current parameters and experiment; raises ParameterError for bad ones."""
        raise NotImplementedError

    def _get_fmu_state(self):
        return {
            "format": self.state_format,
            "variables": super()._get_fmu_state(),
            "run": {name: getattr(self, name) for name in RUN_FIELDS},
            "built_with": self._built_with,
            "model": None if self.model is None else self.model.snapshot(),
        }

    def _set_fmu_state(self, state):
        self._backup = None  # taken by _restore just before it changes anything
        try:
            self._restore(state)
        except Exception as error:  # a foreign, damaged or forged state: refuse, never raise
            try:
                if self._backup is not None:
                    self._restore(self._backup)  # the instance stays as it was
            except Exception as second:  # cannot happen for a state this instance made; be safe anyway
                self._halt(f"fmi2SetFMUstate refused ({error}); the previous state could not be restored ({second!r})")
                return
            finally:
                self._backup = None
            self._error(f"fmi2SetFMUstate refused: not a state of this FMU or a damaged one ({error})")
            return
        if self.fmi_status == STATUS_ERROR:
            self.log(f"restored a state saved after an error: {self.halted or 'a call had failed'}",
                     Fmi2Status.error)

    def _fingerprint(self) -> dict:
        """What a model is built from: every parameter and the experiment (start, stop, tolerance)."""
        return {"parameters": self._parameter_values(),
                "experiment": [self.start_time, self.stop_time, self.experiment_tolerance]}

    def _restore(self, state):
        """Check every field of `state`, then put it back; raises ValueError (nothing half-done before the model)."""
        if isinstance(state, dict) and set(state) == {"unreadable"}:
            raise ValueError(f"unreadable bytes: {state['unreadable']}")
        if not isinstance(state, dict) or state.get("format") != self.state_format:
            found = state.get("format") if isinstance(state, dict) else type(state).__name__
            raise ValueError(f"format {found!r}, expected {self.state_format!r}")
        if set(state) != {"format", "variables", "run", "built_with", "model"}:
            raise ValueError(f"fields {sorted(state)}")
        variables, run = state["variables"], state["run"]
        self._check_variables(variables)
        self._check_run(run)
        if getattr(self, "_backup", None) is None:
            self._backup = self._get_fmu_state()
        for var in self.vars.values():  # not through the setters: a state may hold any value
            setattr(self, var.local_name, variables[var.name])
        for name in RUN_FIELDS:
            setattr(self, name, run[name])
        self._built_with = state["built_with"]
        self.model = None
        if state["model"] is not None:
            # the state's parameters must be those its model was built with (a changed one is refused)
            if not _same(state["built_with"], self._fingerprint()):
                raise ValueError("its parameters or experiment differ from those its model was built with")
            check_parameters(self._parameter_values())
            self.model = self._make_model()
            self.model.restore(state["model"])
        self._published = {var.local_name: getattr(self, var.local_name) for var in self.vars.values()
                           if var.causality == Fmi2Causality.output}

    def _check_variables(self, variables):
        """Every variable present with a value of its type; outputs finite (inputs and parameters are the host's
        values as given: doStep and initialisation check them)."""
        if not isinstance(variables, dict) or set(variables) != {var.name for var in self.vars.values()}:
            raise ValueError("its variables are not this FMU's")
        for var in self.vars.values():
            value = variables[var.name]
            kinds = {Real: (float, int), Integer: (int,), Boolean: (bool,), String: (str,)}[type(var)]
            if not isinstance(value, kinds) or (isinstance(value, bool) and type(var) is not Boolean):
                raise ValueError(f"variable {var.name} = {value!r} is not a {type(var).__name__}")
            if type(var) is Real and var.causality == Fmi2Causality.output and not math.isfinite(value):
                raise ValueError(f"variable {var.name} = {value!r} is not finite")
        if variables["fmi_status"] not in (STATUS_OK, STATUS_ERROR, STATUS_INTERRUPTED):
            raise ValueError(f"fmi_status = {variables['fmi_status']!r}")

    @staticmethod
    def _check_run(run):
        if not isinstance(run, dict) or set(run) != set(RUN_FIELDS):
            raise ValueError("its run fields are not this FMU's")
        checks = {
            "phase": lambda v: v in (INSTANTIATED, INITIALIZATION_MODE, STEP_MODE, TERMINATED),
            "halted": lambda v: v is None or isinstance(v, str),
            "initialised": lambda v: isinstance(v, bool),
            # the host's experiment as given (checked when the model is built from it)
            "start_time": lambda v: _number(v),
            "stop_time": lambda v: v is None or _number(v),
            "experiment_tolerance": lambda v: v is None or _number(v),
        }
        for name, check in checks.items():
            if not check(run[name]):
                raise ValueError(f"run field {name} = {run[name]!r}")
        if run["initialised"] != (run["phase"] in (STEP_MODE, TERMINATED)):
            raise ValueError(f"initialised = {run['initialised']!r} in the {run['phase']} state")

    @staticmethod
    def _fmu_state_to_bytes(state):
        return snapshot.to_bytes(state)

    @staticmethod
    def _fmu_state_from_bytes(data):
        """Never raises (pythonfmu would turn it into fmi2Fatal): bad bytes give a state that
        fmi2SetFMUstate refuses with fmi2Error."""
        try:
            return snapshot.from_bytes(data)
        except Exception as error:
            return {"unreadable": f"{error}"}

    # -- getting variables: unknown value references and wrong types give fmi2Error, never an exception -------
    def get_real(self, vrs):
        return self._get_values(vrs, Real, "fmi2GetReal", 0.0, float)

    def get_integer(self, vrs):
        return self._get_values(vrs, Integer, "fmi2GetInteger", 0, int)

    def get_boolean(self, vrs):
        return self._get_values(vrs, Boolean, "fmi2GetBoolean", False, bool)

    def get_string(self, vrs):
        return self._get_values(vrs, String, "fmi2GetString", "", str)

    _describing = False  # to_xml is reading the start values (not the outputs of Initialization Mode)

    def to_xml(self, *args, **kwargs):
        """The model description: pythonfmu's builder reads the start values through the getters."""
        phase, self.phase, self._describing = self.phase, INITIALIZATION_MODE, True
        try:
            return super().to_xml(*args, **kwargs)
        finally:
            self.phase, self._describing = phase, False

    def _initial_output(self, name):
        """Output `name` in Initialization Mode, from the start values set so far (a subclass whose outputs follow
        its parameters overrides this); raises ParameterError or NonFiniteOutput when it cannot be defined."""
        value = getattr(self, name)
        if isinstance(value, float):
            check_finite({name: value})
        return value

    def _get_values(self, vrs, kind, call, placeholder, convert):
        """The values of vrs; a refused one reads `placeholder` and the call ends in fmi2Error (the status shim
        turns an error logged during a getter into fmi2Error). pythonfmu would turn the KeyError or TypeError of
        its own getters into fmi2Fatal. The status flag itself is read by the shim in every state."""
        values = []
        for vr in vrs:
            var = self.vars.get(vr)
            if var is None:
                refusal = f"{call}: no variable has valueReference {vr}"
            elif not isinstance(var, kind):
                refusal = f"{call}: variable {var.name} (valueReference {vr}) is a {type(var).__name__}, not a {kind.__name__}"
            elif self.phase not in GET_ANY_VARIABLE["FMI2"] and var.name != "fmi_status":
                refusal = (f"{call} of {var.name} is not allowed in the {INSTANTIATED} state (FMI 2.0 allows it from "
                           f"fmi2EnterInitializationMode on)")
            elif self.phase == INITIALIZATION_MODE and var.causality == Fmi2Causality.output and not self._describing:
                try:  # FMI 2.0: outputs in Initialization Mode follow the start values set so far
                    values.append(convert(self._initial_output(var.name)))
                    continue
                except (ParameterError, NonFiniteOutput) as error:
                    refusal = f"{call} of {var.name} in the {INITIALIZATION_MODE} state: {error}"
                except Exception as error:  # never let an exception reach pythonfmu (fmi2Fatal)
                    refusal = f"{call} of {var.name} in the {INITIALIZATION_MODE} state: {error!r}"
            else:
                values.append(convert(var.getter()))
                continue
            self._error(refusal)
            values.append(placeholder)
        return values

    # -- setting variables: FMI 2.0 rules, refusals logged and flagged (never raised) -----------------
    def set_real(self, vrs, values):
        self._set_values(Fmi2Slave.set_real, vrs, values)

    def set_integer(self, vrs, values):
        self._set_values(Fmi2Slave.set_integer, vrs, values)

    def set_boolean(self, vrs, values):
        self._set_values(Fmi2Slave.set_boolean, vrs, values)

    def set_string(self, vrs, values):
        self._set_values(Fmi2Slave.set_string, vrs, values)

    def _set_values(self, setter, vrs, values):
        for vr, value in zip(vrs, values):
            var = self.vars.get(vr)
            name = var.name if var is not None else f"with valueReference {vr}"
            refusal = "no such variable" if var is None else self._set_refusal(var)
            if refusal is None:
                try:
                    setter(self, [vr], [value])
                    continue
                except TypeError as error:  # pythonfmu's type check: wrong setter for the variable
                    refusal = f"{error}"
            self._error(f"{ParameterError(name, value, refusal)}")

    def _set_refusal(self, var):
        """Why FMI 2.0 forbids setting var now, or None (fmi2SetXXX in the co-simulation state machine: the table's
        states of the setters, which are the same for every type, then the rules per variable)."""
        if self.phase not in CALLS["fmi2SetReal"]:
            return f"no variable may be set in the {self.phase} state (FMI 2.0)"
        if var.causality == Fmi2Causality.input:
            return None
        if var.causality == Fmi2Causality.parameter and var.variability == Fmi2Variability.tunable:
            return None
        settable_start = var.causality == Fmi2Causality.parameter or var.initial in (Fmi2Initial.exact,
                                                                                     Fmi2Initial.approx)
        if not settable_start:
            return f"a {var.causality.name} variable computed by the FMU cannot be set"
        if self.initialised:
            kind = f"{(var.variability or Fmi2Variability.continuous).name} {var.causality.name}"
            return (f"a {kind} cannot be set after fmi2ExitInitializationMode (FMI 2.0: only inputs and "
                    f"tunable parameters); it keeps {getattr(self, var.local_name)!r}")
        if var.causality == Fmi2Causality.output:  # its start value is the model's initial output
            return ("an output is computed by the FMU from its parameters (x_start, v_start, ...); setting it "
                    "would be ignored, so it is refused")
        return None

    # -- the controller's parameters and outputs (AdaptiveLyapunovController, HertzEAClosedLoop) ----------
    def _controller_parameters(self):
        gains = Gains()
        self._parameter(Integer, "law", int(Law.PAPER_CORRECTED),
                        "0 paper-corrected (docs/model.md), 1 damped (gain k_damping), 2 paper-literal (Eqs 78, 81 as printed)")
        for name, value in zip(GAIN_NAMES, gains.lambdas):
            self._parameter(Real, name, value, "Lyapunov weight (Eq. 76), > 0")
        self._parameter(Real, "k_damping", gains.k_damping, "damped law: e2 gain k > 0")
        for name, value in zip(ESTIMATE_NAMES, ERRATA_INITIAL_ESTIMATES):
            self._parameter(Real, f"{name}_start", value, "initial estimate")

    def _controller_settings(self) -> tuple[int, Gains, tuple[float, ...]]:
        """(law, gains, initial estimates) from the parameters; validated by vibromodel."""
        gains = Gains(lambdas=tuple(float(getattr(self, name)) for name in GAIN_NAMES),
                      k_damping=float(self.k_damping))
        return int(self.law), gains, tuple(float(getattr(self, f"{name}_start")) for name in ESTIMATE_NAMES)
