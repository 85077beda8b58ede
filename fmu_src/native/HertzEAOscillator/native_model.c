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
#include "me_model.h"
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

/* U is read by the next doStep (the plant holds it over the step); in Model Exchange the outputs follow it. */
void model_input_set(Instance *inst, State *s, fmi2ValueReference vr)
{
    (void)vr;
    if (s->model.me.mode != ME_OFF) model_me_outputs(inst, s);
}

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
    const int fidelity = (int)s->value[VR_fidelity];
    if (fidelity != RULE_AUTO_FIDELITY && VK_FIDELITIES[fidelity].oafm_settings) {
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
    s->model.me.locals_stale = 0;
}

/* After a doStep that left x'' and the forces to be computed when read (model_do_step): x, v and in_contact */
static void publish_state(State *s)
{
    const VkPlant *p = &s->model.plant;
    s->value[VR_x] = p->out[0];
    s->value[VR_v] = p->out[1];
    s->value[VR_in_contact] = p->in_contact != 0;
    s->model.me.locals_stale = 1;
}

/* x'' and the forces of the last doStep's point, when first read: vk_step_outputs, the bits vk_do_step gives them
   (model_do_step left them only where vk_outputs_bounded proved them finite; a forged state that breaks the proof
   reads NaN, which the getter refuses with fmi2Error) */
void model_lazy_outputs(State *s, fmi2ValueReference vr)
{
    if (!s->model.me.locals_stale || (vr != VR_a && vr != VR_F_contact && vr != VR_F_electrostatic)) return;
    if (!s->model.built || s->model.me.mode != ME_OFF) return;
    VkPlant *p = &s->model.plant;
    if (vk_outputs_bounded(p) && vk_step_outputs(p) == VK_OK) {
        publish(s);
        return;
    }
    for (int i = 2; i < 5; i++) s->value[OUTPUT_VRS[i]] = NAN;
    s->model.me.locals_stale = 0;
}

/* auto.choose over the candidates of rules.h (auto.candidates, cheapest first): the first the native FMU runs whose
   estimate (native_error_estimate, error_estimates' to the digit) is at most `tolerance`, its index, the log line of
   the choice in *line; -1 and the refusal's reason in *line when none meets it. */
static int auto_choose(const State *s, double tolerance, char *line, size_t size)
{
    char tried[2048] = "", item[160], rung[96];
    size_t used = 0;
    for (int i = 0; i < N_AUTO_CANDIDATES; i++) {
        const AutoCandidate *c = &AUTO_CANDIDATES[i];
        if (VK_FIDELITIES[c->fidelity].native_refusal) {
            snprintf(item, sizeof item, RULE_TEXT_AUTO_REFUSED, (double)c->fidelity, RULE_AUTO_NEEDS_PYTHON);
        } else {
            if (VK_FIDELITIES[c->fidelity].integrated)
                snprintf(rung, sizeof rung, RULE_TEXT_AUTO_EXACT_RUNG, (double)c->fidelity, c->rtol);
            else
                snprintf(rung, sizeof rung, RULE_TEXT_AUTO_RUNG, (double)c->fidelity);
            const double estimate = native_error_estimate(s, c->fidelity, c->rtol, !vk_solvers[c->solver]->reads_tolerance);
            if (isfinite(estimate) && estimate <= tolerance) {
                char skipped[sizeof tried + 16] = "";
                if (used) snprintf(skipped, sizeof skipped, RULE_TEXT_AUTO_SKIPPED, tried);
                snprintf(line, size, RULE_TEXT_AUTO_CHOSE, rung, c->cost, estimate, tolerance, skipped);
                return i;
            }
            snprintf(item, sizeof item, RULE_TEXT_AUTO_ESTIMATE, rung, estimate);
        }
        used += (size_t)snprintf(tried + used, sizeof tried - used, "%s%s", used ? "; " : "", item);
        if (used >= sizeof tried) used = sizeof tried - 1;
    }
    snprintf(line, size, RULE_TEXT_AUTO_NONE, tried);
    return -1;
}

