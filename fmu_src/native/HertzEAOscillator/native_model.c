/*
 * model.c -- the native plant FMU: HertzEAOscillator.py's slave logic (vibromodel.plant.make_plant,
 * CompiledPlant, StatusSlave._initialise / _guarded_step) on the compiled kernel vibrokernel.c, with the
 * same checks, in the same order, and the same messages.  The rules' constants and fixed texts come from
 * rules.h, generated from vibromodel at build time (harness/vibrofmu/fmus/native.py).
 *
 * The fidelities the registry lets the native FMUs run (fidelity.h: 0, 1, 2) with DOP853 or RK4 run here (kernel = 0
 * and 1 alike: the pure-Python plant gives the compiled kernel's bits).  The others (fidelity 3's slow-flow table,
 * fidelity 4's OAFM fit need set-up code that only the pythonfmu FMU has) are refused with fmi2Error naming it.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fidelity.h"
#include "fmi2_native.h"
#include "plant_setup.h"
#include "pyfloat.h"
#include "pytext.h"
#include "rules.h"
#include "scene_checks.h"
#include "series.h"
#include "solver.h"

#define PYTHONFMU_ALTERNATIVE "use the pythonfmu FMU HertzEAOscillator.fmu (build/HertzEAOscillator.fmu), which runs it in Python"

static const fmi2ValueReference OUTPUT_VRS[5] = {VR_x, VR_v, VR_a, VR_F_contact, VR_F_electrostatic};

void model_instantiate(State *s) { memset(&s->model, 0, sizeof s->model); }

/* U is read by the next doStep (the plant holds it over the step). */
void model_input_set(Instance *inst, State *s, fmi2ValueReference vr) { (void)inst; (void)s; (void)vr; }

/* ---- parameter checks (vibromodel.parameters.validate, plant.Settings.validate, OafmSettings.validate) ---- */

/* After the table of rules (checked before this model starts, fmi2_native.c): the checks vibromodel makes in
   code, in its order (parameters.validate's electrode gaps, OafmSettings.validate's tau_star < oafm_tau_end). */
