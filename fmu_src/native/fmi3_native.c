/*
 * fmi3_native.c -- the FMI 3.0 API of a native vibrofmu FMU (Co-Simulation, and Model Exchange for the models
 * with me_model.h's hooks), written once for every model on top of its FMI 2.0 layer: the FMI 3.0 binary is the
 * FMI 2.0 one (fmi2_native.c, fmi2_me.c, the model's native_model.c: the same rules, messages, integrator and
 * bits) plus this file, which maps each FMI 3.0 call on the FMI 2.0 call that does the work and adds what FMI 3.0
 * has beyond it:
 *   - the independent variable `time` (value reference N_VARIABLES) and, for Model Exchange models, the event
 *     indicators as variables (N_VARIABLES + 1 ...);
 *   - Co-Simulation event mode (hasEventMode) and early return (mightReturnEarlyFromDoStep): with earlyReturnAllowed
 *     a doStep ends at the first contact loss or re-contact inside the step (model_do_step_early), earlyReturn and
 *     lastSuccessfulTime say where, and eventHandlingNeeded asks an event-mode master to handle it;
 *   - the FMI 3.0 modes (instantiated, initialization, event, step / continuous-time, terminated): a call out of
 *     its mode is fmi3Error with one log line naming it.
 * The FMI 2.0 functions are linked in but not exported (harness/vibrofmu/fmus/native.py links with a version
 * script on linux64), so another FMU's fmi2 symbols cannot interpose.
 */
#include <ctype.h>
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "me_model.h"

#define EXPORT3 FMI3_Export

/* The modes are the state table's states (fmi2_calls.h: FMI2_INSTANTIATED ...); which call is allowed in which is
   the table's FMI3CS_MASK_<call> / FMI3ME_MASK_<call> (W3_CALL). */

#define VR_TIME ((fmi3ValueReference)N_VARIABLES)
#ifdef ME_N_STATES
#define N_INDICATOR_VARIABLES ME_N_INDICATORS
#else
#define N_INDICATOR_VARIABLES 0
#endif

typedef struct {
    fmi2Component c;              /* the FMI 2.0 instance (fmi2_native.c) */
    fmi2CallbackFunctions cb;     /* its callbacks: the logger passes messages on to logMessage */
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    int model_exchange, event_mode_used, early_return_allowed;
    int mode;                     /* FMI2_<state> (the state table's) */
    double time;
} W3;

/* The FMU state: the FMI 2.0 instance's, with the FMI 3.0 mode and time */
typedef struct {
    fmi2FMUstate inner;
    int mode; /* FMI2_<state> */
    double time;
} W3State;

static void forward_log(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                        fmi2String message, ...)
{
    (void)name;
    const W3 *w = env;
    if (w == NULL || w->log == NULL) return;
    char text[2048];
    va_list args;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args); /* fmi2_layer doubled each '%': undo it */
    va_end(args);
    w->log(w->env, status <= fmi2Fatal ? (fmi3Status)status : fmi3Error, category, text);
}

static fmi3Status to3(fmi2Status st) { return st <= fmi2Fatal ? (fmi3Status)st : fmi3Error; }

/* A refusal of the FMI 3.0 layer: logged through the FMI 2.0 instance (error state, status flag), fmi3Error */
static fmi3Status refuse(W3 *w, const char *format, ...)
{
    char text[512];
    va_list args;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    native_error((Instance *)w->c, "%s", text);
    native_layer((Instance *)w->c)->mode = FMI2_MODE_ERROR;
    return fmi3Error;
}