void model_initialise(Instance *inst, State *s)
{
    double rtol_requested = s->has_tolerance ? s->tolerance : s->value[VR_rtol];
    if (!valid(inst, s)) return;
    int fidelity = (int)s->value[VR_fidelity], solver = (int)s->value[VR_solver];
    double max_step = s->value[VR_max_step];
    char choice[3072] = "";
    if (fidelity == RULE_AUTO_FIDELITY) { /* the choice's settings replace fidelity, solver, rtol and max_step */
        const int chosen = auto_choose(s, s->value[VR_tolerance], choice, sizeof choice);
        if (chosen < 0) {
            native_halt_parameter(inst, "tolerance", s->value[VR_tolerance], 0, choice);
            return;
        }
        fidelity = AUTO_CANDIDATES[chosen].fidelity;
        solver = AUTO_CANDIDATES[chosen].solver;
        rtol_requested = AUTO_CANDIDATES[chosen].rtol;
        max_step = 0.0;
    }
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
    native_plant_model(&p->model, s, fidelity); /* the level's model from the parameters (fidelity.h vouches) */
    const double factor = native_tolerance_factor(s); /* models.solver_tolerance */
    double solver_rtol = rtol * factor;
    if (solver_rtol < RULE_MIN_RTOL) solver_rtol = RULE_MIN_RTOL;
    p->dop.rtol = solver_rtol;
    p->dop.atol = solver_rtol * RULE_ATOL_PER_RTOL;
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
        if (choice[0]) native_log(inst, fmi2OK, "%s", choice); /* fidelity auto's choice first, as auto.auto_plant */
        native_log(inst, fmi2OK, "%s on the native FMU's compiled kernel (no Python)", vk_solvers[solver]->name);
        /* error_estimates.attach: the level's estimate, -1 (HertzEAOscillator.NO_ESTIMATE) when not finite */
        const double estimate = native_error_estimate(s, fidelity, rtol, !vk_solvers[solver]->reads_tolerance);
        s->value[VR_error_estimate] = isfinite(estimate) ? estimate : -1.0;
        s->value[VR_fidelity_chosen] = fidelity;
        native_log(inst, fmi2OK, "error estimate: max|x - x_exact| ~ %.3g over the run", estimate);
        if (factor != 1.0 && vk_solvers[solver]->reads_tolerance)
            native_log(inst, fmi2OK, RULE_TEXT_TOLERANCE_FACTOR, solver_rtol, rtol, factor, native_error_memory(s),
                       RULE_ERROR_MEMORY_REFERENCE);
        if (clamped) {
            char requested[64];
            native_repr(rtol_requested, requested, sizeof requested);
            native_log(inst, fmi2Warning, RULE_TEXT_RTOL_CLAMPED, requested, RULE_MIN_RTOL, RULE_MIN_RTOL);
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
            kernel_message_text(message, what, sizeof what);
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

static void step_failed(Instance *inst, State *s, int code, double t, double h);

void model_do_step(Instance *inst, State *s, double t, double h)
{
    VkPlant *p = &s->model.plant;
    const double U = s->value[VR_U];
    p->U_input = U;
    /* the step to x and v; x'' and the forces when read (model_lazy_outputs) where a bound proves them finite, so
       that the doStep's status is the one computing them now would give; else now (vk_do_step's bits either way) */
    int code = vk_do_step_state(p, t, h);
    if (code == VK_OK && vk_outputs_bounded(p)) {
        publish_state(s);
        return;
    }
    if (code == VK_OK) code = vk_step_outputs(p);
    if (code == VK_OK) {
        if (native_step_outputs_finite(inst, p->out, OUTPUT_VRS, 5, t)) publish(s);
        return;
    }
    step_failed(inst, s, code, t, h);
}

/* A doStep's failure (code) as the Python slave reports it */
static void step_failed(Instance *inst, State *s, int code, double t, double h)
{
    VkPlant *p = &s->model.plant;
    const double U = s->value[VR_U];
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
    kernel_message_text(message, what, sizeof what);
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
    static const char *const NAMES[] = {"fidelity", SCENE_NAMES}; /* rules.h: scene_names() */
    char reason[256], text[64];
    if (native_rule_refusal(s, NAMES, sizeof NAMES / sizeof NAMES[0], why, size)) return 0;
    const double x = s->value[VR_x_start], v = s->value[VR_v_start], t = s->start_time;
    if (!vibro_gaps_check(x, s->value[VR_R], reason, sizeof reason)) {
        native_repr(x, text, sizeof text);
        snprintf(why, size, "parameter x_start = %s: %s", text, reason);
        return 0;
    }
    int fidelity = (int)s->value[VR_fidelity];
    if (fidelity == RULE_AUTO_FIDELITY) fidelity = VK_FID_EXACT; /* every candidate's forces are Eq. 3's */
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
        kernel_message_text(message, why, size);
        return 0;
    }
    if (vr == VR_in_contact) {
        *value = vm_in_contact(x, v, out[2]);
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

/* ---- Model Exchange (me_model.h): states (x, v), derivatives (v, x''), the solvers' events as indicators ---- */

enum { CONTACT_EVENT = 0 }; /* vk_set_events' order: contact, upper gap, lower gap */

void model_me_start(Instance *inst, State *s)
{
    (void)inst;
    MeData *me = &s->model.me;
    me->t = s->model.plant.plant_t;
    me->x[0] = s->value[VR_x];
    me->x[1] = s->value[VR_v];
}

int model_me_derivatives(Instance *inst, State *s, double *dx)
{
    const MeData *me = &s->model.me;
    int fault;
    dx[0] = me->x[1];
    dx[1] = vm_accel(&s->model.plant.model, me->t, me->x[0], me->x[1], s->value[VR_U], &fault);
    if (!fault && isfinite(dx[1])) return 0;
    char text[128], tt[64], xt[64];
    if (fault) py_fault_text(fault, text, sizeof text);
    else snprintf(text, sizeof text, "x'' = %g is not finite", dx[1]);
    native_repr(me->t, tt, sizeof tt);
    native_repr(me->x[0], xt, sizeof xt);
    native_error(inst, "fmi2GetDerivatives: at tau = %s, x = %s: %s; the state is beyond the model's numerical "
                 "range", tt, xt, text);
    return 1;
}

/* contact 1 + 2x/3 (> 0 in contact), the upper and lower gaps' pull-in margins (<= 0: pull-in): the DOP853
   events g = c0 + c x of vk_set_events; the polynomial models (Eq. 7) have no pull-in events (none in
   co-simulation either): their margins are the constant 1 */
void model_me_indicators(const State *s, double *z)
{
    if (!s->model.built) { /* an unbuilt model's bytes mean nothing (a restored state's may be anything: its solver
                              dimension indexed past the events -- tests/fuzz seed fmi3_cs_unbuilt): a fresh one's */
        z[0] = vm_contact_indentation(0.0);
        z[1] = z[2] = 1.0;
        return;
    }
    const VkPlant *p = &s->model.plant;
    const double *y = s->model.me.mode != ME_OFF ? s->model.me.x : p->out;
    z[0] = vm_contact_indentation(y[0]);
    z[1] = z[2] = 1.0;
    for (int i = 1; i < p->dop.n_events && i < ME_N_INDICATORS; i++) z[i] = dop_event_g(&p->dop, i, y);
}

int model_me_outputs(Instance *inst, State *s)
{
    (void)inst;
    VkPlant *p = &s->model.plant;
    const MeData *me = &s->model.me;
    double fc, fe, a = NAN;
    int fault = vm_forces(&p->model, me->t, me->x[0], &fc, &fe);
    if (fault) fc = fe = NAN;
    else a = vm_accel(&p->model, me->t, me->x[0], me->x[1], s->value[VR_U], &fault);
    s->value[VR_x] = me->x[0];
    s->value[VR_v] = me->x[1];
    s->value[VR_a] = fault ? NAN : a; /* a getter refuses a non-finite value (fmi2Error naming it) */
    s->value[VR_F_contact] = fc;
    s->value[VR_F_electrostatic] = fe;
    return 0;
}

/* in_contact at an event.  Within CONTACT_BAND of the contact surface (where a located root lies, a rounding of
   the host's solver on either side) the direction of motion decides: moving in (x' > 0) closes the contact, moving
   out opens it, so a root located a rounding short still switches the flag; x' = 0 there is a graze (the indicator
   touches 0 without changing sign: a contact of zero length), which leaves the flag as it was -- unless the state
   is at rest there (x' = 0 too): then the sign of x'' decides.  Elsewhere the sign
   of 1 + 2x/3.  The flag changes only here (a discrete variable), so it cannot chatter in continuous-time mode. */
#define CONTACT_BAND 1e-8

int model_me_event(Instance *inst, State *s, int *terminate)
{
    const MeData *me = &s->model.me;
    const VkPlant *p = &s->model.plant;
    double z[ME_N_INDICATORS];
    model_me_indicators(s, z);
    int in_contact = s->value[VR_in_contact] != 0.0;
    if (fabs(z[CONTACT_EVENT]) > CONTACT_BAND) in_contact = z[CONTACT_EVENT] > 0.0;
    else if (me->x[1] != 0.0) in_contact = me->x[1] > 0.0;
    else { /* at rest on the surface (a start at x = -3/2, v = 0): the acceleration says which side it moves to; the
              indicator starts at 0 there, so no sign change would ever tell the host (0: a graze, as it was) */
        int fault = 0;
        const double a = vm_accel(&p->model, me->t, me->x[0], me->x[1], s->value[VR_U], &fault);
        if (!fault && a != 0.0 && isfinite(a)) in_contact = a > 0.0;
    }
    s->value[VR_in_contact] = in_contact;
    me_stop_at_pull_in(inst, &p->model, me, z, terminate);
    return 0;
}

/* ---- FMI 3.0 co-simulation with early return ---- */

/* plant.check_step's pre-checks (as vk_do_step makes them; nothing changes when one refuses) */
static int step_checks(VkPlant *p, double t, double h)
{
    if (!(isfinite(h) && h > 0.0)) return VK_BAD_STEP;
    if (!isfinite(p->U_input)) return VK_BAD_INPUT;
    const double ceiling = vk_step_ceiling(p);
    if (vk_too_many_steps(h, ceiling, p->max_steps_per_dostep)) return VK_TOO_MANY_STEPS;
    if (vk_time_refused(t, h, p->plant_t, p->time_tolerance, ceiling, p->max_steps_per_dostep)) return VK_BAD_TIME;
    return VK_OK;
}

/* DOP853 cuts its step at each zero of the contact event (dop853.h): a step that flips the contact side ends on
   the event, so stepping one solver step at a time (dop_advance to just beyond the solver's time takes exactly
   one step: its steps do not depend on the target) finds each event at the end of a step.  The steps are those of
   model_do_step, so without an event the result is model_do_step's, bit for bit; with one, the doStep ends at
   the event, and the next continues the same solver steps.  An event found by a step that ends beyond t + h stays
   pending (event_t) while the solver is still there and is returned by the doStep that reaches it. RK4 and the
   polynomial models (no contact events) step to t + h. */
void model_do_step_early(Instance *inst, State *s, double t, double h)
{
    VkPlant *p = &s->model.plant;
    MeData *me = &s->model.me;
    me->step_event = 0;
    if (p->solver != VK_DOP853 || p->dop.n_events == 0 || p->error) {
        model_do_step(inst, s, t, h);
        me->reached = p->plant_t;
        return;
    }
    p->U_input = s->value[VR_U];
    int code = step_checks(p, t, h);
    if (code) {
        step_failed(inst, s, code, t, h);
        me->reached = p->plant_t;
        return;
    }
    const double t_end = t + h;
    code = vk_set_input(p, p->plant_t, p->U_input);
    if (me->event_pending && p->dop.t != me->event_t) me->event_pending = 0; /* a restart dropped that step */
    /* the steps of the whole FMI 3.0 doStep so far (its internal doSteps, one per event: fmi3_native.c): the
       budget bounds the call, not each internal doStep */
    double *steps = native_call_steps(inst);
    while (!code && p->dop.t < t_end && !(me->event_pending && me->event_t <= t_end)) {
        if (*steps >= p->dop.step_budget) { /* the budget's error, as dop_advance words it; nothing more stepped */
            char a[64];
            native_repr(t, a, sizeof a);
            native_halt(inst, "doStep failed at tau = %s: %.0f steps reached only tau = %.10g of %.10g: make smaller "
                        "communication steps", a, *steps, p->dop.t, t_end);
            me->step_event = 0;
            me->reached = p->plant_t;
            return;
        }
        const int64_t side = p->dop.side[CONTACT_EVENT];
        code = vk_advance(p, nextafter(p->dop.t, INFINITY));
        *steps += 1.0;
        if (!code && p->dop.side[CONTACT_EVENT] != side) {
            me->event_pending = 1;
            me->event_t = p->dop.t;
        }
    }
    double reached = t_end, xva[3];
    if (!code && me->event_pending && me->event_t <= t_end) {
        reached = me->event_t;
        me->event_pending = 0;
        me->step_event = 1;
    }
    if (!code) code = vk_advance(p, reached); /* no step: a terminal event at or before `reached` */
    if (!code) {
        p->plant_t = reached;
        code = vk_plant_state(p, xva);
    }
    if (!code) code = vk_outputs_at(p, p->plant_t, xva[0], xva[1], &xva[2]);
    if (code) {
        me->step_event = 0;
        step_failed(inst, s, code, t, h);
        me->reached = p->plant_t;
        return;
    }
    me->reached = reached;
    int bad = non_finite_output(p);
    if (bad >= 0) {
        native_error(inst, "simulation stopped: output with valueReference %u is %g (not finite) after the step "
                     "from tau = %.17g; the parameters are beyond the model's numerical range",
                     (unsigned)OUTPUT_VRS[bad], p->out[bad], t);
        return;
    }
    publish(s);
}

/* ---- directional derivatives: the analytic partials (Eq. 3 and Eq. 7 differentiated by hand) ---- */

const char *const MODEL_PARTIALS = "provided: the derivatives of x, v, a, F_contact, F_electrostatic by x, v, U";

/* sum k c_k x^(k-1) of a series (5) */
static double horner_slope(const double *c, double x)
{
    double value = 0.0;
    for (int k = 5; k >= 1; k--) value = value * x + k * c[k];
    return value;
}

/* d/dx of F_contact and F_electrostatic (as vm_forces gives them) and of x'' at (t, x) */
static void force_slopes(const VkModel *m, double t, double x, double *contact, double *electrostatic, double *accel)
{
    int fault = 0;
    const double s = m->ac ? py_sin(m->Omega * t, &fault) : 0.0, c2 = m->ac ? vm_cos_double_angle(s) : 1.0;
    if (m->polynomial) { /* Eq. 7: F_contact G1, F_electrostatic alpha G2 + (beta s + gamma (1 - c2)) G3 */
        const double g3 = horner_slope(m->g3, x);
        *contact = horner_slope(m->g1, x);
        *electrostatic = m->alpha * horner_slope(m->g2, x) + (m->beta * s + m->gamma * (1.0 - c2)) * g3;
        *accel = -horner_slope(m->poly, x) + (m->ac ? (m->beta * s - m->gamma * c2) * g3 : 0.0);
        return;
    }
    /* Eq. 3: d/dx (1 + 2x/3)^(3/2) = (1 + 2x/3)^(1/2) in contact; the electrostatic force of u = 2x/(3R) */
    const double ind = vm_contact_indentation(x);
    *contact = ind > 0.0 ? sqrt(ind) : 0.0;
    const double du = 2.0 / (3.0 * m->R), u = du * x, lower = 1.0 - u, upper = 1.0 + u;
    const double f3_slope = 2.0 * du / (lower * lower * lower);
    *electrostatic = m->alpha * (f3_slope + 2.0 * du / (upper * upper * upper)) +
                     (m->ac ? (m->beta * s + m->gamma * (1.0 - c2)) * f3_slope : 0.0);
    *accel = -*contact + (m->electrostatics ? *electrostatic : 0.0);
}

int model_partial(const State *s, fmi2ValueReference unknown, fmi2ValueReference known, double *value)
{
    const VkPlant *p = &s->model.plant;
    const int me = s->model.me.mode != ME_OFF;
    const double t = me ? s->model.me.t : p->plant_t, x = me ? s->model.me.x[0] : p->out[0];
    if (known != VR_x && known != VR_v && known != VR_U) return 0;
    if (unknown == VR_x || unknown == VR_v) {
        *value = known == unknown ? 1.0 : 0.0;
        return 1;
    }
    if (unknown != VR_a && unknown != VR_F_contact && unknown != VR_F_electrostatic) return 0;
    if (known == VR_v || known == VR_U) { /* a = ... - mu v + U; the forces depend on x only */
        *value = unknown != VR_a ? 0.0 : known == VR_v ? -p->model.mu : 1.0;
        return 1;
    }
    double contact, electrostatic, accel;
    force_slopes(&p->model, t, x, &contact, &electrostatic, &accel);
    *value = unknown == VR_a ? accel : unknown == VR_F_contact ? contact : electrostatic;
    return 1;
}
