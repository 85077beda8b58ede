/*
 * me_model.h -- what a native model provides for Model Exchange (FMI 2.0 in fmi2_me.c, FMI 3.0 through
 * fmi3_native.c) and for FMI 3.0 co-simulation's early return.  A model that has them says so in its config.h:
 *   #define ME_N_STATES n        its continuous states (FMI order: the order of <Derivatives>)
 *   #define ME_N_INDICATORS m    its event indicators
 * and keeps an MeData `me` in its ModelData (so that the FMU state holds the Model Exchange state too).
 * The equations stay the model's (native_model.c on fmu_src/core): these hooks only read and write them.
 */
#ifndef ME_MODEL_H
#define ME_MODEL_H

#include "fmi2_native.h"  /* with config.h, whose ModelData holds an MeData (me_data.h) */


#ifdef ME_N_STATES
/* After a successful model_initialise of a Model Exchange instance: the states and t from the model's start (the
   caller sets the mode and the stop flag). */
void model_me_start(Instance *inst, State *s);
#if ME_N_INDICATORS > 0 /* the models with event indicators are those on the compiled plant (core/plant.h) */
/* fmi2_me.c, for model_me_event: when a pull-in indicator (z[1] ...) is at or below 0, log the co-simulation's
   pull-in message (vk_solver_message of `model`, at the ME state) as a warning and set *terminate; 1 if it did. */
int me_stop_at_pull_in(Instance *inst, const VkModel *model, const MeData *me, const double *z, int *terminate);
#endif
/* Derivatives of the states s->model.me.x at s->model.me.t (inputs from s->value); 0, or 1 after native_error. */
int model_me_derivatives(Instance *inst, State *s, double *dx);
/* The event indicators at the current states (contact, upper gap, lower gap ...), each a continuous function that
   changes sign at the event. */
void model_me_indicators(const State *s, double *z);
/* The continuous outputs at the current states and time into s->value (called after every change of time, states
   or inputs); 0, or 1 after native_error. */
int model_me_outputs(Instance *inst, State *s);
/* Event mode (fmi2NewDiscreteStates): the discrete variables from the states; *terminate set at a terminal event
   (logged).  0, or 1 after native_error. */
int model_me_event(Instance *inst, State *s, int *terminate);
#endif

#ifdef HAS_EARLY_RETURN
/* FMI 3.0 co-simulation's doStep with early return (fmi3_native.c): as model_do_step, but returns at the first
   event (contact loss, re-contact) inside (t, t + h]: s->model.me.reached the time reached, step_event 1 when the
   step ended on an event (early when reached < t + h). */
void model_do_step_early(Instance *inst, State *s, double t, double h);
#endif

#ifdef MODEL_LAZY_OUTPUTS
/* Before output vr is read (fmi2_native.c's getter): if it is one a doStep left to be computed when read, those
   outputs brought up to date (the plant's x'' and forces: a host that reads x alone never pays for them) */
void model_lazy_outputs(State *s, fmi2ValueReference vr);
#endif

#ifdef MODEL_LAZY_LOCALS
/* Before a local variable is read (fmi2_native.c's getter): the locals the model computes on demand brought up to
   date (the closed loop's der(...): one right-hand side, only when read). */
void model_lazy_locals(State *s);
#endif

#ifdef HAS_DIRECTIONAL_DERIVATIVES
/* The partial derivative d(unknown)/d(known) at the current point (Model Exchange: the states and time set; co-
   simulation: the last communication point): 1 with *value, or 0 when the FMU does not provide that pair. */
int model_partial(const State *s, fmi2ValueReference unknown, fmi2ValueReference known, double *value);
/* The text naming the pairs model_partial provides (for the refusal's log line) */
extern const char *const MODEL_PARTIALS;
/* fmi2GetDirectionalDerivative on model_partial (fmi2_me.c): dvUnknown[i] = sum_j d(vUnknown[i])/d(vKnown[j])
   dvKnown[j]; fmi2Error naming the first pair not provided, a NULL array, or a call before initialisation. */
fmi2Status native_directional_derivative(Instance *I, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                         const fmi2ValueReference vKnown[], size_t nKnown, const fmi2Real dvKnown[],
                                         fmi2Real dvUnknown[]);
#endif

#endif
