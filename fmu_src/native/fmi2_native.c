/*
 * fmi2_native.c -- FMI 2.0 co-simulation API of a native vibrofmu FMU (see fmi2_native.h).
 *
 * Compiled once per model with that model's folder (config.h, model.c) and its generated variables.h on the
 * include path.  No global state: every instance is independent.
 */
#include "fmi2_native.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "me_model.h"
#include "pytext.h"
#include "rules.h"
#include "rule_index.h" /* RULE_VR, RULE_WHEN_VR: each rule's parameters by value reference */
#include "state_checks.h"

#define EXPORT FMI2_Export /* fmi2Functions.h: dllexport on Windows, default visibility elsewhere */

#define STOP_TIME_TOLERANCE 1e-9 /* slave_support.STOP_TIME_TOLERANCE */
#define FLAG_OK 0
#define FLAG_ERROR 3

struct Instance {
    Fmi2Layer fmi; /* callbacks, name, logging, error mode (FMI2_MODE_ERROR: a state-changing call ended in fmi2Error) */
    State s;
    int model_exchange; /* instantiated as fmi2ModelExchange (fmi2_me.c) */
    int early_return;   /* FMI 3.0 co-simulation with early return (fmi3_native.c): doStep is model_do_step_early */
    double call_steps;  /* the solver steps the current fmi3DoStep has taken so far, over its internal doSteps */
};

/* The serialized FMU state: this header, then the State's bytes. */
typedef struct {
    char format[64];
    uint64_t size;
    uint64_t checksum; /* state_checksum of the State's bytes */
} StateHeader;

/* FNV-1a (64 bit) of n bytes.  Each step (xor a byte, multiply by an odd constant modulo 2^64) is a bijection of
   the running value, so a change confined to one byte -- every single-bit flip -- always changes the result; other
   changes go unnoticed with probability about 2^-64.  Like the Python states' SHA-256 it detects accidents, not a
   forger who recomputes it. */
static uint64_t state_checksum(const unsigned char *bytes, size_t n)
{
    uint64_t h = 14695981039346656037ULL;
    for (size_t i = 0; i < n; i++) {
        h ^= bytes[i];
        h *= 1099511628211ULL;
    }
    return h;
}

/* ---- logging (fmi2_layer.c) ---- */

void native_log(Instance *inst, fmi2Status status, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    fmi2_layer_vlog(&inst->fmi, status, format, args);
    va_end(args);
}

void native_error(Instance *inst, const char *format, ...)
{
    va_list args;
    inst->s.value[VR_fmi_status] = FLAG_ERROR;
    va_start(args, format);
    fmi2_layer_vlog(&inst->fmi, fmi2Error, format, args);
    va_end(args);
}

void native_halt(Instance *inst, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(inst->s.halt_message, sizeof inst->s.halt_message, format, args);
    va_end(args);
    inst->s.halted = 1;
    native_error(inst, "%s", inst->s.halt_message);
}

void native_halt_parameter(Instance *inst, const char *name, double value, int integer, const char *reason)
{
    char text[64];
    if (integer) snprintf(text, sizeof text, "%d", (int)value);
    else native_repr(value, text, sizeof text);
    native_halt(inst, "parameter %s = %s: %s", name, text, reason);
}

int native_logging_on(const Instance *inst) { return inst->fmi.logging_on; }
State *native_state(Instance *inst) { return &inst->s; }
Fmi2Layer *native_layer(Instance *inst) { return &inst->fmi; }
int native_model_exchange(const Instance *inst) { return inst->model_exchange; }
void native_set_early_return(Instance *inst, int on) { inst->early_return = on != 0; }

double *native_call_steps(Instance *inst) { return &inst->call_steps; }

/* ---- the FMI state machine: the state table (fmi2_calls.h), asked through fmi2_layer.c ---- */

/* The instance's state in the table: its phase; a Model Exchange instance's running phase is its mode. */
int native_table_state(const Instance *inst)
{
#ifdef ME_N_STATES
    if (inst->model_exchange && inst->s.phase == PHASE_STEP_MODE)
        return inst->s.model.me.mode == ME_CONTINUOUS_TIME_MODE ? FMI2_CONTINUOUS_TIME_MODE : FMI2_EVENT_MODE;
#endif
    return (int)inst->s.phase;
}

/* Call `call` (co-simulation mask cs, Model Exchange mask me: the table of the instance's interface): fmi2OK when
   the table allows it now; else its answer (the error mode's, or fmi2Error with the table's refusal logged). */
static fmi2Status native_refused(Instance *inst, const char *call, unsigned mask);

fmi2Status native_allowed(Instance *inst, const char *call, unsigned cs, unsigned me)
{
    const unsigned mask = inst->model_exchange ? me : cs;
    fmi2Status st = fmi2_layer_mode_check(&inst->fmi, call, mask);
    if (st != fmi2OK || (mask & FMI2_BIT(native_table_state(inst)))) return st;
    return native_refused(inst, call, mask);
}