/* A NULL array of n > 0 values: fmi3Error naming the call and the argument */
#define NULL_ARRAY3(call, array, n)                                                                           \
    do {                                                                                                      \
        if ((n) > 0 && (array) == NULL)                                                                       \
            return refuse(w, "%s refused: %s = NULL with %s = %zu", call, #array, #n, (size_t)(n));           \
    } while (0)

/* Call `call` allowed in the instance's mode by the state table of its interface (cs, me: its masks)? else
   fmi3Error with the table's refusal */
static int in_mode(W3 *w, const char *call, unsigned cs, unsigned me, fmi3Status *st)
{
    char why[256];
    const char *refusal = w->model_exchange
        ? fmi_call_refusal(FMI3ME_LABEL, FMI3ME_INTERFACE, call, me, w->mode, why, sizeof why)
        : fmi_call_refusal(FMI3CS_LABEL, FMI3CS_INTERFACE, call, cs, w->mode, why, sizeof why);
    if (refusal == NULL) return 1;
    *st = refuse(w, "%s", refusal);
    return 0;
}

/* A live FMI 3.0 instance of this binary whose state table allows call F in its mode, else fmi3Error */
#define W3_CALL(F)                                                                                         \
    W3 *w = (W3 *)instance;                                                                                \
    fmi3Status st_ = fmi3OK;                                                                               \
    if (!fmi2_live(w, FMI2_LIVE_FMI3)) return fmi3Error;                                                   \
    if (!in_mode(w, #F, FMI3CS_MASK_##F, FMI3ME_MASK_##F, &st_)) return st_

EXPORT3 const char *fmi3GetVersion(void) { return fmi3Version; }

EXPORT3 fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                                       const fmi3String categories[])
{
    W3_CALL(fmi3SetDebugLogging);
    if (nCategories > 0 && categories == NULL)
        return refuse(w, "fmi3SetDebugLogging refused: categories = NULL with nCategories = %zu", nCategories);
    return to3(fmi2SetDebugLogging(w->c, loggingOn, nCategories, categories));
}

/* FMI 2.0 takes the resources as a file URI, FMI 3.0 as a path (with '\\' on Windows, any character): the path as
 * a URI, percent-encoded, so that fmi2Instantiate's check (fmi/fmi2_layer.c) decodes it to the same path:
 * "/tmp/a b/resources/" -> "file:///tmp/a%20b/resources/", "C:\\x\\resources\\" -> "file:///C:/x/resources/". FMI 3.0
 * lets resourcePath be NULL (no resources folder, or no file system path): the native FMUs read no resources, so
 * then the check is given the file system's root, a folder that exists. NULL only if out of memory. */
static char *resource_uri(fmi3String path)
{
    if (path == NULL) path = "/";
    char *uri = malloc(3 * strlen(path) + 9), *out = uri;
    if (uri == NULL) return NULL;
    out += sprintf(out, "file://%s", path[0] == '/' || path[0] == '\\' ? "" : "/");
    for (const unsigned char *p = (const unsigned char *)path; *p; p++) {
        unsigned char c = *p == '\\' ? '/' : *p;
        if (isalnum(c) || strchr("-._~/:", c) != NULL) *out++ = (char)c;
        else out += sprintf(out, "%%%02X", c);
    }
    *out = '\0';
    return uri;
}

static W3 *instantiate(fmi3String name, fmi3String token, fmi3String resourcePath, fmi3Boolean visible,
                       fmi3Boolean loggingOn, fmi3InstanceEnvironment env, fmi3LogMessageCallback log, int me)
{
    W3 *w = calloc(1, sizeof *w);
    if (w == NULL) return NULL;
    w->env = env;
    w->log = log;
    w->model_exchange = me;
    w->cb.logger = forward_log;
    w->cb.allocateMemory = calloc;
    w->cb.freeMemory = free;
    w->cb.componentEnvironment = w;
    char *uri = resource_uri(resourcePath);
    w->c = uri == NULL ? NULL : fmi2Instantiate(name, me ? fmi2ModelExchange : fmi2CoSimulation, token, uri, &w->cb,
                                                visible, loggingOn);
    free(uri);
    if (w->c == NULL) {
        free(w);
        return NULL;
    }
    w->mode = FMI2_INSTANTIATED;
    if (!fmi2_live_add(w, FMI2_LIVE_FMI3)) {
        fmi2FreeInstance(w->c);
        free(w);
        return NULL;
    }
    return w;
}

EXPORT3 fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                                  fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                                  fmi3InstanceEnvironment instanceEnvironment,
                                                  fmi3LogMessageCallback logMessage)
{
    return instantiate(instanceName, instantiationToken, resourcePath, visible, loggingOn, instanceEnvironment,
                       logMessage, 1);
}

EXPORT3 fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                                 fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                                 fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                                 const fmi3ValueReference requiredIntermediateVariables[],
                                                 size_t nRequiredIntermediateVariables,
                                                 fmi3InstanceEnvironment instanceEnvironment,
                                                 fmi3LogMessageCallback logMessage,
                                                 fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)requiredIntermediateVariables; (void)intermediateUpdate; /* no intermediate update */
    W3 *w = instantiate(instanceName, instantiationToken, resourcePath, visible, loggingOn, instanceEnvironment,
                        logMessage, 0);
    if (w == NULL) return NULL;
    if (nRequiredIntermediateVariables > 0 && logMessage != NULL)
        logMessage(instanceEnvironment, fmi3Warning, "logStatusWarning",
                   "requiredIntermediateVariables ignored: this FMU provides no intermediate update");
    w->event_mode_used = eventModeUsed;
    w->early_return_allowed = earlyReturnAllowed;
#ifdef HAS_EARLY_RETURN
    /* event mode without early return steps through the events too (fmi3DoStep), to report them */
    native_set_early_return((Instance *)w->c, earlyReturnAllowed || eventModeUsed);
#endif
    return w;
}

EXPORT3 fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                                       fmi3String resourcePath, fmi3Boolean visible,
                                                       fmi3Boolean loggingOn,
                                                       fmi3InstanceEnvironment instanceEnvironment,
                                                       fmi3LogMessageCallback logMessage,
                                                       fmi3ClockUpdateCallback clockUpdate,
                                                       fmi3LockPreemptionCallback lockPreemption,
                                                       fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage != NULL)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU has no Scheduled Execution interface");
    return NULL;
}