static int valid(Instance *inst, const State *s)
{
    char reason[256];
    if (!vibro_gaps_check(s->value[VR_x_start], s->value[VR_R], reason, sizeof reason)) {
        native_halt_parameter(inst, "x_start", s->value[VR_x_start], 0, reason);
        return 0;
    }
    if (VK_FIDELITIES[(int)s->value[VR_fidelity]].oafm_settings) {
        const double tau_star = s->value[VR_tau_star], tau_end = s->value[VR_oafm_tau_end];
        if (tau_end != 0.0 && tau_star != 0.0 && tau_end <= tau_star) {
            snprintf(reason, sizeof reason, "must exceed tau_star = %g", tau_star);
            native_halt_parameter(inst, "oafm_tau_end", tau_end, 0, reason);
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

static const char *const OUTPUT_NAMES[5] = {"x", "v", "a", "F_contact", "F_electrostatic"};

/* The first non-finite output (StatusSlave._set_finite's NonFiniteOutput), or -1. */
static int non_finite_output(const VkPlant *p)
{
    for (int i = 0; i < 5; i++)
        if (!isfinite(p->out[i])) return i;
    return -1;
}

static void publish(State *s)
{
    const VkPlant *p = &s->model.plant;
    for (int i = 0; i < 5; i++) s->value[OUTPUT_VRS[i]] = p->out[i];
    s->value[VR_in_contact] = p->in_contact != 0;
}

void model_initialise(Instance *inst, State *s)
{
    const double rtol_requested = s->has_tolerance ? s->tolerance : s->value[VR_rtol];
    if (!valid(inst, s)) return;
    const int fidelity = (int)s->value[VR_fidelity], solver = (int)s->value[VR_solver];
    if (VK_FIDELITIES[fidelity].native_refusal) {
        char reason[256];
        snprintf(reason, sizeof reason, "%s; %s", VK_FIDELITIES[fidelity].native_refusal, PYTHONFMU_ALTERNATIVE);
        native_halt_parameter(inst, "fidelity", fidelity, 1, reason);
        return;
    }
    double rtol = rtol_requested;
    int clamped = rtol < RULE_MIN_RTOL; /* parameters.clamp_tolerance */
    if (clamped) rtol = RULE_MIN_RTOL;
    VkPlant *p = &s->model.plant;
    memset(p, 0, sizeof *p);
    native_plant_model(&p->model, s, fidelity); /* compiled._model_fields */
    const double max_step = s->value[VR_max_step];
    p->dop.rtol = rtol;
    p->dop.atol = rtol * RULE_ATOL_PER_RTOL;
    p->dop.max_step = max_step != 0.0 ? max_step : native_drive_ceiling(s, 0.0);  /* models.drive_step_ceiling */
    p->dop.step_budget = RULE_MAX_STEPS_PER_DOSTEP;
    p->rk4.max_step = max_step != 0.0 ? max_step : RULE_RK4_DEFAULT_STEP;
    p->solver = solver;
    p->time_tolerance = RULE_TIME_TOLERANCE;
    p->max_steps_per_dostep = RULE_MAX_STEPS_PER_DOSTEP;
    p->plant_t = s->start_time;
    p->U_input = 0.0;
    p->enabled = 1;
    s->model.built = 1;
    char message[VK_MESSAGE + 64];
    double et, ex, ev, xva[3];
    int code = vk_init(p, s->start_time, s->value[VR_x_start], s->value[VR_v_start]);
    if (code == VK_OK) { /* the slave's _start: notes (fmi2OK), warnings, the first outputs */
        native_log(inst, fmi2OK, "%s on the native FMU's compiled kernel (no Python)", vk_solvers[solver]->name);
        if (clamped) {
            char requested[64];
            native_repr(rtol_requested, requested, sizeof requested);
            native_log(inst, fmi2Warning, "parameter rtol = %s is below %.3g (100 machine epsilons: the error "
                       "control would see only rounding): using rtol = %.3g", requested, RULE_MIN_RTOL, RULE_MIN_RTOL);
        }
        native_drive_warnings(inst, s, vk_solvers[solver], p->rk4.max_step);
        code = vk_plant_state(p, xva);
    }
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
    int bad = non_finite_output(p);
    if (bad >= 0) {
        char value[64];
        native_repr(p->out[bad], value, sizeof value);
        native_halt(inst, "initialisation failed: NonFiniteOutput('output %s = %s is not finite; the parameters are "
                    "beyond the model's numerical range')", OUTPUT_NAMES[bad], value);
        return;
    }
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
        int bad = non_finite_output(p);
        if (bad >= 0) { /* the status shim's fast_outputs_checked */
            native_error(inst, "simulation stopped: output with valueReference %u is %g (not finite) after the step "
                         "from tau = %.17g; the parameters are beyond the model's numerical range",
                         (unsigned)OUTPUT_VRS[bad], p->out[bad], t);
            return;
        }
        publish(s);
        return;
    }
    char a[64], b[64], message[VK_MESSAGE + 64], what[VK_MESSAGE + 64];
    switch (code) { /* plant.check_step's ParameterErrors */
    case VK_BAD_STEP:
        native_repr(h, a, sizeof a);
        native_error(inst, "doStep refused: parameter communicationStepSize = %s: %s", a, RULE_STEP_SIZE);
        return;
    case VK_BAD_INPUT:
        native_repr(U, a, sizeof a);
        native_error(inst, "doStep refused: parameter U = %s: %s", a, RULE_INPUT);
        return;
    case VK_TOO_MANY_STEPS:
        native_repr(h, a, sizeof a);
        native_error(inst, "doStep refused: parameter communicationStepSize = %s: needs more than %.0f steps of %g "
                     "(max_step); make smaller communication steps or raise max_step", a,
                     RULE_MAX_STEPS_PER_DOSTEP, vk_step_ceiling(p));
        return;
    case VK_BAD_TIME:
        native_repr(t, a, sizeof a);
        native_repr(p->plant_t, b, sizeof b);
        native_error(inst, "doStep refused: parameter currentCommunicationPoint = %s: the plant is at tau = %s", a, b);
        return;
    default:
        break;
    }
    double et, ex, ev;
    int pending = take_pending(p, message, sizeof message, &et, &ex, &ev);
    if (pending == VK_TERMINAL || pending == VK_FAILED) { /* HertzEAOscillator.do_step's `stopped` */
        if (vk_outputs_at(p, et, ex, ev, NULL) == VK_OK && non_finite_output(p) < 0) publish(s);
        else take_pending(p, what, sizeof what, &et, &ex, &ev);
        native_halt(inst, "simulation stopped: %s", message);
        return;
    }
    native_repr(t, a, sizeof a);
    py_exception_repr(message, what, sizeof what);
    if (is_arithmetic(message))
        native_halt(inst, "simulation stopped: floating-point failure after tau = %s (%s); the parameters are beyond "
                    "the model's numerical range", a, what);
    else
        native_halt(inst, "doStep failed at tau = %s: %s", a, what);
}

/* HertzEAOscillator._initial_output: x = x_start, v = v_start, a and the forces of the fidelity's model at the start
   time with U = 0 (fidelities 3 and 4: Eq. 3, the exact model: the registry's compiled model of their forces),
   in_contact from x_start; the scene's rules and electrode gaps first (check_parameters on fidelity and the scene,
   then validate).  A level without a compiled model: its native refusal. */
int model_initial_output(const State *s, fmi2ValueReference vr, double *value, char *why, size_t size)
{
    static const char *const NAMES[] = {"fidelity", "mu", "Delta", "omega", "Omega", "alpha", "beta", "gamma", "R",
                                        "x_start", "v_start"}; /* scene_names() */
    char reason[256], text[64];
    if (native_rule_refusal(s, NAMES, sizeof NAMES / sizeof NAMES[0], why, size)) return 0;
    const double x = s->value[VR_x_start], v = s->value[VR_v_start], t = s->start_time;
    if (!vibro_gaps_check(x, s->value[VR_R], reason, sizeof reason)) {
        native_repr(x, text, sizeof text);
        snprintf(why, size, "parameter x_start = %s: %s", text, reason);
        return 0;
    }
    const int fidelity = (int)s->value[VR_fidelity];
    if (VK_FIDELITIES[fidelity].model == VK_MODEL_NONE) {
        snprintf(why, size, "parameter fidelity = %d: %s; %s", fidelity, VK_FIDELITIES[fidelity].native_refusal,
                 PYTHONFMU_ALTERNATIVE);
        return 0;
    }
    VkModel m;
    memset(&m, 0, sizeof m);
    native_plant_model(&m, s, fidelity);
    double out[5] = {x, v, 0.0, 0.0, 0.0};
    int fault = vm_forces(&m, t, x, &out[3], &out[4]);
    if (!fault) out[2] = vm_accel(&m, t, x, v, 0.0, &fault);
    if (fault) {
        char message[128];
        py_fault_text(fault, message, sizeof message);
        py_exception_repr(message, why, size);
        return 0;
    }
    if (vr == VR_in_contact) {
        *value = vm_contact_indentation(x) > 0.0;
        return 1;
    }
    for (int i = 0; i < 5; i++) {
        if (OUTPUT_VRS[i] != vr) continue;
        if (!isfinite(out[i])) {
            native_repr(out[i], text, sizeof text);
            snprintf(why, size, "output %s = %s is not finite; the parameters are beyond the model's numerical range",
                     OUTPUT_NAMES[i], text);
            return 0;
        }
        *value = out[i];
        return 1;
    }
    *value = s->value[vr];
    return 1;
}