/* native_allowed's refusal, apart (noinline): the allowed call, every call of a running simulation, then inlines
   into the FMI functions without the refusal's text buffer on its stack */
static __attribute__((noinline)) fmi2Status native_refused(Instance *inst, const char *call, unsigned mask)
{
    char why[256];
    const int me_table = inst->model_exchange;
    native_error(inst, "%s", fmi_call_refusal(me_table ? FMI2ME_LABEL : FMI2_LABEL,
                                              me_table ? FMI2ME_INTERFACE : FMI2_INTERFACE, call, mask,
                                              native_table_state(inst), why, sizeof why));
    return native_settle(inst);
}

/* The current value of variable vr as Python prints it (repr). */
static void value_text(const State *s, fmi2ValueReference vr, char *out, size_t size)
{
    const VariableInfo *v = &VARIABLES[vr];
    if (v->type == T_REAL) native_repr(s->value[vr], out, size);
    else if (v->type == T_INTEGER) snprintf(out, size, "%d", (int)s->value[vr]);
    else snprintf(out, size, "%s", s->value[vr] != 0.0 ? "True" : "False");
}

_Static_assert(N_RULE_INDEX == N_RULES, "rule_index.h and rules.h were generated from different rule tables");

/* StatusSlave._initialise's first step, parameters.check_parameters: the first parameter (in the table's
   order) out of its range halts the instance, naming it.  rtol is the experiment's tolerance when
   fmi2SetupExperiment gave one (StatusSlave._parameter_values).  The parameters of rule r are RULE_VR[r] and
   RULE_WHEN_VR[r] (rule_index.h, generated: the first parameter of that name, -1 when the model has none). */

/* Rule.refusal is None: the value is in the rule's range (or its automatic value). */
static int obeys(const VibroRule *rule, double number)
{
    if (rule->has_automatic && number == rule->automatic) return 1;
    int ok = isfinite(number) && (!rule->integer || number == trunc(number));
    ok = ok && (rule->low_inclusive ? number >= rule->low : number > rule->low);
    ok = ok && (rule->high_inclusive ? number <= rule->high : number < rule->high);
    return ok;
}

/* An input's rule (check_parameters({name: value}) in the controller slave's _set_input): its refusal text
   when the value breaks it, else NULL (inputs without a rule, e.g. the plant's U, take any value). */
static const char *input_refusal(fmi2ValueReference vr, double number)
{
    for (size_t r = 0; r < N_RULES; r++)
        if (RULES[r].when == NULL && strcmp(RULES[r].name, VARIABLES[vr].name) == 0 && !obeys(&RULES[r], number))
            return RULES[r].text;
    return NULL;
}

static int check_parameters(Instance *inst)
{
    for (size_t r = 0; r < N_RULES; r++) {
        const VibroRule *rule = &RULES[r];
        int vr = RULE_VR[r];
        if (vr < 0) continue;
        if (rule->when != NULL) {
            int other = RULE_WHEN_VR[r];
            int applies = 0;
            for (int k = 0; other >= 0 && k < rule->n_when; k++)
                if (inst->s.value[other] == rule->when_values[k]) applies = 1;
            if (!applies) continue;
        }
        double number = inst->s.value[vr];
        int tolerance = inst->s.has_tolerance && strcmp(rule->name, "rtol") == 0;
        if (tolerance) number = inst->s.tolerance;
        if (obeys(rule, number)) continue;
        char text[64];
        if (tolerance) native_repr(number, text, sizeof text);
        else value_text(&inst->s, (fmi2ValueReference)vr, text, sizeof text);
        native_halt(inst, "parameter %s = %s: %s", rule->name, text, rule->text);
        return 0;
    }
    return 1;
}


int native_rule_refusal(const State *s, const char *const names[], size_t n, char *why, size_t size)
{
    for (size_t r = 0; r < N_RULES; r++) {
        const VibroRule *rule = &RULES[r];
        int listed = 0, vr = RULE_VR[r];
        for (size_t k = 0; k < n; k++) listed |= strcmp(names[k], rule->name) == 0;
        if (!listed || vr < 0) continue;
        if (rule->when != NULL) { /* Rule.applies: the condition's parameter must be among the names */
            int other = RULE_WHEN_VR[r], applies = 0, named = 0;
            for (size_t k = 0; k < n; k++) named |= strcmp(names[k], rule->when) == 0;
            for (int k = 0; named && other >= 0 && k < rule->n_when; k++)
                if (s->value[other] == rule->when_values[k]) applies = 1;
            if (!applies) continue;
        }
        if (obeys(rule, s->value[vr])) continue;
        char text[64];
        value_text(s, (fmi2ValueReference)vr, text, sizeof text);
        snprintf(why, size, "parameter %s = %s: %s", rule->name, text, rule->text);
        return 1;
    }
    return 0;
}