EXPORT3 void fmi3FreeInstance(fmi3Instance instance)
{
    W3 *w = (W3 *)instance;
    if (!fmi2_live_remove(w, FMI2_LIVE_FMI3)) return; /* NULL, freed already, or not this binary's */
    fmi2FreeInstance(w->c);
    free(w);
}

EXPORT3 fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                               fmi3Float64 tolerance, fmi3Float64 startTime,
                                               fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    W3_CALL(fmi3EnterInitializationMode);
    if (!isfinite(startTime)) /* it becomes the variable `time`, which must be finite when read with fmi3OK */
        return refuse(w, "fmi3EnterInitializationMode refused: startTime = %g is not a finite number", startTime);
    fmi2Status st = fmi2SetupExperiment(w->c, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);
    if (st <= fmi2Warning) st = fmi2EnterInitializationMode(w->c);
    if (st <= fmi2Warning) {
        w->mode = FMI2_INITIALIZATION_MODE;
        w->time = startTime;
    }
    return to3(st);
}

EXPORT3 fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    W3_CALL(fmi3ExitInitializationMode);
    fmi2Status st = fmi2ExitInitializationMode(w->c);
    w->mode = w->model_exchange || w->event_mode_used ? FMI2_EVENT_MODE : FMI2_STEP_MODE;
    return to3(st);
}

EXPORT3 fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    W3_CALL(fmi3EnterEventMode);
    if (!w->model_exchange && !w->event_mode_used)
        return refuse(w, "fmi3EnterEventMode: the instance was created with eventModeUsed = false");
    fmi2Status st = fmi2OK;
#ifdef ME_N_STATES
    if (w->model_exchange) st = fmi2EnterEventMode(w->c);
#endif
    if (st <= fmi2Warning) w->mode = FMI2_EVENT_MODE;
    return to3(st);
}

EXPORT3 fmi3Status fmi3Terminate(fmi3Instance instance)
{
    W3_CALL(fmi3Terminate);
    fmi2Status st = fmi2Terminate(w->c);
    if (st <= fmi2Warning) w->mode = FMI2_TERMINATED;
    return to3(st);
}

EXPORT3 fmi3Status fmi3Reset(fmi3Instance instance)
{
    W3_CALL(fmi3Reset);
    fmi2Status st = fmi2Reset(w->c);
    w->mode = FMI2_INSTANTIATED;
    w->time = 0.0;
    return to3(st);
}

/* ---- variables: Float64 (FMI 2.0 Real), Int32 (Integer), Boolean; `time` and the indicators beside them ---- */

static int sizes_match(W3 *w, const char *call, size_t nvr, size_t nValues, fmi3Status *st)
{
    if (nvr == nValues) return 1;
    *st = refuse(w, "%s: nValues = %zu, expected nValueReferences = %zu (every variable is a scalar)", call, nValues,
                 nvr);
    return 0;
}

static int arrays_given(W3 *w, const char *call, const void *vr, const void *values, size_t n, fmi3Status *st)
{
    if (n == 0 || (vr != NULL && values != NULL)) return 1;
    *st = refuse(w, "%s refused: %s = NULL with nValueReferences = %zu", call, vr == NULL ? "valueReferences"
                 : "values", n);
    return 0;
}

/* The variable calls' checks: nValues = nValueReferences (every variable a scalar) and both arrays given */
static int values_given(W3 *w, const char *call, const void *vr, size_t nvr, const void *values, size_t nValues,
                        fmi3Status *st)
{
    return sizes_match(w, call, nvr, nValues, st) && arrays_given(w, call, vr, values, nvr, st);
}
#define VALUES_GIVEN(F)                                                                                         \
    if (!values_given(w, #F, valueReferences, nValueReferences, values, nValues, &st_)) return st_

/* an FMI 3.0-only variable (time, indicators) as a Float64: 1 with its value */
static int extra_float64(W3 *w, fmi3ValueReference vr, double *value)
{
    if (vr == VR_TIME) {
        *value = w->time;
        return 1;
    }
#ifdef ME_N_STATES
    if (vr > VR_TIME && vr <= VR_TIME + ME_N_INDICATORS) {
        double z[ME_MAX_INDICATORS];
        model_me_indicators(native_state((Instance *)w->c), z);
        *value = z[vr - VR_TIME - 1];
        return 1;
    }
#endif
    return 0;
}

EXPORT3 fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    W3_CALL(fmi3GetFloat64);
    VALUES_GIVEN(fmi3GetFloat64);
    int plain = 1;
    for (size_t i = 0; i < nValueReferences; i++) plain &= valueReferences[i] < VR_TIME;
    if (plain) return to3(fmi2GetReal(w->c, valueReferences, nValueReferences, values));
    fmi3Status worst = fmi3OK;
    for (size_t i = 0; i < nValueReferences; i++) {
        if (extra_float64(w, valueReferences[i], &values[i])) {
            if (!isfinite(values[i])) /* e.g. an event indicator of a model not yet initialised */
                return refuse(w, "fmi3GetFloat64: variable with valueReference %u (%s) is %g (not finite): refused",
                              valueReferences[i], valueReferences[i] == VR_TIME ? "time" : "an event indicator",
                              values[i]);
            continue;
        }
        fmi3Status st = to3(fmi2GetReal(w->c, &valueReferences[i], 1, &values[i]));
        if (st > worst) worst = st;
    }
    return worst;
}

EXPORT3 fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    W3_CALL(fmi3SetFloat64);
    VALUES_GIVEN(fmi3SetFloat64);
    for (size_t i = 0; i < nValueReferences; i++)
        if (valueReferences[i] >= VR_TIME && valueReferences[i] <= VR_TIME + N_INDICATOR_VARIABLES)
            return refuse(w, "fmi3SetFloat64: variable with valueReference %u (%s) is computed by the FMU and cannot "
                          "be set", valueReferences[i], valueReferences[i] == VR_TIME ? "time" : "an event indicator");
    return to3(fmi2SetReal(w->c, valueReferences, nValueReferences, values));
}

