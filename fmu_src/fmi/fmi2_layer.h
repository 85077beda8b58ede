/*
 * fmi2_layer.h -- the FMI 2.0 plumbing of the vibrofmu FMUs, written once (fmi2_layer.c) and used by both FMI
 * layers: the status shim over pythonfmu's library (fmu_src/fmi2_status_shim.c) and the native FMUs
 * (fmu_src/native/fmi2_native.c).  It holds
 *   - logging: the host's callbacks, fmi2SetDebugLogging's flag and categories, messages passed on with '%'
 *     doubled (the host treats a message as a printf format);
 *   - the error mode: an instance whose state-changing call ended in fmi2Error answers only the calls the state
 *     table allows in the error state (the others: fmi2Error and "call X not allowed after an error"); after an
 *     fmi2Fatal nothing is answered but fmi2Fatal;
 *   - the finite-value check of the Reals a getter returns (none leaves with fmi2OK non-finite);
 *   - the FMI state machines: ONE table of the states each call is allowed in, per interface (fmi2_calls.h, in
 *     the manner of the Modelica Reference-FMUs' ASSERT_STATE masks: FMI 2.0 co-simulation and Model Exchange,
 *     FMI 3.0 both), generated from slave_support.STATE_TABLES (CALLS: the co-simulation table the Python slaves
 *     read), and fmi_call_refusal, the one check of a call against it.
 * The FMI types and function prototypes are the standard's own headers (fmi2Functions.h: from FMPy's package,
 * see harness/vibrofmu/fmus/toolchain.py).
 */
#ifndef FMI2_LAYER_H
#define FMI2_LAYER_H

#include <math.h>
#include <stdarg.h>
#include <stddef.h>

#include "fmi2Functions.h"
#include "fmi2_calls.h"  /* FMI2_<STATE>, FMI2_STATE_NAMES, FMI2_MASK_<call> (generated) */

/* The instance's error mode (orthogonal to its phase FMI2_INSTANTIATED ... FMI2_TERMINATED). */
typedef enum { FMI2_MODE_OK, FMI2_MODE_ERROR, FMI2_MODE_FATAL } Fmi2Mode;

typedef struct {
    fmi2CallbackFunctions cb; /* the host's callbacks (a copy; logger never NULL) */
    char *name;               /* the instance name */
    Fmi2Mode mode;
    int logging_on;           /* fmi2SetDebugLogging's flag ... */
    size_t ncat;              /* ... and categories (0: all) */
    char **cat;
} Fmi2Layer;

/* fmi2Instantiate's part: the callbacks, the name, the logging flag; 0 when out of memory (nothing to free). */
int fmi2_layer_init(Fmi2Layer *L, fmi2String instanceName, const fmi2CallbackFunctions *functions,
                    fmi2Boolean loggingOn);
/* fmi2FreeInstance's part: the name and the categories. */
void fmi2_layer_free(Fmi2Layer *L);
void fmi2_layer_free_categories(Fmi2Layer *L);
/* fmi2SetDebugLogging: the flag, and the categories (n == 0: all). */
void fmi2_layer_set_logging(Fmi2Layer *L, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]);
/* fmi2SetDebugLogging's work in every FMI 2.0 layer: categories NULL with n > 0 refused (logged), else
   fmi2_layer_set_logging; fmi2OK or fmi2Error. */
fmi2Status fmi2_layer_debug_logging(Fmi2Layer *L, fmi2Boolean loggingOn, size_t n, const fmi2String categories[]);

/* A message to a host's logger as text ('%' doubled), without filtering. */
void fmi2_log_to(const fmi2CallbackFunctions *cb, fmi2String instanceName, fmi2Status status, fmi2String category,
                 fmi2String message);
/* A message to the host, filtered: Warning, Discard, Error and Fatal always; fmi2OK only with logging on and its
   category enabled. */
void fmi2_layer_emit(const Fmi2Layer *L, fmi2String instanceName, fmi2Status status, fmi2String category,
                     fmi2String message);