static fmi2Status settle(Instance *inst, int may_clear_error)
{
    if (inst->s.value[VR_fmi_status] == FLAG_ERROR) {
        inst->fmi.mode = FMI2_MODE_ERROR;
        return fmi2Error;
    }
    if (may_clear_error) inst->fmi.mode = FMI2_MODE_OK;
    return fmi2OK;
}

fmi2Status native_settle(Instance *inst) { return settle(inst, 0); }

/* A live instance of this binary (fmi2_live: never a freed, foreign or NULL pointer), else fmi2Error */
#define INST(c) Instance *I = (Instance *)(c); if (!fmi2_live(I, FMI2_LIVE_INSTANCE)) return fmi2Error
/* The pointer arguments of call F: an array of n values (or a result pointer) that is NULL is refused (logged). */
#define ARRAYS(F, n, a, b) FMI2_ARRAYS(&I->fmi, #F, n, a, b)
#define POINTER(F, p) do { if (FMI2_NULL_POINTER(&I->fmi, #F, p) != fmi2OK) return fmi2Error; } while (0)
/* The state table's guard of call F (native_allowed): returns the refusal unless the table allows F now. */
#define ALLOWED(F) NATIVE_ALLOWED(I, F)

static void reset_state(State *s)
{
    memset(s, 0, sizeof *s);
    for (size_t i = 0; i < N_VARIABLES; i++) s->value[i] = VARIABLES[i].start;
    s->value[VR_fmi_status] = FLAG_OK;
    s->phase = PHASE_INSTANTIATED;
    s->halted = 1;
    snprintf(s->halt_message, sizeof s->halt_message, "the FMU has not been initialised");
    model_instantiate(s);
}

/* state_checks.c: what a state's own parameters build (ExitInitializationMode in a silent scratch instance). */
int native_rebuild(const State *s, State *fresh)
{
    Instance *scratch = calloc(1, sizeof *scratch);
    int built = 0;
    if (scratch != NULL && fmi2_layer_init(&scratch->fmi, "state check", NULL, 0)) {
        State *r = &scratch->s;
        reset_state(r);
        for (size_t i = 0; i < N_VARIABLES; i++) /* the parameters; inputs and outputs keep their start values */
            if (VARIABLES[i].causality == C_PARAMETER) r->value[i] = s->value[i];
        r->start_time = s->start_time;
        r->has_stop = s->has_stop;
        r->stop_time = s->stop_time;
        r->has_tolerance = s->has_tolerance;
        r->tolerance = s->tolerance;
        r->phase = PHASE_STEP_MODE;
        r->initialised = 1;
        if (check_parameters(scratch)) {
            r->halted = 0;
            r->halt_message[0] = '\0';
            model_initialise(scratch, r);
        }
        built = r->model.built != 0; /* halted or not: an initialisation that fails after building (halted) too */
        memcpy(fresh, r, sizeof *fresh);
        fmi2_layer_free(&scratch->fmi);
    }
    free(scratch);
    return built;
}

/* ---- API ---- */

EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)visible;
    Instance *inst = calloc(1, sizeof *inst);
    if (inst == NULL) return NULL;
    if (!fmi2_layer_init(&inst->fmi, instanceName, functions, loggingOn)) { free(inst); return NULL; }
#ifdef ME_N_STATES
    inst->model_exchange = fmuType == fmi2ModelExchange;