/* The getters and setters that are the FMI 2.0 ones of the same values */
#define FORWARD(Name, T, F2)                                                                                    \
    EXPORT3 fmi3Status fmi3##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[],            \
                                  size_t nValueReferences, T values[], size_t nValues)                          \
    {                                                                                                           \
        W3_CALL(fmi3##Name);                                                                                    \
        VALUES_GIVEN(fmi3##Name);                                                                               \
        return to3(F2(w->c, valueReferences, nValueReferences, values));                                        \
    }
FORWARD(GetInt32, fmi3Int32, fmi2GetInteger)
FORWARD(SetInt32, const fmi3Int32, fmi2SetInteger)
FORWARD(GetString, fmi3String, fmi2GetString)
FORWARD(SetString, const fmi3String, fmi2SetString)

#define CHUNK 64
EXPORT3 fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Boolean values[], size_t nValues)
{
    W3_CALL(fmi3GetBoolean);
    VALUES_GIVEN(fmi3GetBoolean);
    fmi3Status worst = fmi3OK;
    for (size_t done = 0; done < nValueReferences; done += CHUNK) {
        size_t n = nValueReferences - done < CHUNK ? nValueReferences - done : CHUNK;
        fmi2Boolean b[CHUNK] = {0};  /* false where the FMI 2.0 getter refuses before writing (GCC -O3 warns) */
        fmi3Status st = to3(fmi2GetBoolean(w->c, valueReferences + done, n, b));
        for (size_t i = 0; i < n; i++) values[done + i] = b[i] != 0;
        if (st > worst) worst = st;
    }
    return worst;
}

EXPORT3 fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Boolean values[], size_t nValues)
{
    W3_CALL(fmi3SetBoolean);
    VALUES_GIVEN(fmi3SetBoolean);
    fmi3Status worst = fmi3OK;
    for (size_t done = 0; done < nValueReferences; done += CHUNK) {
        size_t n = nValueReferences - done < CHUNK ? nValueReferences - done : CHUNK;
        fmi2Boolean b[CHUNK];
        for (size_t i = 0; i < n; i++) b[i] = values[done + i] ? fmi2True : fmi2False;
        fmi3Status st = to3(fmi2SetBoolean(w->c, valueReferences + done, n, b));
        if (st > worst) worst = st;
    }
    return worst;
}

/* The types this FMU has no variable of: any value reference is an error naming the type */
static fmi3Status no_such_type(W3 *w, const char *call, const char *type, size_t n)
{
    if (n == 0) return fmi3OK;
    return refuse(w, "%s: this FMU has no %s variable", call, type);
}

