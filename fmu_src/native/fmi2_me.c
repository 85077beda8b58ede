/*
 * fmi2_me.c -- the FMI 2.0 Model Exchange API of the native FMUs, written once for every model that provides the
 * hooks of me_model.h (config.h defines ME_N_STATES); compiled beside fmi2_native.c into the same binary, so one
 * FMU offers both <CoSimulation> and <ModelExchange> (as the Reference-FMUs do).
 *
 * Modes: fmi2ExitInitializationMode of a Model Exchange instance leaves it in Event Mode (fmi2_native.c calls
 * model_me_start); fmi2EnterContinuousTimeMode / fmi2EnterEventMode switch; fmi2Terminate ends.  A call out of its
 * mode, a wrong array size or a NULL array is fmi2Error with one log line naming the call, the mode and the rule;
 * after an error only the getters and fmi2Reset / fmi2FreeInstance are answered (the error state of fmi2_layer.c).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "me_model.h"
#include "pytext.h"

#ifdef ME_N_STATES
#include "plant.h" /* vk_solver_message: the co-simulation's pull-in message (me_stop_at_pull_in) */

#define EXPORT FMI2_Export

enum { IN_INSTANTIATED = 1, IN_INITIALIZATION = 2, IN_EVENT = 4, IN_CONTINUOUS = 8, IN_TERMINATED = 16 };
#define ALL_PHASES (FMI2_BIT(FMI2_INSTANTIATED) | FMI2_BIT(FMI2_INITIALIZATION_MODE) | FMI2_BIT(FMI2_STEP_MODE) | \
                    FMI2_BIT(FMI2_TERMINATED))
#define GETTER_PHASES (ALL_PHASES | FMI2_BIT(FMI2_ERROR)) /* the getters are answered in the error state */

static int current_mode(const State *s)
{
    switch ((int)s->phase) {
    case PHASE_INSTANTIATED: return IN_INSTANTIATED;
    case PHASE_INITIALIZATION_MODE: return IN_INITIALIZATION;
    case PHASE_TERMINATED: return IN_TERMINATED;
    default: return s->model.me.mode == ME_CONTINUOUS_TIME_MODE ? IN_CONTINUOUS : IN_EVENT;
    }
}

static const char *mode_name(int mode)
{
    switch (mode) {
    case IN_INSTANTIATED: return "instantiated";
    case IN_INITIALIZATION: return "initialization mode";
    case IN_EVENT: return "event mode";
    case IN_CONTINUOUS: return "continuous-time mode";
    default: return "terminated";
    }
}

static fmi2Status settled(Instance *I)
{
    if (native_state(I)->value[VR_fmi_status] == 3.0) {
        native_layer(I)->mode = FMI2_MODE_ERROR;
        return fmi2Error;
    }
    return fmi2OK;
}

/* The call's checks: the instance, the error state, Model Exchange use, the mode (allowed: IN_* bits). 1: go on. */
static int me_allowed(Instance *I, const char *call, unsigned error_mask, int allowed, fmi2Status *st)
{
    *st = fmi2_layer_mode_check(native_layer(I), call, error_mask);
    if (*st != fmi2OK) return 0;
    if (!native_model_exchange(I)) {
        native_error(I, "%s: this instance was instantiated for Co-Simulation (fmuType fmi2ModelExchange has it)",
                     call);
        *st = settled(I);
        return 0;
    }
    int mode = current_mode(native_state(I));
    if (mode & allowed) return 1;
    char modes[160] = "";
    for (int bit = IN_INSTANTIATED; bit <= IN_TERMINATED; bit <<= 1)
        if (allowed & bit)
            snprintf(modes + strlen(modes), sizeof modes - strlen(modes), "%s%s", modes[0] ? ", " : "",
                     mode_name(bit));
    native_error(I, "%s is not allowed in %s (FMI 2.0 Model Exchange allows it in: %s)", call, mode_name(mode),
                 modes);
    *st = settled(I);
    return 0;
}

/* An array argument of n values where `expected` are needed: 1 when right, else an error naming it. */
static int sized(Instance *I, const char *call, const char *what, const void *array, size_t n, size_t expected)
{
    if (n != expected) {
        native_error(I, "%s: %s = %zu, this FMU has %zu", call, what, n, expected);
        return 0;
    }
    if (array == NULL && n > 0) {
        native_error(I, "%s: the array of %s values is NULL", call, what);
        return 0;
    }
    return 1;
}

