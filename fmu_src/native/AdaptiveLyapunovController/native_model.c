/*
 * model.c -- the native controller FMU: AdaptiveLyapunovController.py's slave logic (vibromodel.compiled_loop.
 * make_estimator / CompiledEstimator / fill_controller, control.Controller's constants, StatusSlave) on the
 * compiled controller fmu_src/core/controller.c, with the same checks in the same order and the same messages
 * (fixed texts from rules.h, generated from vibromodel at build time).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmi2_native.h"
#include "controller_setup.h"
#include "me_model.h"
#include "pytext.h"
#include "rules.h"
#include "series.h"

static const fmi2ValueReference INPUT_VRS[VC_INPUTS] = {VR_x, VR_v, VR_x_ref, VR_v_ref, VR_a_ref};
static const fmi2ValueReference OUTPUT_VRS[VC_OUTPUTS] = {
    VR_U, VR_e1, VR_e2, VR_V, VR_mu_hat, VR_a1_hat, VR_a2_hat, VR_a3_hat, VR_a4_hat, VR_a5_hat, VR_Delta_hat,
    VR_beta_hat, VR_gamma_hat};
void model_instantiate(State *s) { memset(&s->model, 0, sizeof s->model); }

/* The outputs from the structure (its out[] holds them only when all were finite: StatusSlave._set_finite). */
static void copy_outputs(State *s)
{
    for (int i = 0; i < VC_OUTPUTS; i++) s->value[OUTPUT_VRS[i]] = s->model.c.out[i];
    s->model.me.locals_stale = 1; /* der(theta^_i) when read: model_lazy_locals */
}

static void copy_inputs(State *s)
{
    for (int i = 0; i < VC_INPUTS; i++) s->model.c.in[i] = s->value[INPUT_VRS[i]];
}

/* control.Controller's constants into the structure (controller_setup.c), then the slave's model setter. */
static void fill(State *s)
{
    VcController *c = &s->model.c;
    native_controller_constants(c, s);
    /* the slave's model setter: its inputs and outputs move into the structure */
    copy_inputs(s);
    for (int i = 0; i < VC_OUTPUTS; i++) c->out[i] = s->value[OUTPUT_VRS[i]];
}

/* The Python exception of a vk_controller_publish that failed with `code`: ValueError('math domain error') (VC_RAISED) or
   StatusSlave._set_finite's NonFiniteOutput naming the first non-finite output (VC_NON_FINITE). */
static void publish_failure(const VcController *c, int code, char *what, size_t size)
{
    double out[VC_OUTPUTS];
    int bad = code == VC_NON_FINITE && vk_controller_outputs(c, c->t, c->theta_hat, out) == VC_OK ? vk_controller_non_finite(out) : -1;
    if (bad < 0) {
        snprintf(what, size, "ValueError('math domain error')");
        return;
    }
    char value[64], message[256];
    native_repr(out[bad], value, sizeof value);
    snprintf(message, sizeof message, "NonFiniteOutput: output %s = %s is not finite; the parameters are beyond the "
             "model's numerical range", VARIABLES[OUTPUT_VRS[bad]].name, value);
    kernel_message_text(message, what, size);
}

void model_initialise(Instance *inst, State *s)
{
    /* every check of make_estimator and control.Controller is a rule of the table, checked before (the scene's
       electrode check has x_start = 0 here, the controller having no initial state) */
    fill(s);
    s->model.built = 1;
    int code = vk_controller_publish(&s->model.c);
    if (code != VC_OK) {
        char what[400];
        publish_failure(&s->model.c, code, what, sizeof what);
        native_halt(inst, "initialisation failed: %s", what);
        return;
    }
    copy_outputs(s);
}

/* AdaptiveLyapunovController._set_input: U, e1, e2, V follow the inputs once initialised. */
void model_input_set(Instance *inst, State *s, fmi2ValueReference vr)
{
    if (!s->model.built) return;
    copy_inputs(s);
    if (s->halted) return;
    int code = vk_controller_publish(&s->model.c);
    if (code != VC_OK) {
        char value[64], what[400];
        native_repr(s->value[vr], value, sizeof value);
        publish_failure(&s->model.c, code, what, sizeof what);
        native_halt(inst, "input %s = %s: %s", VARIABLES[vr].name, value, what);
        return;
    }
    copy_outputs(s);
}