#define NO_TYPE(Name, T)                                                                                        \
    EXPORT3 fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[],          \
                                     size_t nValueReferences, T values[], size_t nValues)                        \
    {                                                                                                           \
        W3_CALL(fmi3Get##Name);                                                                       \
        (void)valueReferences; (void)values; (void)nValues;                                                     \
        return no_such_type(w, "fmi3Get" #Name, #Name, nValueReferences);                                       \
    }                                                                                                           \
    EXPORT3 fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[],          \
                                     size_t nValueReferences, const T values[], size_t nValues)                  \
    {                                                                                                           \
        W3_CALL(fmi3Set##Name);                                                                       \
        (void)valueReferences; (void)values; (void)nValues;                                                     \
        return no_such_type(w, "fmi3Set" #Name, #Name, nValueReferences);                                       \
    }
NO_TYPE(Float32, fmi3Float32)
NO_TYPE(Int8, fmi3Int8)
NO_TYPE(UInt8, fmi3UInt8)
NO_TYPE(Int16, fmi3Int16)
NO_TYPE(UInt16, fmi3UInt16)
NO_TYPE(UInt32, fmi3UInt32)
NO_TYPE(Int64, fmi3Int64)
NO_TYPE(UInt64, fmi3UInt64)

EXPORT3 fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                 size_t nValueReferences, size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    W3_CALL(fmi3GetBinary);
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    return no_such_type(w, "fmi3GetBinary", "Binary", nValueReferences);
}

EXPORT3 fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                 size_t nValueReferences, const size_t valueSizes[], const fmi3Binary values[],
                                 size_t nValues)
{
    W3_CALL(fmi3SetBinary);
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    return no_such_type(w, "fmi3SetBinary", "Binary", nValueReferences);
}

/* The Clock calls: this FMU has no Clock variable, so any value reference is an error naming the type (the arrays
   after the value references are not read) */
#define UNREAD __attribute__((unused))
#define NO_CLOCK(Name, ...)                                                                                     \
    EXPORT3 fmi3Status fmi3##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[] UNREAD,     \
                                  size_t nValueReferences, __VA_ARGS__)                                         \
    {                                                                                                           \
        W3_CALL(fmi3##Name);                                                                                    \
        return no_such_type(w, "fmi3" #Name, "Clock", nValueReferences);                                        \
    }
NO_CLOCK(GetClock, fmi3Clock values[] UNREAD)
NO_CLOCK(SetClock, const fmi3Clock values[] UNREAD)
NO_CLOCK(GetIntervalDecimal, fmi3Float64 intervals[] UNREAD, fmi3IntervalQualifier qualifiers[] UNREAD)
NO_CLOCK(GetIntervalFraction, fmi3UInt64 counters[] UNREAD, fmi3UInt64 resolutions[] UNREAD,
         fmi3IntervalQualifier qualifiers[] UNREAD)
NO_CLOCK(GetShiftDecimal, fmi3Float64 shifts[] UNREAD)
NO_CLOCK(GetShiftFraction, fmi3UInt64 counters[] UNREAD, fmi3UInt64 resolutions[] UNREAD)
NO_CLOCK(SetIntervalDecimal, const fmi3Float64 intervals[] UNREAD)
NO_CLOCK(SetIntervalFraction, const fmi3UInt64 counters[] UNREAD, const fmi3UInt64 resolutions[] UNREAD)
NO_CLOCK(SetShiftDecimal, const fmi3Float64 shifts[] UNREAD)
NO_CLOCK(SetShiftFraction, const fmi3UInt64 counters[] UNREAD, const fmi3UInt64 resolutions[] UNREAD)

/* ---- not provided (the modelDescription says so) ---- */

static fmi3Status not_provided(W3 *w, const char *call, const char *why)
{
    return refuse(w, "%s is not provided (%s)", call, why);
}

EXPORT3 fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                                       size_t *nDependencies)
{
    W3_CALL(fmi3GetNumberOfVariableDependencies);
    (void)valueReference; (void)nDependencies;
    return not_provided(w, "fmi3GetNumberOfVariableDependencies", "providesPerElementDependencies=false");
}

EXPORT3 fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                               size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                               size_t elementIndicesOfIndependents[],
                                               fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    W3_CALL(fmi3GetVariableDependencies);
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    return not_provided(w, "fmi3GetVariableDependencies", "providesPerElementDependencies=false");
}

EXPORT3 fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                                size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                                const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                                size_t nSensitivity)
{
    W3_CALL(fmi3GetDirectionalDerivative);
#ifdef HAS_DIRECTIONAL_DERIVATIVES
    if (nSeed != nKnowns || nSensitivity != nUnknowns)
        return refuse(w, "fmi3GetDirectionalDerivative: nSeed = %zu and nSensitivity = %zu must be nKnowns = %zu and "
                      "nUnknowns = %zu (every variable is a scalar)", nSeed, nSensitivity, nKnowns, nUnknowns);
    return to3(fmi2GetDirectionalDerivative(w->c, unknowns, nUnknowns, knowns, nKnowns, seed, sensitivity));
#else
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    return not_provided(w, "fmi3GetDirectionalDerivative", "providesDirectionalDerivatives=false");
#endif
}

EXPORT3 fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                            size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                            const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                            size_t nSensitivity)
{
    W3_CALL(fmi3GetAdjointDerivative);
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    return not_provided(w, "fmi3GetAdjointDerivative", "providesAdjointDerivatives=false");
}

EXPORT3 fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    W3_CALL(fmi3EnterConfigurationMode);
    return not_provided(w, "fmi3EnterConfigurationMode", "this FMU has no structural parameters");
}

EXPORT3 fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    W3_CALL(fmi3ExitConfigurationMode);
    return not_provided(w, "fmi3ExitConfigurationMode", "this FMU has no structural parameters");
}

#define U(x) (void)(x)
EXPORT3 fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    W3_CALL(fmi3EvaluateDiscreteStates);
    return not_provided(w, "fmi3EvaluateDiscreteStates", "providesEvaluateDiscreteStates=false");
}

EXPORT3 fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                              fmi3Float64 activationTime)
{
    W3_CALL(fmi3ActivateModelPartition);
    U(clockReference); U(activationTime);
    return not_provided(w, "fmi3ActivateModelPartition", "no Scheduled Execution interface");
}