#define ME_CALL(F, ERROR_MASK, MODES)                                                                        \
    Instance *I = (Instance *)c;                                                                             \
    fmi2Status st_;                                                                                          \
    if (!fmi2_live(I, FMI2_LIVE_INSTANCE)) return fmi2Error;                                                 \
    if (!me_allowed(I, #F, (ERROR_MASK), (MODES), &st_)) return st_;                                          \
    State *S = native_state(I)

EXPORT fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    ME_CALL(fmi2EnterEventMode, ALL_PHASES, IN_EVENT | IN_CONTINUOUS);
    S->model.me.mode = ME_EVENT_MODE;
    return settled(I);
}

EXPORT fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    ME_CALL(fmi2NewDiscreteStates, ALL_PHASES, IN_EVENT);
    if (info == NULL) {
        native_error(I, "fmi2NewDiscreteStates: fmi2EventInfo is NULL");
        return settled(I);
    }
    int terminate = 0;
    if (!S->model.me.stopped && model_me_event(I, S, &terminate) == 0 && terminate) S->model.me.stopped = 1;
    info->newDiscreteStatesNeeded = fmi2False; /* the discrete state follows the continuous one: no iteration */
    info->terminateSimulation = S->model.me.stopped ? fmi2True : fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False; /* an impact is continuous: no state is reset */
    info->nextEventTimeDefined = fmi2False;           /* no time events */
    info->nextEventTime = 0.0;
    return settled(I);
}

EXPORT fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    ME_CALL(fmi2EnterContinuousTimeMode, ALL_PHASES, IN_EVENT);
    S->model.me.mode = ME_CONTINUOUS_TIME_MODE;
    return settled(I);
}

EXPORT fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                              fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    ME_CALL(fmi2CompletedIntegratorStep, ALL_PHASES, IN_CONTINUOUS);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (enterEventMode == NULL || terminateSimulation == NULL) {
        native_error(I, "fmi2CompletedIntegratorStep: enterEventMode or terminateSimulation is NULL");
        return settled(I);
    }
    *enterEventMode = fmi2False; /* no step events: the events are the indicators' */
    *terminateSimulation = S->model.me.stopped ? fmi2True : fmi2False;
    return settled(I);
}

EXPORT fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    ME_CALL(fmi2SetTime, ALL_PHASES, IN_EVENT | IN_CONTINUOUS);
    if (!isfinite(time)) {
        native_error(I, "fmi2SetTime: time = %g is not finite", time);
        return settled(I);
    }
    S->model.me.t = time;
    model_me_outputs(I, S);
    return settled(I);
}

EXPORT fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    ME_CALL(fmi2SetContinuousStates, ALL_PHASES, IN_CONTINUOUS);
    if (!sized(I, "fmi2SetContinuousStates", "nx", x, nx, ME_N_STATES)) return settled(I);
    for (size_t i = 0; i < nx; i++)
        if (!isfinite(x[i])) {
            native_error(I, "fmi2SetContinuousStates: state %zu = %g is not finite", i, x[i]);
            return settled(I);
        }
    for (size_t i = 0; i < nx; i++) S->model.me.x[i] = x[i];
    model_me_outputs(I, S);
    return settled(I);
}

#define AFTER_INITIALISATION (IN_EVENT | IN_CONTINUOUS | IN_TERMINATED)

EXPORT fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx)
{
    ME_CALL(fmi2GetDerivatives, GETTER_PHASES, AFTER_INITIALISATION);
    if (!sized(I, "fmi2GetDerivatives", "nx", dx, nx, ME_N_STATES)) return settled(I);
    double d[ME_MAX_STATES];
    if (model_me_derivatives(I, S, d) != 0) {
        for (size_t i = 0; i < nx; i++) dx[i] = 0.0;
        return settled(I);
    }
    for (size_t i = 0; i < nx; i++) dx[i] = d[i];
    return settled(I);
}

EXPORT fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t ni)
{
    ME_CALL(fmi2GetEventIndicators, GETTER_PHASES, AFTER_INITIALISATION);
    if (!sized(I, "fmi2GetEventIndicators", "ni", z, ni, ME_N_INDICATORS)) return settled(I);
    double g[ME_MAX_INDICATORS];
    model_me_indicators(S, g);
    for (size_t i = 0; i < ni; i++) z[i] = g[i];
    return settled(I);
}

