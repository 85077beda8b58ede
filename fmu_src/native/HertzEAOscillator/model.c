/*
 * model.c -- the native plant FMU: HertzEAOscillator.py's slave logic (vibromodel.plant.make_plant,
 * CompiledPlant, StatusSlave._initialise / _guarded_step) on the compiled kernel vibrokernel.c, with the
 * same checks, in the same order, and the same messages.  The rules' constants and fixed texts come from
 * rules.h, generated from vibromodel at build time (harness/vibrofmu/native.py).
 *
 * Fidelities 0, 1, 2 with the adaptive solver run here (kernel = 0 and 1 alike: the pure-Python plant gives
 * the compiled kernel's bits).  Fidelity 3 (slow-flow table), fidelity 4 (OAFM fit) and RK4 need code that
 * only the pythonfmu FMU has: they are refused with fmi2Error naming it.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmi2_native.h"
#include "pytext.h"
#include "rules.h"
#include "scene_checks.h"
#include "series.h"

#define PYTHONFMU_ALTERNATIVE "use the pythonfmu FMU HertzEAOscillator.fmu (build/HertzEAOscillator.fmu), which runs it in Python"

static const fmi2ValueReference OUTPUT_VRS[5] = {VR_x, VR_v, VR_a, VR_F_contact, VR_F_electrostatic};

void model_instantiate(State *s) { memset(&s->model, 0, sizeof s->model); }

/* U is read by the next doStep (the plant holds it over the step). */
void model_input_set(Instance *inst, State *s, fmi2ValueReference vr) { (void)inst; (void)s; (void)vr; }

/* ---- parameter checks (vibromodel.parameters.validate, plant.Settings.validate, OafmSettings.validate) ---- */

/* ParameterError text: "parameter NAME = repr(value): reason" */
static void halt_parameter(Instance *inst, const char *name, double value, int integer, const char *reason)
{
    char text[64];
    if (integer) snprintf(text, sizeof text, "%d", (int)value);
    else py_repr(value, text, sizeof text);
    native_halt(inst, "parameter %s = %s: %s", name, text, reason);
}

/* After the table of rules (checked before this model starts, fmi2_native.c): the checks vibromodel makes in
   code, in its order (parameters.validate's electrode gaps, OafmSettings.validate's tau_star < oafm_tau_end). */
static int valid(Instance *inst, const State *s)
{
    char reason[256];
    if (!vibro_gaps_check(s->value[VR_x_start], s->value[VR_R], reason, sizeof reason)) {
        halt_parameter(inst, "x_start", s->value[VR_x_start], 0, reason);
        return 0;
    }
    if (s->value[VR_fidelity] == 4) {
        const double tau_star = s->value[VR_tau_star], tau_end = s->value[VR_oafm_tau_end];
        if (tau_end != 0.0 && tau_star != 0.0 && tau_end <= tau_star) {
            snprintf(reason, sizeof reason, "must exceed tau_star = %g", tau_star);
            halt_parameter(inst, "oafm_tau_end", tau_end, 0, reason);
            return 0;
        }
    }
    return 1;
}

/* ---- the kernel's errors as the Python slave reports them ---- */

/* The pending error's exception: message; clears it as CompiledPlant._raise_pending does. Returns its code. */
static int take_pending(VkPlant *p, char *message, size_t size, double *t, double *x, double *v)
{
    int code = (int)p->error;
    snprintf(message, size, "%s", p->message);
    *t = p->error_t; *x = p->error_x; *v = p->error_v;
    p->error = 0;
    p->error_t = p->error_x = p->error_v = 0.0;
    memset(p->message, 0, sizeof p->message);
    return code;
}

static int is_arithmetic(const char *message)
{
    return strncmp(message, "ZeroDivisionError:", 18) == 0 || strncmp(message, "OverflowError:", 14) == 0;
}

/* ---- initialisation ---- */

static void publish(State *s)
{
    const VkPlant *p = &s->model.plant;
    for (int i = 0; i < 5; i++)
        if (!isfinite(p->out[i])) return; /* StatusSlave._set_finite */
    for (int i = 0; i < 5; i++) s->value[OUTPUT_VRS[i]] = p->out[i];
    s->value[VR_in_contact] = p->in_contact != 0;
}