EXPORT3 fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                            size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                            size_t nValues)
{
    W3_CALL(fmi3GetOutputDerivatives);
    U(valueReferences); U(nValueReferences); U(orders); U(values); U(nValues);
    return not_provided(w, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder=0");
}

/* ---- FMU state: the FMI 2.0 instance's, with the FMI 3.0 mode and time ---- */

/* A state pointer that is not a live FMI 3.0 state of this binary (freed, another FMU's): never read or written */
static fmi3Status foreign_state3(W3 *w, const char *call, const void *state)
{
    return refuse(w, "%s refused: FMUState = %p is not a state of this FMU (freed, or another FMU's)", call, state);
}

EXPORT3 fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    W3_CALL(fmi3GetFMUState);
    if (FMUState == NULL) return refuse(w, "fmi3GetFMUState refused: FMUState = NULL (the pointer to store it in)");
    if (*FMUState != NULL && !fmi2_live(*FMUState, FMI2_LIVE_FMI3_STATE))
        return foreign_state3(w, "fmi3GetFMUState", *FMUState);
    W3State *s = *FMUState != NULL ? (W3State *)*FMUState : calloc(1, sizeof *s);
    if (s == NULL) return refuse(w, "fmi3GetFMUState: out of memory");
    fmi2Status st = fmi2GetFMUstate(w->c, &s->inner);
    if (st <= fmi2Warning && *FMUState == NULL && !fmi2_live_add(s, FMI2_LIVE_FMI3_STATE)) {
        fmi2FreeFMUstate(w->c, &s->inner);
        st = fmi2Error;
    }
    if (st > fmi2Warning) {
        if (*FMUState == NULL) free(s);
        return to3(st);
    }
    s->mode = w->mode;
    s->time = w->time;
    *FMUState = s;
    return to3(st);
}

EXPORT3 fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    W3_CALL(fmi3SetFMUState);
    if (FMUState == NULL) return refuse(w, "fmi3SetFMUState refused: FMUState = NULL (no state given)");
    if (!fmi2_live(FMUState, FMI2_LIVE_FMI3_STATE)) return foreign_state3(w, "fmi3SetFMUState", FMUState);
    const W3State *s = FMUState;
    /* a state of a mode this instance's interface has (the table's states; event mode in co-simulation only with
       eventModeUsed) */
    const unsigned modes = w->model_exchange ? FMI3ME_STATES
                         : FMI3CS_STATES & ~(w->event_mode_used ? 0u : FMI2_BIT(FMI2_EVENT_MODE));
    if (!(modes & FMI2_BIT(s->mode)))
        return refuse(w, "fmi3SetFMUState refused: a state in %s, which this instance (%s%s) has not",
                      FMI2_STATE_NAMES[s->mode], w->model_exchange ? "Model Exchange" : "Co-Simulation",
                      !w->model_exchange && !w->event_mode_used ? " without event mode" : "");
    fmi2Status st = fmi2SetFMUstate(w->c, s->inner);
    if (st <= fmi2Warning) {
        w->mode = s->mode;
        w->time = s->time;
    }
    return to3(st);
}

EXPORT3 fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    W3_CALL(fmi3FreeFMUState);
    if (FMUState == NULL || *FMUState == NULL) return fmi3OK;
    if (!fmi2_live_remove(*FMUState, FMI2_LIVE_FMI3_STATE)) return foreign_state3(w, "fmi3FreeFMUState", *FMUState);
    W3State *s = *FMUState;
    fmi2Status st = fmi2FreeFMUstate(w->c, &s->inner);
    free(s);
    *FMUState = NULL;
    return to3(st);
}

/* serialized: mode (int64) and time (double), then the FMI 2.0 state's bytes */
#define W3_HEADER (sizeof(int64_t) + sizeof(double))

EXPORT3 fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    W3_CALL(fmi3SerializedFMUStateSize);
    if (FMUState == NULL || size == NULL)
        return refuse(w, "fmi3SerializedFMUStateSize refused: %s = NULL", FMUState == NULL ? "FMUState" : "size");
    if (!fmi2_live(FMUState, FMI2_LIVE_FMI3_STATE)) return foreign_state3(w, "fmi3SerializedFMUStateSize", FMUState);
    size_t inner = 0;
    fmi2Status st = fmi2SerializedFMUstateSize(w->c, ((W3State *)FMUState)->inner, &inner);
    *size = inner + W3_HEADER;
    return to3(st);
}

EXPORT3 fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                         size_t size)
{
    W3_CALL(fmi3SerializeFMUState);
    if (FMUState == NULL || serializedState == NULL)
        return refuse(w, "fmi3SerializeFMUState refused: %s = NULL", FMUState == NULL ? "FMUState" : "serializedState");
    if (size < W3_HEADER) return refuse(w, "fmi3SerializeFMUState refused: size = %zu bytes are too few", size);
    if (!fmi2_live(FMUState, FMI2_LIVE_FMI3_STATE)) return foreign_state3(w, "fmi3SerializeFMUState", FMUState);
    const W3State *s = FMUState;
    int64_t mode = s->mode;
    memcpy(serializedState, &mode, sizeof mode);
    memcpy(serializedState + sizeof mode, &s->time, sizeof s->time);
    return to3(fmi2SerializeFMUstate(w->c, s->inner, (fmi2Byte *)serializedState + W3_HEADER, size - W3_HEADER));
}

