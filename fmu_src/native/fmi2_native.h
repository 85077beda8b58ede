/*
 * fmi2_native.h -- the FMI 2.0 co-simulation layer of the native vibrofmu FMUs (no Python at run time).
 *
 * Written once (fmi2_native.c) for every native FMU, in the spirit of the Reference-FMUs: each model has a
 * folder with config.h (its ModelData: every FMI variable's value plus the model's own plain-data state) and
 * native_model.c (the hooks below).  variables.h, generated at build time from the pythonfmu FMU's
 * modelDescription.xml (harness/vibrofmu/fmus/native.py), lists the variables with the same value references,
 * causalities and start values, so the native FMU has the pythonfmu FMU's interface.
 *
 * The layer reproduces the behaviour of the pythonfmu slaves behind the status shim (slave_support.py,
 * fmi2_status_shim.c): the same setting rules and messages, the status flag fmi_status (0 ok, 3 error), the
 * error state (after an fmi2Error only getters, fmi2Reset, fmi2SetFMUstate and fmi2FreeInstance: the state table of
 * fmu_src/fmi/fmi2_layer.c, shared with the shim), and the FMU state (the instance's State is plain data without pointers: get/set is a copy, serialization its bytes).
 */
#ifndef FMI2_NATIVE_H
#define FMI2_NATIVE_H

#include <stddef.h>
#include <stdint.h>

#include "fmi2_layer.h"  /* the FMI 2.0 headers, logging, error mode, state table (fmu_src/fmi/, shared with the shim) */

typedef enum { T_REAL, T_INTEGER, T_BOOLEAN } VarType;
typedef enum { C_PARAMETER, C_INPUT, C_OUTPUT, C_LOCAL } VarCausality;

typedef struct {
    const char *name;
    VarType type;
    VarCausality causality;
    const char *variability; /* "fixed", "tunable", "discrete", "continuous" */
    int settable_start;      /* parameter, or initial exact/approx: may be set before initialization */
    double start;
} VariableInfo;

#include "variables.h"  /* N_VARIABLES, VR_<name>, VARIABLES[] (generated) */
#include "config.h"     /* MODEL_IDENTIFIER, STATE_FORMAT, ModelData (per model) */

/* The interfaces fmi2Instantiate accepts (fmuType, as FMI2_TYPE_BIT(...)); a model's config.h may widen it. */
#ifndef NATIVE_FMU_TYPES
#define NATIVE_FMU_TYPES FMI2_TYPE_BIT(fmi2CoSimulation)
#endif

#define HALT_MESSAGE 640

/* Everything that decides an instance's future: plain data (the FMU state). */
/* FMI 2.0 co-simulation states (slave_support.StatusSlave.phase; the state table's phases, fmi2_calls.h); the error
   state is the instance's Fmi2Layer mode */
enum { PHASE_INSTANTIATED = FMI2_INSTANTIATED, PHASE_INITIALIZATION_MODE = FMI2_INITIALIZATION_MODE,
       PHASE_STEP_MODE = FMI2_STEP_MODE, PHASE_TERMINATED = FMI2_TERMINATED };

typedef struct {
    double value[N_VARIABLES];   /* every FMI variable, by value reference (Integer/Boolean as exact doubles) */
    int64_t phase;               /* PHASE_* */
    int64_t initialised;         /* fmi2ExitInitializationMode was called: only inputs may be set */
    int64_t halted;              /* doStep refuses, with halt_message */
    double start_time, stop_time, tolerance;
    int64_t has_stop, has_tolerance;
    ModelData model;
    char halt_message[HALT_MESSAGE];
} State;

typedef struct Instance Instance;

/* ---- provided by fmi2_native.c for the models ---- */
void native_log(Instance *inst, fmi2Status status, const char *format, ...);
/* an error: fmi_status = 3, message logged as fmi2Error (StatusSlave._error) */
void native_error(Instance *inst, const char *format, ...);
/* an error after which doStep refuses (StatusSlave._halt) */
void native_halt(Instance *inst, const char *format, ...);
/* native_halt with ParameterError's text: "parameter NAME = repr(value): reason" (integer: the value as %d) */
void native_halt_parameter(Instance *inst, const char *name, double value, int integer, const char *reason);
int native_logging_on(const Instance *inst);
State *native_state(Instance *inst);
Fmi2Layer *native_layer(Instance *inst);
/* instantiated as fmi2ModelExchange */
int native_model_exchange(const Instance *inst);
/* The state table (fmi2_calls.h) for this instance: its state there (its phase; Model Exchange: event or
   continuous-time mode when running), and the check of call F against the table of its interface (FMI2_MASK_F or
   FMI2ME_MASK_F): fmi2OK, or the refusal (logged, the error mode). NATIVE_ALLOWED returns the refusal. */
int native_table_state(const Instance *inst);
fmi2Status native_allowed(Instance *inst, const char *call, unsigned cs, unsigned me);
#define NATIVE_ALLOWED(I, F)                                                                                      \
    do {                                                                                                          \
        fmi2Status allowed_ = native_allowed((I), #F, FMI2_MASK_##F, FMI2ME_MASK_##F);                            \
        if (allowed_ != fmi2OK) return allowed_;                                                                  \
    } while (0)
/* fmi2Error (the error mode) when the status flag says a call failed, else fmi2OK */
fmi2Status native_settle(Instance *inst);
/* FMI 3.0 co-simulation with early return: fmi2DoStep steps with model_do_step_early (me_model.h) */
void native_set_early_return(Instance *inst, int on);
/* The solver steps taken so far by the current FMI 3.0 doStep (fmi3_native.c sets 0 before its first internal
   doStep; model_do_step_early adds its steps and stops at the step budget): the budget bounds the whole call */
double *native_call_steps(Instance *inst);

/* ---- provided by each model (native_model.c) ---- */
/* After the generic start values are in value[]: the model's own defaults. */
void model_instantiate(State *s);
/* fmi2ExitInitializationMode, after every parameter passed the table of rules (rules.h): the model's own
   checks, build the model, publish the first outputs; report failures with
   native_halt (the instance then refuses doStep). */
void model_initialise(Instance *inst, State *s);
/* After fmi2SetXXX set input vr (its new value is in s->value[vr]). */
void model_input_set(Instance *inst, State *s, fmi2ValueReference vr);
/* fmi2DoStep from t over h (s->halted is 0); failures through native_error / native_halt. */
void model_do_step(Instance *inst, State *s, double t, double h);
/* fmi2GetXXX of output vr in Initialization Mode (FMI 2.0: from the start values set so far): 1 and *value, or 0
   and why it cannot be defined in `why` (a ParameterError's or exception's text). */
int model_initial_output(const State *s, fmi2ValueReference vr, double *value, char *why, size_t size);
/* The first rule of the table (rules.h, in its order) that one of `names`' values breaks: 1 and its ParameterError
   text "parameter NAME = VALUE: reason" in `why`, else 0 (vibromodel.parameters.check_parameters on those names). */
int native_rule_refusal(const State *s, const char *const names[], size_t n, char *why, size_t size);

#endif
