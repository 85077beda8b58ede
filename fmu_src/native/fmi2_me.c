/*
 * fmi2_me.c -- the FMI 2.0 Model Exchange API of the native FMUs, written once for every model that provides the
 * hooks of me_model.h (config.h defines ME_N_STATES); compiled beside fmi2_native.c into the same binary, so one
 * FMU offers both <CoSimulation> and <ModelExchange> (as the Reference-FMUs do).
 *
 * Modes: fmi2ExitInitializationMode of a Model Exchange instance leaves it in Event Mode (fmi2_native.c calls
 * model_me_start); fmi2EnterContinuousTimeMode / fmi2EnterEventMode switch; fmi2Terminate ends.  Which call is
 * allowed in which mode is the state table's (fmi2_calls.h: FMI2ME_MASK_<call>, asked by NATIVE_ALLOWED, as every
 * FMI 2.0 call of the native FMUs asks it); a call out of its mode, a wrong array size or a NULL array is fmi2Error
 * with one log line naming the call, the mode and the rule; after an error only the getters and fmi2Reset /
 * fmi2FreeInstance are answered (the error state of fmi2_layer.c).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "me_model.h"
#include "pytext.h"

#ifdef ME_N_STATES
#if ME_N_INDICATORS > 0 /* a model on the plant (the controller has no indicators and no plant) */
#include "plant.h" /* vk_solver_message: the co-simulation's pull-in message (me_stop_at_pull_in) */
#endif

#define EXPORT FMI2_Export

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

/* The call's checks: a live instance, then the state table of its interface (FMI2ME_MASK_F: Model Exchange;
   FMI2_MASK_F is 0 for these calls, so a co-simulation instance is told it has no such call). */
#define ME_CALL(F)                                                                                           \
    Instance *I = (Instance *)c;                                                                             \
    if (!fmi2_live(I, FMI2_LIVE_INSTANCE)) return fmi2Error;                                                 \
    NATIVE_ALLOWED(I, F);                                                                                    \
    State *S = native_state(I)

EXPORT fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    ME_CALL(fmi2EnterEventMode);
    S->model.me.mode = ME_EVENT_MODE;
    return native_settle(I);
}

EXPORT fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    ME_CALL(fmi2NewDiscreteStates);
    if (info == NULL) {
        native_error(I, "fmi2NewDiscreteStates: fmi2EventInfo is NULL");
        return native_settle(I);
    }
    int terminate = 0;
    if (!S->model.me.stopped && model_me_event(I, S, &terminate) == 0 && terminate) S->model.me.stopped = 1;
    info->newDiscreteStatesNeeded = fmi2False; /* the discrete state follows the continuous one: no iteration */
    info->terminateSimulation = S->model.me.stopped ? fmi2True : fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False; /* an impact is continuous: no state is reset */
    info->nextEventTimeDefined = fmi2False;           /* no time events */
    info->nextEventTime = 0.0;
    return native_settle(I);
}

EXPORT fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    ME_CALL(fmi2EnterContinuousTimeMode);
    S->model.me.mode = ME_CONTINUOUS_TIME_MODE;
    return native_settle(I);
}

EXPORT fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                              fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    ME_CALL(fmi2CompletedIntegratorStep);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (enterEventMode == NULL || terminateSimulation == NULL) {
        native_error(I, "fmi2CompletedIntegratorStep: enterEventMode or terminateSimulation is NULL");
        return native_settle(I);
    }
    *enterEventMode = fmi2False; /* no step events: the events are the indicators' */
    *terminateSimulation = S->model.me.stopped ? fmi2True : fmi2False;
    return native_settle(I);
}

EXPORT fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    ME_CALL(fmi2SetTime);
    if (!isfinite(time)) {
        native_error(I, "fmi2SetTime: time = %g is not finite", time);
        return native_settle(I);
    }
    S->model.me.t = time;
    model_me_outputs(I, S);
    return native_settle(I);
}

EXPORT fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    ME_CALL(fmi2SetContinuousStates);
    if (!sized(I, "fmi2SetContinuousStates", "nx", x, nx, ME_N_STATES)) return native_settle(I);
    for (size_t i = 0; i < nx; i++)
        if (!isfinite(x[i])) {
            native_error(I, "fmi2SetContinuousStates: state %zu = %g is not finite", i, x[i]);
            return native_settle(I);
        }
    for (size_t i = 0; i < nx; i++) S->model.me.x[i] = x[i];
    model_me_outputs(I, S);
    return native_settle(I);
}