EXPORT3 fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                           fmi3FMUState *FMUState)
{
    W3_CALL(fmi3DeserializeFMUState);
    if (serializedState == NULL || FMUState == NULL)
        return refuse(w, "fmi3DeserializeFMUState refused: %s = NULL", serializedState == NULL ? "serializedState"
                      : "FMUState (the pointer to store it in)");
    if (size < W3_HEADER) return refuse(w, "fmi3DeserializeFMUState refused: size = %zu bytes are too few", size);
    int64_t mode;
    double time;
    memcpy(&mode, serializedState, sizeof mode);
    memcpy(&time, serializedState + sizeof mode, sizeof time);
    if (mode < 0 || mode >= FMI2_N_STATES || !((FMI3CS_STATES | FMI3ME_STATES) & FMI2_BIT(mode)) || !isfinite(time))
        return refuse(w, "fmi3DeserializeFMUState refused: not a state of this FMU (mode %lld, time %g)",
                      (long long)mode, time);
    if (*FMUState != NULL && !fmi2_live(*FMUState, FMI2_LIVE_FMI3_STATE))
        return foreign_state3(w, "fmi3DeserializeFMUState", *FMUState);
    W3State *s = *FMUState != NULL ? (W3State *)*FMUState : calloc(1, sizeof *s);
    if (s == NULL) return refuse(w, "fmi3DeserializeFMUState: out of memory");
    fmi2Status st = fmi2DeSerializeFMUstate(w->c, (const fmi2Byte *)serializedState + W3_HEADER, size - W3_HEADER,
                                            &s->inner);
    if (st <= fmi2Warning && *FMUState == NULL && !fmi2_live_add(s, FMI2_LIVE_FMI3_STATE)) {
        fmi2FreeFMUstate(w->c, &s->inner);
        st = fmi2Error;
    }
    if (st > fmi2Warning) {
        if (*FMUState == NULL) free(s);
        return to3(st);
    }
    s->mode = (int)mode;
    s->time = time;
    *FMUState = s;
    return to3(st);
}

/* ---- event mode (both interfaces) ---- */

EXPORT3 fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                            fmi3Boolean *terminateSimulation,
                                            fmi3Boolean *nominalsOfContinuousStatesChanged,
                                            fmi3Boolean *valuesOfContinuousStatesChanged,
                                            fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
{
    W3_CALL(fmi3UpdateDiscreteStates);
    if (discreteStatesNeedUpdate == NULL || terminateSimulation == NULL || nominalsOfContinuousStatesChanged == NULL ||
        valuesOfContinuousStatesChanged == NULL || nextEventTimeDefined == NULL || nextEventTime == NULL)
        return refuse(w, "fmi3UpdateDiscreteStates: an output argument is NULL");
    fmi2EventInfo info = {fmi2False, fmi2False, fmi2False, fmi2False, fmi2False, 0.0};
    fmi2Status st = fmi2OK;
#ifdef ME_N_STATES
    if (w->model_exchange) st = fmi2NewDiscreteStates(w->c, &info);
#endif
    /* Co-Simulation: the doStep that ended on the event left the discrete outputs (in_contact) on its new side */
    *discreteStatesNeedUpdate = info.newDiscreteStatesNeeded;
    *terminateSimulation = info.terminateSimulation;
    *nominalsOfContinuousStatesChanged = info.nominalsOfContinuousStatesChanged;
    *valuesOfContinuousStatesChanged = info.valuesOfContinuousStatesChanged;
    *nextEventTimeDefined = info.nextEventTimeDefined;
    *nextEventTime = info.nextEventTime;
    return to3(st);
}

/* ---- Co-Simulation ---- */

EXPORT3 fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    W3_CALL(fmi3EnterStepMode);
    w->mode = FMI2_STEP_MODE;
    return fmi3OK;
}

EXPORT3 fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                              fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                              fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                              fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    W3_CALL(fmi3DoStep);
    if (eventHandlingNeeded == NULL || terminateSimulation == NULL || earlyReturn == NULL ||
        lastSuccessfulTime == NULL)
        return refuse(w, "fmi3DoStep: an output argument is NULL");
    const double t_end = currentCommunicationPoint + communicationStepSize;
#ifdef HAS_EARLY_RETURN
    *native_call_steps((Instance *)w->c) = 0.0; /* the step budget counts from here, over every internal doStep */
#endif
    fmi2Status st = fmi2DoStep(w->c, currentCommunicationPoint, communicationStepSize,
                               noSetFMUStatePriorToCurrentPoint);
    double reached = st <= fmi2Warning ? t_end : currentCommunicationPoint;
    int event = 0;