#endif
    char resources[4096]; /* unused: the native FMUs need no resources, but the location must be a folder */
    if (!fmi2_instantiate_check(&inst->fmi, instanceName, MODEL_IDENTIFIER, fmuType, NATIVE_FMU_TYPES, fmuGUID, FMU_GUID,
                                fmuResourceLocation, resources, sizeof resources)) {
        fmi2_layer_free(&inst->fmi);
        free(inst);
        return NULL;
    }
    reset_state(&inst->s);
    if (!fmi2_live_add(inst, FMI2_LIVE_INSTANCE)) {
        fmi2_layer_log(&inst->fmi, fmi2Error, "fmi2Instantiate: out of memory");
        fmi2_layer_free(&inst->fmi);
        free(inst);
        return NULL;
    }
    return inst;
}

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Instance *I = (Instance *)c;
    if (!fmi2_live_remove(I, FMI2_LIVE_INSTANCE)) return; /* NULL, freed already, or not this binary's */
    fmi2_layer_free(&I->fmi);
    free(I);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String cats[])
{
    INST(c); ALLOWED(fmi2SetDebugLogging);
    return fmi2_layer_debug_logging(&I->fmi, loggingOn, n, cats);
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real tStart,
                                      fmi2Boolean stopDef, fmi2Real tStop)
{
    INST(c); ALLOWED(fmi2SetupExperiment);
    I->s.start_time = tStart;
    I->s.has_stop = stopDef != 0;
    I->s.stop_time = stopDef ? tStop : 0.0;
    I->s.has_tolerance = tolDef != 0;
    I->s.tolerance = tolDef ? tol : 0.0;
    return settle(I, 0);
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    INST(c); ALLOWED(fmi2EnterInitializationMode);
    I->s.phase = PHASE_INITIALIZATION_MODE;
    return settle(I, 0);
}

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    INST(c); ALLOWED(fmi2ExitInitializationMode);
    I->s.phase = PHASE_STEP_MODE;
    I->s.initialised = 1;
    if (check_parameters(I)) { /* StatusSlave._initialise: the table, then the model */
        I->s.halted = 0;
        I->s.halt_message[0] = '\0';
        model_initialise(I, &I->s);
#ifdef ME_N_STATES
        if (I->model_exchange && !I->s.halted) {
            I->s.model.me.mode = ME_EVENT_MODE; /* Model Exchange leaves initialisation in event mode */
            I->s.model.me.stopped = 0;
            model_me_start(I, &I->s);
        }
#endif
    }
    return settle(I, 0);
}

EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    INST(c); ALLOWED(fmi2Terminate);
    I->s.phase = PHASE_TERMINATED;
    I->s.halted = 1;
    snprintf(I->s.halt_message, sizeof I->s.halt_message,
             "fmi2Terminate was called (FMI 2.0: only fmi2Reset or fmi2FreeInstance may follow)");
    return settle(I, 0);
}

EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    INST(c); ALLOWED(fmi2Reset);
    reset_state(&I->s);
    return settle(I, 1);
}

static const char *const TYPE_NAMES[] = {"Real", "Integer", "Boolean"};
/* the states in which the getters read any variable (the table's; elsewhere only the status flag fmi_status) */
#define GET_ANY_VARIABLE(I) ((I)->model_exchange ? FMI2ME_GET_ANY_VARIABLE : FMI2_GET_ANY_VARIABLE)

/* StatusSlave._get_values: an unknown value reference, a wrong type, or any variable but fmi_status before
   fmi2EnterInitializationMode is an error (logged; that value reads as 0); then the call returns fmi2Error and
   the instance is in the error state (the status shim's checked_getter). */
static fmi2Status get_values(Instance *I, const fmi2ValueReference vr[], size_t nvr, const char *type,
                             int type_index, const char *call, double out[])
{
    int failed = 0;
    for (size_t i = 0; i < nvr; i++) {
        out[i] = 0.0;
        if (vr[i] >= N_VARIABLES) {
            native_error(I, "%s: no variable has valueReference %u", call, vr[i]);
        } else if (type_index < 0 || (int)VARIABLES[vr[i]].type != type_index) {
            native_error(I, "%s: variable %s (valueReference %u) is a %s, not a %s", call, VARIABLES[vr[i]].name,
                         vr[i], TYPE_NAMES[VARIABLES[vr[i]].type], type);
        } else if (!(GET_ANY_VARIABLE(I) & FMI2_BIT(native_table_state(I))) && vr[i] != VR_fmi_status) {
            native_error(I, "%s of %s is not allowed in the instantiated state (FMI 2.0 allows it from "
                         "fmi2EnterInitializationMode on)", call, VARIABLES[vr[i]].name);
        } else if (I->s.phase == PHASE_INITIALIZATION_MODE && VARIABLES[vr[i]].causality == C_OUTPUT) {
            char why[512]; /* StatusSlave._get_values: outputs follow the start values set so far */
            if (model_initial_output(&I->s, vr[i], &out[i], why, sizeof why)) continue;
            out[i] = 0.0;
            native_error(I, "%s of %s in the initialization mode state: %s", call, VARIABLES[vr[i]].name, why);
        } else {
#ifdef MODEL_LAZY_LOCALS
            if (VARIABLES[vr[i]].causality == C_LOCAL) model_lazy_locals(&I->s); /* me_model.h */
#endif
#ifdef MODEL_LAZY_OUTPUTS
            if (VARIABLES[vr[i]].causality == C_OUTPUT) model_lazy_outputs(&I->s, vr[i]); /* me_model.h */
#endif
            out[i] = I->s.value[vr[i]];
            continue;
        }
        failed = 1;
    }
    if (failed) {
        I->fmi.mode = FMI2_MODE_ERROR;
        return fmi2Error;
    }
    return fmi2OK;
}