EXPORT fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    ME_CALL(fmi2GetContinuousStates, GETTER_PHASES, AFTER_INITIALISATION);
    if (!sized(I, "fmi2GetContinuousStates", "nx", x, nx, ME_N_STATES)) return settled(I);
    for (size_t i = 0; i < nx; i++) x[i] = S->model.me.x[i];
    return settled(I);
}

EXPORT fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    ME_CALL(fmi2GetNominalsOfContinuousStates, GETTER_PHASES, IN_INSTANTIATED | AFTER_INITIALISATION);
    (void)S;
    if (!sized(I, "fmi2GetNominalsOfContinuousStates", "nx", x_nominal, nx, ME_N_STATES)) return settled(I);
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0; /* x, v in units of the static compression */
    return settled(I);
}

int me_stop_at_pull_in(Instance *inst, const VkModel *model, const MeData *me, const double *z, int *terminate)
{
    for (int i = 1; i < ME_N_INDICATORS; i++) {
        if (z[i] > 0.0) continue;
        DopReport r; /* the co-simulation's pull-in message (vk_solver_message) */
        memset(&r, 0, sizeof r);
        r.t = me->t;
        r.y[0] = me->x[0];
        r.y[1] = me->x[1];
        r.event = i;
        char text[DOP_MESSAGE];
        vk_solver_message(model, DOP_TERMINAL, &r, text, sizeof text);
        native_log(inst, fmi2Warning, "simulation stopped: %s (terminateSimulation)", text);
        *terminate = 1;
        return 1;
    }
    return 0;
}

#endif

#ifdef HAS_DIRECTIONAL_DERIVATIVES
fmi2Status native_directional_derivative(Instance *I, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                         const fmi2ValueReference vKnown[], size_t nKnown, const fmi2Real dvKnown[],
                                         fmi2Real dvUnknown[])
{
    State *S = native_state(I);
    const char *call = "fmi2GetDirectionalDerivative";
    if ((nUnknown > 0 && (vUnknown == NULL || dvUnknown == NULL)) || (nKnown > 0 && (vKnown == NULL || dvKnown == NULL))) {
        native_error(I, "%s: an array argument is NULL", call);
        return settled(I);
    }
    if (S->phase != PHASE_STEP_MODE && S->phase != PHASE_TERMINATED) {
        native_error(I, "%s is not allowed in %s (FMI 2.0: after fmi2ExitInitializationMode, at the model's current "
                     "point)", call, mode_name(current_mode(S)));
        return settled(I);
    }
    if (S->halted && S->phase != PHASE_TERMINATED) {
        native_error(I, "%s refused: %s", call, S->halt_message);
        return settled(I);
    }
    for (size_t i = 0; i < nUnknown; i++) {
        double sum = 0.0;
        for (size_t j = 0; j < nKnown; j++) {
            double partial;
            if (vUnknown[i] >= N_VARIABLES || vKnown[j] >= N_VARIABLES ||
                !model_partial(S, vUnknown[i], vKnown[j], &partial)) {
                native_error(I, "%s: the derivative of valueReference %u by valueReference %u is not provided (%s)",
                             call, vUnknown[i], vKnown[j], MODEL_PARTIALS);
                return settled(I);
            }
            if (!isfinite(partial)) { /* at an electrode (x = +-3R/2) the electrostatic slope is infinite */
                char xt[64];
                native_repr(S->value[VR_x], xt, sizeof xt);
                native_error(I, "%s refused: the derivative of %s by %s is %g (not finite) at x = %s: the state is at "
                             "an electrode, outside the model's domain", call, VARIABLES[vUnknown[i]].name,
                             VARIABLES[vKnown[j]].name, partial, xt);
                return settled(I);
            }
            sum += partial * dvKnown[j];
        }
        if (!isfinite(sum)) {
            native_error(I, "%s refused: the derivative of %s along the seed given is %g (not finite; a seed value "
                         "not finite or too large)", call, VARIABLES[vUnknown[i]].name, sum);
            return settled(I);
        }
        dvUnknown[i] = sum;
    }
    return settled(I);
}
#endif