#ifdef HAS_EARLY_RETURN
    const MeData *me = &native_state((Instance *)w->c)->model.me;
    if (w->early_return_allowed && st <= fmi2Warning) {
        reached = me->reached;
        event = st <= fmi2Warning && me->step_event;
    } else if (w->event_mode_used && st <= fmi2Warning) {
        /* event mode without early return: the step goes on through each event it meets (the same solver steps:
           model_do_step_early without an event is model_do_step) and eventHandlingNeeded says one happened.  The
           step budget bounds the whole loop (native_call_steps: model_do_step_early stops with the budget's error
           when the internal doSteps together spend it); each pass takes a solver step or returns a pending event,
           so the passes are bounded too. */
        event = (int)me->step_event;
        while (st <= fmi2Warning && me->reached < t_end) {
            const double from = me->reached;
            st = fmi2DoStep(w->c, from, t_end - from, noSetFMUStatePriorToCurrentPoint);
            event |= st <= fmi2Warning && me->step_event;
        }
        reached = st <= fmi2Warning ? t_end : me->reached;
        if (st > fmi2Warning) {
            w->time = reached; /* where the failed step left the instance: it is in the error state */
            *earlyReturn = fmi3False;
            *lastSuccessfulTime = reached;
            *eventHandlingNeeded = fmi3False;
            *terminateSimulation = fmi3False;
            return to3(st);
        }
    }
#endif
    *earlyReturn = st <= fmi2Warning && reached < t_end;
    *lastSuccessfulTime = reached;
    *eventHandlingNeeded = event && w->event_mode_used;
    *terminateSimulation = fmi3False;
    if (st <= fmi2Warning) w->time = *earlyReturn ? reached : t_end;
    return to3(st);
}

/* ---- Model Exchange ---- */

/* Defined for every model (FMPy loads them all); a model without Model Exchange (no ME_N_STATES) answers
   fmi3Error: its instances are Co-Simulation ones. */
#ifdef ME_N_STATES
#define ME2_CALL(expr) (expr)
#else /* never reached past W3_CALL (the table has these calls for Model Exchange only): fmi3InstantiateModelExchange fails for these models (sizeof: not evaluated) */
#define ME2_CALL(expr) ((void)sizeof(expr), fmi2Error)
#define ME_N_STATES 0
#define ME_N_INDICATORS 0
#endif

EXPORT3 fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    W3_CALL(fmi3EnterContinuousTimeMode);
    fmi2Status st = ME2_CALL(fmi2EnterContinuousTimeMode(w->c));
    if (st <= fmi2Warning) w->mode = FMI2_CONTINUOUS_TIME_MODE;
    return to3(st);
}

EXPORT3 fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                               fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    W3_CALL(fmi3CompletedIntegratorStep);
    if (enterEventMode == NULL || terminateSimulation == NULL)
        return refuse(w, "fmi3CompletedIntegratorStep: enterEventMode or terminateSimulation is NULL");
    fmi2Boolean enter = fmi2False, terminate = fmi2False;
    fmi2Status st =
        ME2_CALL(fmi2CompletedIntegratorStep(w->c, noSetFMUStatePriorToCurrentPoint, &enter, &terminate));
    *enterEventMode = enter != 0;
    *terminateSimulation = terminate != 0;
    return to3(st);
}

EXPORT3 fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    W3_CALL(fmi3SetTime);
    fmi2Status st = ME2_CALL(fmi2SetTime(w->c, time));
    if (st <= fmi2Warning) w->time = time;
    return to3(st);
}

/* Model Exchange's calls on an array of n values: the table, the NULL check, then the FMI 2.0 call (F2) */
#define ME_ARRAY(Name, F2, T, array, n)                                                                        \
    EXPORT3 fmi3Status fmi3##Name(fmi3Instance instance, T array[], size_t n)                                  \
    {                                                                                                         \
        W3_CALL(fmi3##Name);                                                                                  \
        NULL_ARRAY3("fmi3" #Name, array, n);                                                                  \
        return to3(ME2_CALL(F2(w->c, array, n)));                                                             \
    }
ME_ARRAY(SetContinuousStates, fmi2SetContinuousStates, const fmi3Float64, continuousStates, nContinuousStates)
ME_ARRAY(GetContinuousStateDerivatives, fmi2GetDerivatives, fmi3Float64, derivatives, nContinuousStates)
ME_ARRAY(GetEventIndicators, fmi2GetEventIndicators, fmi3Float64, eventIndicators, nEventIndicators)
ME_ARRAY(GetContinuousStates, fmi2GetContinuousStates, fmi3Float64, continuousStates, nContinuousStates)
ME_ARRAY(GetNominalsOfContinuousStates, fmi2GetNominalsOfContinuousStates, fmi3Float64, nominals, nContinuousStates)

EXPORT3 fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    W3_CALL(fmi3GetNumberOfEventIndicators);
    if (nEventIndicators == NULL) return refuse(w, "fmi3GetNumberOfEventIndicators: nEventIndicators is NULL");
    *nEventIndicators = ME_N_INDICATORS;
    return fmi3OK;
}

EXPORT3 fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    W3_CALL(fmi3GetNumberOfContinuousStates);
    if (nContinuousStates == NULL) return refuse(w, "fmi3GetNumberOfContinuousStates: nContinuousStates is NULL");
    *nContinuousStates = ME_N_STATES;
    return fmi3OK;
}