void model_initialise(Instance *inst, State *s)
{
    const double rtol_requested = s->has_tolerance ? s->tolerance : s->value[VR_rtol];
    if (!valid(inst, s)) return;
    const int fidelity = (int)s->value[VR_fidelity], solver = (int)s->value[VR_solver];
    if (fidelity == 3 || fidelity == 4) {
        halt_parameter(inst, "fidelity", fidelity, 1, fidelity == 3
            ? "the native FMU cannot tabulate the averaged slow flow (fidelity 3 needs Python); " PYTHONFMU_ALTERNATIVE
            : "the native FMU cannot fit the OAFM solution (fidelity 4 needs Python); " PYTHONFMU_ALTERNATIVE);
        return;
    }
    if (solver == 1) {
        halt_parameter(inst, "solver", solver, 1, "the native FMU has no RK4 solver; use solver = 0 (adaptive "
                       "DOP853), or " PYTHONFMU_ALTERNATIVE);
        return;
    }
    double rtol = rtol_requested;
    if (rtol < RULE_MIN_RTOL) { /* parameters.clamp_tolerance */
        char requested[64];
        py_repr(rtol, requested, sizeof requested);
        native_log(inst, fmi2Warning, "parameter rtol = %s is below %.3g (100 machine epsilons: the error control "
                   "would see only rounding): using rtol = %.3g", requested, RULE_MIN_RTOL, RULE_MIN_RTOL);
        rtol = RULE_MIN_RTOL;
    }
    VkPlant *p = &s->model.plant;
    memset(p, 0, sizeof *p);
    const double mu = s->value[VR_mu], Delta = s->value[VR_Delta], omega = s->value[VR_omega],
                 alpha = s->value[VR_alpha], beta = s->value[VR_beta], gamma = s->value[VR_gamma],
                 Omega = s->value[VR_Omega], R = s->value[VR_R];
    p->mu = mu; p->Delta = Delta; p->omega = omega; p->alpha = alpha; p->beta = beta; p->gamma = gamma;
    p->Omega = Omega; p->R = R;
    p->pull_in_c = 2.0 / (3.0 * R); /* models.pull_in_slope */
    p->pull_in_gap = RULE_PULL_IN_GAP;
    p->load_forcing = Delta != 0.0;
    p->ac = beta != 0.0 || gamma != 0.0;
    if (fidelity == 0) {
        p->polynomial = 0;
        p->electrostatics = alpha != 0.0 || p->ac;
    } else {
        /* (models.PolynomialModel's "R out of range" cannot happen: the rules keep R in [1e-6, 1e6]) */
        p->polynomial = 1;
        p->electrostatics = p->ac;
        vibro_series(fidelity == 2, alpha, gamma, R, p->poly, p->g1, p->g2, p->g3);
    }
    p->rtol = rtol;
    p->atol = rtol * RULE_ATOL_PER_RTOL;
    p->max_step = s->value[VR_max_step] != 0.0 ? s->value[VR_max_step] : INFINITY;
    p->step_budget = RULE_MAX_STEPS_PER_DOSTEP;
    p->time_tolerance = RULE_TIME_TOLERANCE;
    p->max_steps_per_dostep = RULE_MAX_STEPS_PER_DOSTEP;
    p->plant_t = s->start_time;
    p->U_input = 0.0;
    p->enabled = 1;
    s->model.built = 1;
    char message[VK_MESSAGE + 64];
    double et, ex, ev, xva[3];
    int code = vk_restart(p, s->start_time, s->value[VR_x_start], s->value[VR_v_start], 0.0);
    if (code == VK_OK) code = vk_plant_state(p, xva);
    if (code == VK_OK) code = vk_outputs_at(p, p->plant_t, xva[0], xva[1], &xva[2]);
    if (code != VK_OK) { /* StatusSlave._initialise */
        char what[VK_MESSAGE + 64];
        int pending = take_pending(p, message, sizeof message, &et, &ex, &ev);
        if (pending == VK_TERMINAL || pending == VK_FAILED) {
            native_halt(inst, "simulation stopped: %s", message);
        } else {
            py_exception_repr(message, what, sizeof what);
            native_halt(inst, "initialisation failed: %s", what);
        }
        return;
    }
    native_log(inst, fmi2OK, "DOP853 on the native FMU's compiled kernel (no Python)");
    p->U_input = s->value[VR_U];
    publish(s);
}

/* ---- doStep ---- */

void model_do_step(Instance *inst, State *s, double t, double h)
{
    VkPlant *p = &s->model.plant;
    const double U = s->value[VR_U];
    p->U_input = U;
    int code = vk_do_step(p, t, h);
    if (code == VK_OK) {
        publish(s);
        return;
    }
    char a[64], b[64], message[VK_MESSAGE + 64], what[VK_MESSAGE + 64];
    switch (code) { /* plant.check_step's ParameterErrors */
    case VK_BAD_STEP:
        py_repr(h, a, sizeof a);
        native_error(inst, "doStep refused: parameter communicationStepSize = %s: %s", a, RULE_STEP_SIZE);
        return;
    case VK_BAD_INPUT:
        py_repr(U, a, sizeof a);
        native_error(inst, "doStep refused: parameter U = %s: %s", a, RULE_INPUT);
        return;
    case VK_TOO_MANY_STEPS:
        py_repr(h, a, sizeof a);
        native_error(inst, "doStep refused: parameter communicationStepSize = %s: needs more than %.0f steps of %g "
                     "(max_step); make smaller communication steps or raise max_step", a,
                     RULE_MAX_STEPS_PER_DOSTEP, p->max_step);
        return;
    case VK_BAD_TIME:
        py_repr(t, a, sizeof a);
        py_repr(p->plant_t, b, sizeof b);
        native_error(inst, "doStep refused: parameter currentCommunicationPoint = %s: the plant is at tau = %s", a, b);
        return;
    default:
        break;
    }
    double et, ex, ev;
    int pending = take_pending(p, message, sizeof message, &et, &ex, &ev);
    if (pending == VK_TERMINAL || pending == VK_FAILED) { /* HertzEAOscillator.do_step's `stopped` */
        if (vk_outputs_at(p, et, ex, ev, NULL) == VK_OK) publish(s);
        else take_pending(p, what, sizeof what, &et, &ex, &ev);
        native_halt(inst, "simulation stopped: %s", message);
        return;
    }
    py_repr(t, a, sizeof a);
    py_exception_repr(message, what, sizeof what);
    if (is_arithmetic(message))
        native_halt(inst, "simulation stopped: floating-point failure after tau = %s (%s); the parameters are beyond "
                    "the model's numerical range", a, what);
    else
        native_halt(inst, "doStep failed at tau = %s: %s", a, what);
}