/* A printf-formatted message of this instance (category logStatusError, logStatusWarning or logAll by status),
   filtered as fmi2_layer_emit. */
void fmi2_layer_log(const Fmi2Layer *L, fmi2Status status, const char *format, ...);
void fmi2_layer_vlog(const Fmi2Layer *L, fmi2Status status, const char *format, va_list args);

/* The error mode's check of call `call` (allowed states: mask): fmi2OK when it may run; after a fatal fmi2Fatal
   (nothing logged: reported once); in the error mode, when the table does not allow the call there, fmi2Error
   with "call X not allowed after an error" logged.  Inline: in the OK mode (every call of a running simulation)
   it is one comparison, as the checks it replaced were. */
fmi2Status fmi2_layer_mode_refusal(const Fmi2Layer *L, const char *call, unsigned mask);
static inline fmi2Status fmi2_layer_mode_check(const Fmi2Layer *L, const char *call, unsigned mask)
{
    return L->mode == FMI2_MODE_OK ? fmi2OK : fmi2_layer_mode_refusal(L, call, mask);
}
#define FMI2_MODE_CHECK(L, F) fmi2_layer_mode_check((L), #F, FMI2_MASK_##F)

/* The state table's answer for call `call` (allowed states: mask, from the table named `label` of interface
   `interface`, fmi2_calls.h) in state `state` (FMI2_INSTANTIATED ...): NULL when allowed; else why, written into
   buf: "<call> is not allowed in the <state> state (<label> allows it in: <states>)" (co-simulation:
   slave_support.StatusSlave._allowed's text), or, for a call the interface does not have (mask 0 but for the error
   state), "<call>: this instance was instantiated for <interface> (<label> has no such call)".  The one function
   every FMI layer asks (FMI_TABLE_REFUSAL); the state is the caller's, the rule the table's. */
const char *fmi_call_refusal(const char *label, const char *interface, const char *call, unsigned mask, int state,
                             char *buf, size_t size);