#define MAX_GET 64
#define GETTER(Name, T, TYPE, CONVERT, CHECK)                                                             \
    EXPORT fmi2Status fmi2Get##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, T value[])  \
    {                                                                                                     \
        INST(c); ALLOWED(fmi2Get##Name); ARRAYS(fmi2Get##Name, nvr, vr, value);                            \
        fmi2Status worst = fmi2OK;                                                                        \
        for (size_t done = 0; done < nvr; done += MAX_GET) {                                              \
            size_t n = nvr - done < MAX_GET ? nvr - done : MAX_GET;                                       \
            double values[MAX_GET];                                                                       \
            fmi2Status st = get_values(I, vr + done, n, #Name, TYPE, "fmi2Get" #Name, values);            \
            for (size_t i = 0; i < n; i++) value[done + i] = CONVERT(values[i]);                          \
            if (st > worst) worst = st;                                                                   \
        }                                                                                                 \
        return CHECK(worst);                                                                              \
    }
#define AS_INTEGER(v) ((fmi2Integer)(v))
#define AS_BOOLEAN(v) ((v) != 0.0)
#define NO_CHECK(st) (st)
#define FINITE_CHECK(st) fmi2_layer_finite_reals(&I->fmi, (st), vr, nvr, value)

/* fmi2GetReal: GETTER's, the values read straight into the caller's array (fmi2Real is double: no staging array,
   no copy; get_values reads any number of them) */
EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    INST(c); ALLOWED(fmi2GetReal); ARRAYS(fmi2GetReal, nvr, vr, value);
    return FINITE_CHECK(get_values(I, vr, nvr, "Real", T_REAL, "fmi2GetReal", value));
}
GETTER(Integer, fmi2Integer, T_INTEGER, AS_INTEGER, NO_CHECK)
GETTER(Boolean, fmi2Boolean, T_BOOLEAN, AS_BOOLEAN, NO_CHECK)

EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    INST(c); ALLOWED(fmi2GetString); ARRAYS(fmi2GetString, nvr, vr, value);
    fmi2Status worst = fmi2OK;
    for (size_t i = 0; i < nvr; i++) {
        double ignored;
        value[i] = "";
        fmi2Status st = get_values(I, vr + i, 1, "String", -1, "fmi2GetString", &ignored);
        if (st > worst) worst = st;
    }
    return worst;
}

/* StatusSlave._set_refusal: why FMI 2.0 forbids setting variable vr now, or NULL. */
static const char *set_refusal(Instance *I, fmi2ValueReference vr, char *buf, size_t size)
{
    const VariableInfo *v = &VARIABLES[vr];
    static const char *const CAUSALITY[] = {"parameter", "input", "output", "local"};
    if (v->causality == C_INPUT) return NULL;
    if (v->causality == C_PARAMETER && strcmp(v->variability, "tunable") == 0) return NULL;
    if (!v->settable_start) {
        snprintf(buf, size, "a %s variable computed by the FMU cannot be set", CAUSALITY[v->causality]);
        return buf;
    }
    if (I->s.initialised) {
        char current[64];
#ifdef MODEL_LAZY_OUTPUTS
        if (v->causality == C_OUTPUT) model_lazy_outputs(&I->s, vr); /* me_model.h: the value it keeps */
#endif
        value_text(&I->s, vr, current, sizeof current);
        snprintf(buf, size, "a %s %s cannot be set after fmi2ExitInitializationMode (FMI 2.0: only inputs and "
                 "tunable parameters); it keeps %s", v->variability, CAUSALITY[v->causality], current);
        return buf;
    }
    if (v->causality == C_OUTPUT) /* its start value is the model's initial output */
        return "an output is computed by the FMU from its parameters (x_start, v_start, ...); setting it would be "
               "ignored, so it is refused";
    return NULL;
}

/* StatusSlave._set_values: each refusal logged as ParameterError(name, value, reason), the rest set. */
static fmi2Status set_values(Instance *I, const fmi2ValueReference vr[], size_t nvr, VarType type,
                             const double value[], const char *const text[])
{
    char reason[512], name[96];
    for (size_t i = 0; i < nvr; i++) {
        const char *refusal;
        if (vr[i] >= N_VARIABLES) {
            snprintf(name, sizeof name, "with valueReference %u", vr[i]);
            refusal = "no such variable";
        } else {
            snprintf(name, sizeof name, "%s", VARIABLES[vr[i]].name);
            refusal = set_refusal(I, vr[i], reason, sizeof reason);
            if (refusal == NULL && VARIABLES[vr[i]].type != type) { /* pythonfmu's TypeError */
                snprintf(reason, sizeof reason, "Variable with valueReference=%u is not of type %s!", vr[i],
                         TYPE_NAMES[type]);
                refusal = reason;
            }
            if (refusal == NULL && VARIABLES[vr[i]].causality == C_INPUT) refusal = input_refusal(vr[i], value[i]);
        }
        if (refusal == NULL) {
            I->s.value[vr[i]] = value[i];
            if (VARIABLES[vr[i]].causality == C_INPUT) model_input_set(I, &I->s, vr[i]);
            continue;
        }
        native_error(I, "parameter %s = %s: %s", name, text[i], refusal);
    }
    return settle(I, 0);
}