void model_do_step(Instance *inst, State *s, double t, double h)
{
    VcController *c = &s->model.c;
    char a[64], b[64];
    if (!(isfinite(h) && h > 0.0)) {
        native_repr(h, a, sizeof a);
        native_error(inst, "doStep refused: parameter communicationStepSize = %s: %s", a, RULE_STEP_SIZE);
        return;
    }
    if (!(isfinite(t) && fabs(t - c->t) <= RULE_TIME_TOLERANCE * fmax(1.0, fabs(t)))) {
        native_repr(t, a, sizeof a);
        native_repr(c->t, b, sizeof b);
        native_error(inst, "doStep refused: parameter currentCommunicationPoint = %s: the controller is at tau = %s",
                     a, b);
        return;
    }
    for (int i = 0; i < VC_INPUTS; i++)
        if (!isfinite(c->in[i])) {
            native_repr(c->in[i], a, sizeof a);
            native_error(inst, "doStep refused: parameter %s = %s: %s", VARIABLES[INPUT_VRS[i]].name, a, RULE_INPUT);
            return;
        }
    /* HeldInputEstimator.advance, then _publish (vk_controller_do_step does both, the way the fast path runs it) */
    int code = vk_controller_advance(c, t, h, c->in[0], c->in[1], c->in + 2);
    if (code == VC_OK) code = vk_controller_publish(c);
    if (code != VC_OK) {
        char what[400];
        native_repr(t, a, sizeof a);
        publish_failure(c, code, what, sizeof what);
        if (code == VC_NON_FINITE) /* StatusSlave._guarded_step: an ArithmeticError */
            native_halt(inst, "simulation stopped: floating-point failure after tau = %s (%s); the parameters are "
                        "beyond the model's numerical range", a, what);
        else
            native_halt(inst, "doStep failed at tau = %s: %s", a, what);
        return;
    }
    copy_outputs(s);
}

/* Outputs in Initialization Mode: their start values (StatusSlave._initial_output). */
int model_initial_output(const State *s, fmi2ValueReference vr, double *value, char *why, size_t size)
{
    (void)why; (void)size;
    *value = s->value[vr];
    return 1;
}

/* ---- Model Exchange (me_model.h): states theta^ (the estimates), derivatives the update law's rates
   theta^' = lambda2 Lambda^-1 phi(t, x, v) e2 at the inputs set (vk_controller_rates: the integrand of the
   co-simulation's exact increment, vk_controller_increment), no event indicators.  The controller's time and
   estimates follow the Model Exchange time and states (model_me_outputs), so the setters and getters read the
   same structure in both interfaces. ---- */

/* The derivative variables der(theta^_i) (with_derivative_variables, native.py) */
static const fmi2ValueReference DERIVATIVE_VRS[VC_N] = {
    VR_der_mu_hat_, VR_der_a1_hat_, VR_der_a2_hat_, VR_der_a3_hat_, VR_der_a4_hat_, VR_der_a5_hat_,
    VR_der_Delta_hat_, VR_der_beta_hat_, VR_der_gamma_hat_};

/* der(theta^_i) at the current point (co-simulation: the last communication point with the inputs held;
   Model Exchange: the time and inputs set), computed when a local is read after the point changed; NaN where the
   rate is not finite (a getter refuses it) */
void model_lazy_locals(State *s)
{
    if (!s->model.me.locals_stale || !s->model.built) return;
    const VcController *c = &s->model.c;
    double rates[VC_N];
    const int fault = vk_controller_rates(c, c->t, c->in[0], c->in[1], c->in + 2, rates) != VC_OK;
    for (int i = 0; i < VC_N; i++) s->value[DERIVATIVE_VRS[i]] = fault ? NAN : rates[i];
    s->model.me.locals_stale = 0;
}

void model_me_start(Instance *inst, State *s)
{
    (void)inst;
    s->model.me.t = s->model.c.t;
    memcpy(s->model.me.x, s->model.c.theta_hat, VC_N * sizeof(double));
}

int model_me_derivatives(Instance *inst, State *s, double *dx)
{
    const VcController *c = &s->model.c;
    const MeData *me = &s->model.me;
    char tt[64], xt[64], vt[64];
    native_repr(me->t, tt, sizeof tt);
    if (vk_controller_rates(c, me->t, c->in[0], c->in[1], c->in + 2, dx) != VC_OK) { /* an infinite angle */
        native_error(inst, "fmi2GetDerivatives: at tau = %s: ValueError('math domain error')", tt);
        return 1;
    }
    for (int i = 0; i < VC_N; i++) {
        if (isfinite(dx[i])) continue;
        native_repr(c->in[0], xt, sizeof xt);
        native_repr(c->in[1], vt, sizeof vt);
        native_error(inst, "fmi2GetDerivatives: at tau = %s, x = %s, v = %s the rate of %s is %g (not finite); the "
                     "inputs are beyond the model's numerical range", tt, xt, vt, VARIABLES[OUTPUT_VRS[4 + i]].name,
                     dx[i]);
        return 1;
    }
    return 0;
}

void model_me_indicators(const State *s, double *z) { (void)s; (void)z; } /* ME_N_INDICATORS 0 */

int model_me_outputs(Instance *inst, State *s)
{
    (void)inst;
    VcController *c = &s->model.c;
    c->t = s->model.me.t;
    memcpy(c->theta_hat, s->model.me.x, sizeof c->theta_hat);
    double out[VC_OUTPUTS];
    if (vk_controller_outputs(c, c->t, c->theta_hat, out) == VC_OK && vk_controller_non_finite(out) < 0) {
        memcpy(c->out, out, sizeof c->out);
        copy_outputs(s);
        return 0;
    }
    for (int i = 0; i < VC_OUTPUTS; i++) s->value[OUTPUT_VRS[i]] = NAN; /* a getter refuses them, naming one */
    s->model.me.locals_stale = 1;
    return 0;
}

/* No events: nothing discrete changes, nothing stops the controller. */
int model_me_event(Instance *inst, State *s, int *terminate)
{
    (void)inst; (void)s; (void)terminate;
    return 0;
}