#define FMI_TABLE_REFUSAL(P, F, state, buf, size)                                                                 \
    fmi_call_refusal(P##_LABEL, P##_INTERFACE, #F, P##_MASK_##F, (state), (buf), (size))
/* fmi_call_refusal of the FMI 2.0 co-simulation table (FMI2_MASK_<call>) in phase `phase` */
const char *fmi2_phase_refusal(const char *call, unsigned mask, int phase, char *buf, size_t size);

/* After a getter of Reals answered st: every value finite, else fmi2Error naming the first that is not (logged:
   "fmi2GetReal: variable with valueReference VR is VALUE (not finite): refused") and the error mode. */
fmi2Status fmi2_layer_refuse_nonfinite(Fmi2Layer *L, fmi2Status st, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Real value[]);
static inline fmi2Status fmi2_layer_finite_reals(Fmi2Layer *L, fmi2Status st, const fmi2ValueReference vr[],
                                                 size_t nvr, const fmi2Real value[])
{
    if (st > fmi2Warning) return st;
    for (size_t i = 0; i < nvr; i++)
        if (!isfinite(value[i])) return fmi2_layer_refuse_nonfinite(L, st, vr, nvr, value);
    return st; /* inline: the loop the shim and the native layer each had (no call on the getters' path) */
}

/* ---- pointer arguments ----
   A NULL array of n > 0 values (or a NULL pointer to store a result in): fmi2Error, logged "<call> refused:
   <argument> = NULL with <count> = <n>" (or "<call> refused: <argument> = NULL"); the instance is left as it was.
   FMI2_ARRAYS(L, call, n, a, b): both arrays of n values given, else that refusal for the first NULL one. */
fmi2Status fmi2_layer_null_refusal(const Fmi2Layer *L, const char *call, const char *argument, const char *count,
                                   size_t n);
#define FMI2_NULL_ARRAY(L, call, array, n)                                                                        \
    ((n) > 0 && (array) == NULL ? fmi2_layer_null_refusal((L), (call), #array, #n, (n)) : fmi2OK)
#define FMI2_NULL_POINTER(L, call, pointer)                                                                       \
    ((pointer) == NULL ? fmi2_layer_null_refusal((L), (call), #pointer, NULL, 0) : fmi2OK)
#define FMI2_ARRAYS(L, call, n, a, b)                                                                             \
    do {                                                                                                          \
        if (FMI2_NULL_ARRAY((L), (call), a, n) != fmi2OK || FMI2_NULL_ARRAY((L), (call), b, n) != fmi2OK)         \
            return fmi2Error;                                                                                     \
    } while (0)

/* ---- live instances ----
   Every instance a binary hands out is in its set of live instances from fmi2Instantiate (fmi3Instantiate...) to
   fmi2FreeInstance (fmi3FreeInstance); every call first asks the set, so a freed, foreign or made-up instance
   pointer is answered fmi2Error (or ignored by FreeInstance: a second fmi2FreeInstance is a no-op) and never
   dereferenced.  The set is this binary's (hidden symbols: each FMU its own), a hash set under a spin lock (C11
   atomics, no thread library); `kind` tells the FMI 2.0 instances from the FMI 3.0 layer's wrappers. */
int fmi2_live_add(const void *instance, int kind);      /* 0 when out of memory */
int fmi2_live_remove(const void *instance, int kind);   /* 1 when it was live (then it is no more) */
int fmi2_live(const void *instance, int kind);
/* kinds: an FMI 2.0 instance, an FMI 3.0 instance, an FMU state of each (a state of another FMU, or one freed, is
   refused by every state call: fmi3GetFMUState into another model's state overwrote it in place) */
enum { FMI2_LIVE_INSTANCE = 1, FMI2_LIVE_FMI3 = 2, FMI2_LIVE_STATE = 3, FMI2_LIVE_FMI3_STATE = 4 };
/* An FMU state pointer given to call `call` that is not a live FMI 2.0 state of this binary (freed, another FMU's,
   made up): 1, logged "<call> refused: FMUstate = <p> is not a state of this FMU (freed, or another FMU's)"
   (fmi2Error); a live one: 0.  Such a pointer is never read or written. */
int fmi2_layer_foreign_state(const Fmi2Layer *L, const char *call, const void *state);

/* ---- fmi2Instantiate's arguments (issue 25) ----
   fmuResourceLocation as a local folder: 1 and its path (no trailing '/') in `path`, or 0 and why in `why`.
   Accepted, as FMI 2.0 (section 2.1.5: an RFC 3986 URI of scheme "file") and RFC 8089 allow: file:/abs,
   file:///abs, file://localhost/abs, percent-encoded octets (%XX), with or without a trailing '/'; the folder must
   exist.  Refused: NULL, the empty string, another scheme (http:, ...) or host, a relative path, a query or
   fragment, a malformed or NUL escape, a folder that does not exist. */
int fmi2_resource_path(fmi2String uri, char *path, size_t size, char *why, size_t why_size);

/* The checks every FMU of the project makes in fmi2Instantiate, logged (fmi2Error, naming the argument, its value
   and the rule) through the host's callbacks in L: fmuType among `types` (a mask of FMI2_TYPE_BIT(fmi2ModelExchange)
   / FMI2_TYPE_BIT(fmi2CoSimulation)), fmuGUID equal to `guid`, fmuResourceLocation a local folder (its path in
   `path`), instanceName not NULL and not blank (FMI 2.0, 2.1.5).  1 when all hold. */
#define FMI2_TYPE_BIT(type) (1u << (unsigned)(type))
int fmi2_instantiate_check(const Fmi2Layer *L, fmi2String instanceName, const char *model, fmi2Type fmuType,
                           unsigned types,
                           fmi2String fmuGUID, const char *guid, fmi2String fmuResourceLocation, char *path,
                           size_t size);

#endif
