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
#include "pytext.h"
#include "rules.h"
#include "series.h"

static const fmi2ValueReference INPUT_VRS[VC_INPUTS] = {VR_x, VR_v, VR_x_ref, VR_v_ref, VR_a_ref};
static const fmi2ValueReference OUTPUT_VRS[VC_OUTPUTS] = {
    VR_U, VR_e1, VR_e2, VR_V, VR_mu_hat, VR_a1_hat, VR_a2_hat, VR_a3_hat, VR_a4_hat, VR_a5_hat, VR_Delta_hat,
    VR_beta_hat, VR_gamma_hat};
static const fmi2ValueReference ESTIMATE_START_VRS[VC_N] = {
    VR_mu_hat_start, VR_a1_hat_start, VR_a2_hat_start, VR_a3_hat_start, VR_a4_hat_start, VR_a5_hat_start,
    VR_Delta_hat_start, VR_beta_hat_start, VR_gamma_hat_start};
static const fmi2ValueReference GAIN_VRS[11] = {VR_lambda1, VR_lambda2, VR_lambda3, VR_lambda4, VR_lambda5,
                                                VR_lambda6, VR_lambda7, VR_lambda8, VR_lambda9, VR_lambda10,
                                                VR_lambda11};

void model_instantiate(State *s) { memset(&s->model, 0, sizeof s->model); }

/* The outputs from the structure (its out[] holds them only when all were finite: StatusSlave._set_finite). */
static void copy_outputs(State *s)
{
    for (int i = 0; i < VC_OUTPUTS; i++) s->value[OUTPUT_VRS[i]] = s->model.c.out[i];
}

static void copy_inputs(State *s)
{
    for (int i = 0; i < VC_INPUTS; i++) s->model.c.in[i] = s->value[INPUT_VRS[i]];
}

/* control.Controller's constants into the structure (compiled_loop.fill_controller). */
static void fill(State *s)
{
    VcController *c = &s->model.c;
    memset(c, 0, sizeof *c);
    const double mu = s->value[VR_mu], Delta = s->value[VR_Delta], omega = s->value[VR_omega],
                 Omega = s->value[VR_Omega], alpha = s->value[VR_alpha], beta = s->value[VR_beta],
                 gamma = s->value[VR_gamma], R = s->value[VR_R];
    double poly[6], g1[6], g2[6];
    vibro_series(0, alpha, gamma, R, poly, g1, g2, c->g3);  /* forces.coefficients, series_g3 */
    const double theta[VC_N] = {mu, poly[1], poly[2], poly[3], poly[4], poly[5], Delta, beta, gamma};
    memcpy(c->theta, theta, sizeof theta);                /* control.true_theta */
    c->phi.w_delta = omega; c->phi.delta_sign = 1.0; c->phi.w_beta = Omega; c->phi.w_gamma = 2.0 * Omega;
    const int law = (int)s->value[VR_law];
    if (law == 2) { /* Eq. 81 as printed: -cos tau for Delta^, cos Omega tau for gamma^ */
        c->phi_update.w_delta = 1.0; c->phi_update.delta_sign = -1.0;
        c->phi_update.w_beta = Omega; c->phi_update.w_gamma = Omega;
    } else {
        c->phi_update = c->phi;
    }
    c->l1 = s->value[VR_lambda1];
    c->l2 = s->value[VR_lambda2];
    for (int i = 0; i < VC_N; i++) {
        c->Lambda[i] = s->value[GAIN_VRS[i + 2]];
        c->adaptation[i] = c->l2 / c->Lambda[i];          /* lambda2 Lambda^-1 */
    }
    c->c = sqrt(c->l1 / c->l2);                           /* Eq. 84 */
    c->k_damping = s->value[VR_k_damping];
    c->promised_e1 = -pow(c->l1, 1.5) / sqrt(c->l2);      /* Eq. 85 */
    c->true_delta = Delta;
    c->law = law;
    c->time_tolerance = RULE_TIME_TOLERANCE;
    c->t = s->start_time;
    for (int i = 0; i < VC_N; i++) c->theta_hat[i] = s->value[ESTIMATE_START_VRS[i]];
    c->enabled = 1;
    /* the slave's model setter: its inputs and outputs move into the structure */
    copy_inputs(s);
    for (int i = 0; i < VC_OUTPUTS; i++) c->out[i] = s->value[OUTPUT_VRS[i]];
}

void model_initialise(Instance *inst, State *s)
{
    /* every check of make_estimator and control.Controller is a rule of the table, checked before (the scene's
       electrode check has x_start = 0 here, the controller having no initial state) */
    fill(s);
    s->model.built = 1;
    if (vc_publish(&s->model.c) != VC_OK) {
        native_halt(inst, "initialisation failed: ValueError('math domain error')");
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
    if (vc_publish(&s->model.c) != VC_OK) {
        char value[64];
        native_repr(s->value[vr], value, sizeof value);
        native_halt(inst, "input %s = %s: ValueError('math domain error')", VARIABLES[vr].name, value);
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
    /* HeldInputEstimator.advance, then _publish (vc_do_step does both, the way the fast path runs it) */
    if (vc_advance(c, t, h, c->in[0], c->in[1], c->in + 2) != VC_OK || vc_publish(c) != VC_OK) {
        native_repr(t, a, sizeof a);
        native_halt(inst, "doStep failed at tau = %s: ValueError('math domain error')", a);
        return;
    }
    copy_outputs(s);
}