#define MAX_SET 64
#define SETTER(Name, T, Type, FORMAT)                                                                     \
    EXPORT fmi2Status fmi2Set##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const T value[]) \
    {                                                                                                     \
        INST(c); ALLOWED(fmi2Set##Name); ARRAYS(fmi2Set##Name, nvr, vr, value);                            \
        fmi2Status worst = fmi2OK;                                                                        \
        for (size_t done = 0; done < nvr; done += MAX_SET) {                                              \
            size_t n = nvr - done < MAX_SET ? nvr - done : MAX_SET;                                       \
            double values[MAX_SET];                                                                       \
            char texts[MAX_SET][48];                                                                      \
            const char *text[MAX_SET];                                                                    \
            for (size_t i = 0; i < n; i++) {                                                              \
                values[i] = (double)value[done + i];                                                      \
                FORMAT(value[done + i], texts[i], sizeof texts[i]);                                       \
                text[i] = texts[i];                                                                       \
            }                                                                                             \
            fmi2Status st = set_values(I, vr + done, n, Type, values, text);                              \
            if (st > worst) worst = st;                                                                   \
        }                                                                                                 \
        return worst;                                                                                     \
    }
#define FORMAT_REAL(v, out, size) native_repr(v, out, size)
#define FORMAT_INTEGER(v, out, size) snprintf(out, size, "%d", (int)(v))
#define FORMAT_BOOLEAN(v, out, size) snprintf(out, size, "%s", (v) ? "True" : "False")
SETTER(Real, fmi2Real, T_REAL, FORMAT_REAL)
SETTER(Integer, fmi2Integer, T_INTEGER, FORMAT_INTEGER)
SETTER(Boolean, fmi2Boolean, T_BOOLEAN, FORMAT_BOOLEAN)

EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    INST(c); ALLOWED(fmi2SetString); ARRAYS(fmi2SetString, nvr, vr, value);
    for (size_t i = 0; i < nvr; i++) {
        char quoted[256];
        quoted_text(value[i] ? value[i] : "", quoted, sizeof quoted);
        if (vr[i] >= N_VARIABLES)
            native_error(I, "parameter with valueReference %u = %s: no such variable", vr[i], quoted);
        else
            native_error(I, "parameter %s = %s: Variable with valueReference=%u is not of type String!",
                         VARIABLES[vr[i]].name, quoted, vr[i]);
    }
    return settle(I, 0);
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior)
{
    INST(c);
    (void)noSetPrior;
    /* StatusSlave._step_allowed: step mode only (a terminated instance says why it halted), and not beyond the
       declared stop time */
    if (!I->model_exchange && native_table_state(I) == FMI2_TERMINATED &&
        fmi2_layer_mode_check(&I->fmi, "fmi2DoStep", FMI2_MASK_fmi2DoStep) == fmi2OK) {
        native_error(I, "doStep refused: %s", I->s.halt_message);
        return settle(I, 0);
    }
    ALLOWED(fmi2DoStep);
    if (I->s.has_stop) {
        const double stop = I->s.stop_time, magnitude = fabs(stop);  /* fmax(1.0, |stop|), without the call */
        const double end = stop + STOP_TIME_TOLERANCE * (magnitude > 1.0 ? magnitude : 1.0);
        if (isfinite(t) && isfinite(h) && t <= end && end < t + h) {
            char a[64], b[64], e[64], f[64];
            native_repr(h, a, sizeof a);
            native_repr(t, b, sizeof b);
            native_repr(t + h, e, sizeof e);
            native_repr(stop, f, sizeof f);
            native_error(I, "parameter communicationStepSize = %s: the step from tau = %s would end at tau = %s, "
                         "beyond the stop time %s declared in fmi2SetupExperiment", a, b, e, f);
            return settle(I, 0);
        }
    }
    if (I->s.halted) {
        native_error(I, "doStep refused: %s", I->s.halt_message);
        return settle(I, 0);
    }
#ifdef HAS_EARLY_RETURN
    if (I->early_return) {
        model_do_step_early(I, &I->s, t, h);
        return settle(I, 0);
    }
#endif
    model_do_step(I, &I->s, t, h);
    return settle(I, 0);
}

EXPORT fmi2Status fmi2CancelStep(fmi2Component c)
{
    INST(c); ALLOWED(fmi2CancelStep);
    native_log(I, fmi2Error, "fmi2CancelStep: doStep always completes (no asynchronous steps)");
    return fmi2Error;
}

/* ---- FMU state: a copy of the State ---- */