EXPORT fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx)
{
    ME_CALL(fmi2GetDerivatives);
    if (!sized(I, "fmi2GetDerivatives", "nx", dx, nx, ME_N_STATES)) return native_settle(I);
    double d[ME_MAX_STATES];
    if (model_me_derivatives(I, S, d) != 0) {
        for (size_t i = 0; i < nx; i++) dx[i] = 0.0;
        return native_settle(I);
    }
    for (size_t i = 0; i < nx; i++) dx[i] = d[i];
    return native_settle(I);
}

EXPORT fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t ni)
{
    ME_CALL(fmi2GetEventIndicators);
    if (!sized(I, "fmi2GetEventIndicators", "ni", z, ni, ME_N_INDICATORS)) return native_settle(I);
    double g[ME_MAX_INDICATORS];
    model_me_indicators(S, g);
    for (size_t i = 0; i < ni; i++)
        if (!isfinite(g[i])) { /* a state set beyond the model's numerical range (x = 1.8e308: the contact indicator
                                  1 + 2x/3 overflows; found by tests/fuzz): refused as fmi2GetDerivatives refuses it */
            char gt[64], xt[64];
            native_repr(g[i], gt, sizeof gt);
            native_repr(S->model.me.x[0], xt, sizeof xt);
            native_error(I, "fmi2GetEventIndicators: event indicator %zu = %s at x = %s: the state is beyond the "
                         "model's numerical range", i, gt, xt);
            for (size_t k = 0; k < ni; k++) z[k] = 0.0;
            return native_settle(I);
        }
    for (size_t i = 0; i < ni; i++) z[i] = g[i];
    return native_settle(I);
}

EXPORT fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    ME_CALL(fmi2GetContinuousStates);
    if (!sized(I, "fmi2GetContinuousStates", "nx", x, nx, ME_N_STATES)) return native_settle(I);
    for (size_t i = 0; i < nx; i++) x[i] = S->model.me.x[i];
    return native_settle(I);
}

EXPORT fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    ME_CALL(fmi2GetNominalsOfContinuousStates);
    (void)S;
    if (!sized(I, "fmi2GetNominalsOfContinuousStates", "nx", x_nominal, nx, ME_N_STATES)) return native_settle(I);
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0; /* x, v in units of the static compression */
    return native_settle(I);
}

#if ME_N_INDICATORS > 0
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
        return native_settle(I);
    }
    if (S->halted && S->phase != PHASE_TERMINATED) {
        native_error(I, "%s refused: %s", call, S->halt_message);
        return native_settle(I);
    }
    for (size_t i = 0; i < nUnknown; i++) {
        double sum = 0.0;
        for (size_t j = 0; j < nKnown; j++) {
            double partial;
            if (vUnknown[i] >= N_VARIABLES || vKnown[j] >= N_VARIABLES ||
                !model_partial(S, vUnknown[i], vKnown[j], &partial)) {
                native_error(I, "%s: the derivative of valueReference %u by valueReference %u is not provided (%s)",
                             call, vUnknown[i], vKnown[j], MODEL_PARTIALS);
                return native_settle(I);
            }
            if (!isfinite(partial)) { /* at an electrode (x = +-3R/2) the electrostatic slope is infinite */
                char xt[64];
                native_repr(S->value[VR_x], xt, sizeof xt);
                native_error(I, "%s refused: the derivative of %s by %s is %g (not finite) at x = %s: the state is at "
                             "an electrode, outside the model's domain", call, VARIABLES[vUnknown[i]].name,
                             VARIABLES[vKnown[j]].name, partial, xt);
                return native_settle(I);
            }
            sum += partial * dvKnown[j];
        }
        if (!isfinite(sum)) {
            native_error(I, "%s refused: the derivative of %s along the seed given is %g (not finite; a seed value "
                         "not finite or too large)", call, VARIABLES[vUnknown[i]].name, sum);
            return native_settle(I);
        }
        dvUnknown[i] = sum;
    }
    return native_settle(I);
}
#endif