#define refuse_null(I, call, argument) fmi2_layer_null_refusal(&(I)->fmi, (call), (argument), NULL, 0)
/* A state pointer that is not a live state of this binary (freed, another FMU's, made up): never read or written. */
#define foreign_state(I, call, state) fmi2_layer_foreign_state(&(I)->fmi, (call), (state))

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    INST(c); ALLOWED(fmi2GetFMUstate);
    if (state == NULL) return refuse_null(I, "fmi2GetFMUstate", "FMUstate (the pointer to store it in)");
    if (*state != NULL && foreign_state(I, "fmi2GetFMUstate", *state)) return fmi2Error;
    State *copy = *state != NULL ? (State *)*state : malloc(sizeof *copy);
    if (copy == NULL || (*state == NULL && !fmi2_live_add(copy, FMI2_LIVE_STATE))) {
        if (*state == NULL) free(copy);
        native_log(I, fmi2Error, "fmi2GetFMUstate: out of memory");
        return fmi2Error;
    }
    memcpy(copy, &I->s, sizeof *copy);
    *state = copy;
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    INST(c); ALLOWED(fmi2SetFMUstate);
    if (state == NULL) return refuse_null(I, "fmi2SetFMUstate", "FMUstate (no state given)");
    if (foreign_state(I, "fmi2SetFMUstate", state)) return fmi2Error;
    /* A live state is either a copy of an instance's own State (fmi2GetFMUstate) or one that
       fmi2DeSerializeFMUstate validated in full (native_state_refusal: its fields and constants, whatever instance
       restores it): its content is not checked again here.  Its interface is: a state may be set into another
       instance of this binary than the one that made or deserialized it. */
    char why[512];
    if (native_interface_refusal((const State *)state, I->model_exchange, why, sizeof why)) {
        native_log(I, fmi2Error, "fmi2SetFMUstate refused: %s", why);
        return fmi2Error;
    }
    memcpy(&I->s, state, sizeof I->s);
    if (I->s.value[VR_fmi_status] == FLAG_ERROR)
        native_log(I, fmi2Error, "restored a state saved after an error: %s",
                   I->s.halted ? I->s.halt_message : "a call had failed");
    return settle(I, 1);
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    INST(c); ALLOWED(fmi2FreeFMUstate);
    if (state == NULL || *state == NULL) return fmi2OK; /* nothing to free (FMI 2.0: a no-op) */
    if (foreign_state(I, "fmi2FreeFMUstate", *state)) return fmi2Error;
    fmi2_live_remove(*state, FMI2_LIVE_STATE);
    free(*state);
    *state = NULL;
    return fmi2OK;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    INST(c); ALLOWED(fmi2SerializedFMUstateSize);
    if (state == NULL) return refuse_null(I, "fmi2SerializedFMUstateSize", "FMUstate");
    if (size == NULL) return refuse_null(I, "fmi2SerializedFMUstateSize", "size (the pointer to store it in)");
    if (foreign_state(I, "fmi2SerializedFMUstateSize", state)) return fmi2Error;
    *size = sizeof(StateHeader) + sizeof(State);
    return fmi2OK;
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    INST(c); ALLOWED(fmi2SerializeFMUstate);
    if (bytes == NULL) return refuse_null(I, "fmi2SerializeFMUstate", "serializedState (the buffer)");
    if (state != NULL && foreign_state(I, "fmi2SerializeFMUstate", state)) return fmi2Error;
    if (state == NULL || size < sizeof(StateHeader) + sizeof(State)) {
        native_log(I, fmi2Error, "fmi2SerializeFMUstate: no state, or %zu bytes are too few", size);
        return fmi2Error;
    }
    StateHeader header;
    memset(&header, 0, sizeof header);
    snprintf(header.format, sizeof header.format, "%s", STATE_FORMAT);
    header.size = sizeof(State);
    header.checksum = state_checksum((const unsigned char *)state, sizeof(State));
    memcpy(bytes, &header, sizeof header);
    memcpy(bytes + sizeof header, state, sizeof(State));
    return fmi2OK;
}

EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state)
{
    INST(c); ALLOWED(fmi2DeSerializeFMUstate);
    if (bytes == NULL) return refuse_null(I, "fmi2DeSerializeFMUstate", "serializedState (the bytes)");
    if (state == NULL) return refuse_null(I, "fmi2DeSerializeFMUstate", "FMUstate (the pointer to store it in)");
    if (*state != NULL && foreign_state(I, "fmi2DeSerializeFMUstate", *state)) return fmi2Error;
    StateHeader header;
    if (size != sizeof header + sizeof(State)) {
        native_log(I, fmi2Error, "fmi2DeSerializeFMUstate refused: not a state of this FMU (%zu bytes, expected "
                   "%zu)", size, sizeof header + sizeof(State));
        return fmi2Error;
    }
    memcpy(&header, bytes, sizeof header);
    char format[sizeof header.format] = {0}; /* every byte of the field: the name, then zeros */
    snprintf(format, sizeof format, "%s", STATE_FORMAT);
    if (memcmp(header.format, format, sizeof format) != 0 || header.size != sizeof(State)) {
        native_log(I, fmi2Error, "fmi2DeSerializeFMUstate refused: not a state of this FMU (format %.63s, "
                   "expected %s)", header.format, STATE_FORMAT);
        return fmi2Error;
    }
    if (header.checksum != state_checksum((const unsigned char *)bytes + sizeof header, sizeof(State))) {
        native_log(I, fmi2Error, "fmi2DeSerializeFMUstate refused: the state's checksum does not match its content "
                   "(a damaged state)");
        return fmi2Error;
    }
    char why[512];
    State *copy = malloc(sizeof *copy);
    if (copy == NULL) return fmi2Error;
    memcpy(copy, bytes + sizeof header, sizeof *copy);
    if (native_interface_refusal(copy, I->model_exchange, why, sizeof why) ||
        native_state_refusal(copy, &I->s, why, sizeof why)) { /* a forged state: the checksum recomputed (issue 25) */
        free(copy);
        native_log(I, fmi2Error, "fmi2DeSerializeFMUstate refused: %s", why);
        return fmi2Error;
    }
    if (*state != NULL) { /* FMI 2.0: an existing state is overwritten */
        memcpy(*state, copy, sizeof *copy);
        free(copy);
        return fmi2OK;
    }
    if (!fmi2_live_add(copy, FMI2_LIVE_STATE)) {
        free(copy);
        native_log(I, fmi2Error, "fmi2DeSerializeFMUstate: out of memory");
        return fmi2Error;
    }
    *state = copy;
    return fmi2OK;
}

/* ---- not provided by a co-simulation FMU without these capabilities ---- */

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vU[], size_t nU,
                                               const fmi2ValueReference vK[], size_t nK,
                                               const fmi2Real dvK[], fmi2Real dvU[])
{
    INST(c); ALLOWED(fmi2GetDirectionalDerivative);
    ARRAYS(fmi2GetDirectionalDerivative, nU, vU, dvU);
    ARRAYS(fmi2GetDirectionalDerivative, nK, vK, dvK);
#ifdef HAS_DIRECTIONAL_DERIVATIVES
    return native_directional_derivative(I, vU, nU, vK, nK, dvK, dvU); /* fmi2_me.c */
#endif
    (void)vU; (void)nU; (void)vK; (void)nK; (void)dvK; (void)dvU;
    native_log(I, fmi2Error, "fmi2GetDirectionalDerivative is not provided (providesDirectionalDerivative=false)");
    return fmi2Error;
}

EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[])
{
    INST(c); ALLOWED(fmi2SetRealInputDerivatives);
    ARRAYS(fmi2SetRealInputDerivatives, nvr, vr, value);
    ARRAYS(fmi2SetRealInputDerivatives, nvr, order, value);
    (void)vr; (void)nvr; (void)order; (void)value;
    native_log(I, fmi2Error, "fmi2SetRealInputDerivatives is not provided (canInterpolateInputs=false)");
    return fmi2Error;
}

EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[])
{
    INST(c); ALLOWED(fmi2GetRealOutputDerivatives);
    ARRAYS(fmi2GetRealOutputDerivatives, nvr, vr, value);
    ARRAYS(fmi2GetRealOutputDerivatives, nvr, order, value);
    (void)vr; (void)nvr; (void)order; (void)value;
    native_log(I, fmi2Error, "fmi2GetRealOutputDerivatives is not provided (maxOutputDerivativeOrder=0)");
    return fmi2Error;
}

EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    INST(c); ALLOWED(fmi2GetStatus); POINTER(fmi2GetStatus, value);
    if (s != fmi2DoStepStatus) return fmi2Discard;
    *value = I->fmi.mode == FMI2_MODE_OK ? fmi2OK : fmi2Error;
    return fmi2OK;
}

/* The other status queries: no such status (fmi2Discard), after the table and the pointer checks */
#define NO_STATUS(Name, T)                                                                                        \
    EXPORT fmi2Status fmi2Get##Name(fmi2Component c, const fmi2StatusKind s, T *value)                            \
    {                                                                                                             \
        INST(c); ALLOWED(fmi2Get##Name); POINTER(fmi2Get##Name, value);                                           \
        (void)s;                                                                                                  \
        return fmi2Discard;                                                                                       \
    }
NO_STATUS(RealStatus, fmi2Real)
NO_STATUS(IntegerStatus, fmi2Integer)
NO_STATUS(BooleanStatus, fmi2Boolean)
NO_STATUS(StringStatus, fmi2String)
