/*
 * model.c -- the native closed-loop FMU: HertzEAClosedLoop.py's slave logic (closedloop.ClosedLoop's set-up,
 * compiled_loop.CompiledClosedLoop, StatusSlave) on the compiled closed loop fmu_src/core/closedloop.c, with the
 * same checks, in the same order, and the same messages (rules.h, generated from vibromodel at build time).
 *
 * The reference x~ needs set-up code that only Python has (vibromodel.tracking.make_reference and
 * compiled_open_loop.OafmProgram).  The build runs it for the FMU's default parameters and packs the result as
 * constant tables (reference.h), each with the values of every parameter it depends on; a run whose parameters
 * differ from every packed reference is refused with fmi2Error naming the parameter and the pythonfmu FMU.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "controller_setup.h"
#include "fidelity.h"
#include "fmi2_native.h"
#include "me_model.h"
#include "plant.h"
#include "plant_setup.h"
#include "pyfloat.h"
#include "pytext.h"
#include "reference.h"
#include "rules.h"
#include "scene_checks.h"

#define PYTHONFMU_ALTERNATIVE "use the pythonfmu FMU HertzEAClosedLoop.fmu (build/HertzEAClosedLoop.fmu), which sets it up in Python"

static const fmi2ValueReference OUTPUT_VRS[VL_OUTPUTS] = {
    VR_x, VR_v, VR_x_ref, VR_U, VR_e1, VR_e2, VR_V, VR_V_rate, VR_V_rate_promised, VR_mu_hat, VR_a1_hat,
    VR_a2_hat, VR_a3_hat, VR_a4_hat, VR_a5_hat, VR_Delta_hat, VR_beta_hat, VR_gamma_hat};
static const fmi2ValueReference ESTIMATE_START_VRS[VC_N] = {
    VR_mu_hat_start, VR_a1_hat_start, VR_a2_hat_start, VR_a3_hat_start, VR_a4_hat_start, VR_a5_hat_start,
    VR_Delta_hat_start, VR_beta_hat_start, VR_gamma_hat_start};

void model_instantiate(State *s) { memset(&s->model, 0, sizeof s->model); }

void model_input_set(Instance *inst, State *s, fmi2ValueReference vr) { (void)inst; (void)s; (void)vr; }


/* The loop's reference from the packed table (its pointers are this library's constants). */
static void point_reference(State *s)
{
    const PackedReference *r = &PACKED_REFERENCES[s->model.reference];
    s->model.loop.reference.n_pieces = r->n_pieces;
    s->model.loop.reference.pieces = r->pieces;
}

/* The packed reference's fastest frequency (OafmProgram's largest frequency base: for the packed kinds, ERRATA and
   MULTITONE, the largest frequency of its terms, as ClosedLoop's reference.fastest_frequency()) */
static double reference_frequency(int reference)
{
    const PackedReference *r = &PACKED_REFERENCES[reference];
    double fastest = 0.0;
    for (int64_t i = 0; i < r->n_pieces; i++)
        for (int64_t j = 0; j < r->pieces[i].n_freq_bases; j++)
            if (fabs(r->pieces[i].freq_base[j]) > fastest) fastest = fabs(r->pieces[i].freq_base[j]);
    return fastest;
}

/* The packed reference of the current parameters (its index), or -1 after refusing with the parameter that
   differs from the packed reference of the same kind (or `reference` when its kind is not packed). */
static int find_reference(Instance *inst, const State *s)
{
    const PackedReference *same_kind = NULL;
    for (int i = 0; i < N_PACKED_REFERENCES; i++) {
        const PackedReference *r = &PACKED_REFERENCES[i];
        if (s->value[VR_reference] != r->kind) continue;
        same_kind = r;
        int match = s->start_time == r->start_time;
        for (int j = 0; j < r->n_depends && match; j++) match = s->value[r->depends[j]] == r->values[j];
        if (match) return i;
    }
    char reason[512];
    if (same_kind == NULL) {
        snprintf(reason, sizeof reason, "the native FMU carries no set-up of this reference (it needs Python); %s",
                 PYTHONFMU_ALTERNATIVE);
        native_halt_parameter(inst, "reference", s->value[VR_reference], 1, reason);
        return -1;
    }
    char packed[64];
    if (s->start_time != same_kind->start_time) {
        native_repr(same_kind->start_time, packed, sizeof packed);
        snprintf(reason, sizeof reason, "the native FMU carries the reference set up for start time %s only (another "
                 "needs Python); %s", packed, PYTHONFMU_ALTERNATIVE);
        native_halt_parameter(inst, "startTime", s->start_time, 0, reason);
        return -1;
    }
    for (int j = 0; j < same_kind->n_depends; j++) {
        const fmi2ValueReference vr = same_kind->depends[j];
        if (s->value[vr] == same_kind->values[j]) continue;
        native_repr(same_kind->values[j], packed, sizeof packed);
        snprintf(reason, sizeof reason, "the native FMU carries the reference set up for %s = %s only (another value "
                 "needs Python); %s", VARIABLES[vr].name, packed, PYTHONFMU_ALTERNATIVE);
        native_halt_parameter(inst, VARIABLES[vr].name, s->value[vr], VARIABLES[vr].type != T_REAL, reason);
        return -1;
    }
    return -1;
}

/* The Model Exchange derivative variables der(v), der(theta^_i) (with_derivative_variables, native.py) */
static const fmi2ValueReference DERIVATIVE_VRS[VL_DIM - 1] = {
    VR_der_v_, VR_der_mu_hat_, VR_der_a1_hat_, VR_der_a2_hat_, VR_der_a3_hat_, VR_der_a4_hat_, VR_der_a5_hat_,
    VR_der_Delta_hat_, VR_der_beta_hat_, VR_der_gamma_hat_};

/* The state y = (x, v, theta^) behind the outputs */
static void state_of_outputs(const VlLoop *l, double *y)
{
    y[0] = l->out[0];
    y[1] = l->out[1];
    memcpy(y + 2, l->out + 9, VC_N * sizeof(double));
}

/* der(v), der(theta^_i) at (t, y) into value[] (NaN where the right-hand side faults: a getter refuses it) */
static void publish_derivatives(State *s, double t, const double *y)
{
    double f[VL_DIM];
    int fault = vk_loop_rhs(&s->model.loop, t, y, f);
    for (int i = 1; i < VL_DIM; i++) s->value[DERIVATIVE_VRS[i - 1]] = fault ? NAN : f[i];
}

static void publish(State *s)
{
    for (int i = 0; i < VL_OUTPUTS; i++) s->value[OUTPUT_VRS[i]] = s->model.loop.out[i];
    s->model.me.locals_stale = 1; /* der(...) when read: model_lazy_locals */
}

/* der(v), der(theta^_i) at the current point (co-simulation: the last communication point; Model Exchange: the
   states and time set), computed when a local is read after the point changed */
void model_lazy_locals(State *s)
{
    if (!s->model.me.locals_stale || !s->model.built) return;
    double y[VL_DIM];
    const int me = s->model.me.mode != ME_OFF;
    if (me) memcpy(y, s->model.me.x, sizeof y);
    else state_of_outputs(&s->model.loop, y);
    point_reference(s);
    publish_derivatives(s, me ? s->model.me.t : s->model.loop.t, y);
    s->model.me.locals_stale = 0;
}

/* The pending error as the Python slave reports it (CompiledClosedLoop._raise_pending, StatusSlave). */
static void report_pending(Instance *inst, State *s, const char *what_failed, const char *t_failed)
{
    VlLoop *l = &s->model.loop;
    char message[VL_MESSAGE + 64], what[VL_MESSAGE + 64];
    const int code = (int)l->error;
    snprintf(message, sizeof message, "%s", l->message);
    l->error = 0;
    l->error_t = l->error_x = l->error_v = 0.0;
    memset(l->message, 0, sizeof l->message);
    if (code == VL_TERMINAL || code == VL_FAILED) {
        native_halt(inst, "simulation stopped: %s", message);
        return;
    }
    kernel_message_text(message, what, sizeof what);
    if (t_failed != NULL && (strncmp(message, "ZeroDivisionError:", 18) == 0 ||
                             strncmp(message, "OverflowError:", 14) == 0 || strncmp(message, "NonFiniteOutput:", 16) == 0))
        /* StatusSlave._guarded_step: an ArithmeticError */
        native_halt(inst, "simulation stopped: floating-point failure after tau = %s (%s); the parameters are beyond "
                    "the model's numerical range", t_failed, what);
    else
        native_halt(inst, "%s: %s", what_failed, what);
}

void model_initialise(Instance *inst, State *s)
{
    const double rtol_requested = s->has_tolerance ? s->tolerance : s->value[VR_rtol];
    char reason[256];
    /* ClosedLoop.__init__: validate(scene) (the table, then the electrode gaps), checked_settings, loop.validate
       (the table), the plant's fidelity, the model, the controller, the reference, the integrator */
    if (!vibro_gaps_check(s->value[VR_x_start], s->value[VR_R], reason, sizeof reason)) {
        native_halt_parameter(inst, "x_start", s->value[VR_x_start], 0, reason);
        return;
    }
    const int fidelity = (int)s->value[VR_fidelity], solver = (int)s->value[VR_solver];
    double rtol = rtol_requested;
    const int clamped = rtol < RULE_MIN_RTOL; /* parameters.clamp_tolerance */
    if (clamped) rtol = RULE_MIN_RTOL;
    VlLoop *l = &s->model.loop;
    memset(l, 0, sizeof *l);
    const double max_step = s->value[VR_max_step];
    if (clamped) {
        char requested[64];
        native_repr(rtol_requested, requested, sizeof requested);
        native_log(inst, fmi2Warning, "parameter rtol = %s is below %.3g (100 machine epsilons: the error "
                   "control would see only rounding): using rtol = %.3g", requested, RULE_MIN_RTOL, RULE_MIN_RTOL);
    }
    native_drive_warnings(inst, s, vk_solvers[solver], max_step != 0.0 ? max_step : RULE_RK4_DEFAULT_STEP);
    if (fidelity < 0 || !VK_FIDELITIES[fidelity].integrated) { /* the registry's levels (fidelity.h); -1: auto, the plant FMU's */
        native_halt_parameter(inst, "fidelity", fidelity, 1, VK_FIDELITY_CLOSED_LOOP_REFUSAL);
        return;
    }
    if (VK_FIDELITIES[fidelity].native_refusal) {
        snprintf(reason, sizeof reason, "%s; %s", VK_FIDELITIES[fidelity].native_refusal, PYTHONFMU_ALTERNATIVE);
        native_halt_parameter(inst, "fidelity", fidelity, 1, reason);
        return;
    }
    const int reference = find_reference(inst, s);
    if (reference < 0) return;
    native_plant_model(&l->model, s, fidelity);
    native_controller_constants(&l->controller, s);
    l->solver = solver;
    l->time_tolerance = RULE_TIME_TOLERANCE;
    l->dop.rtol = rtol;
    l->dop.atol = rtol * RULE_ATOL_PER_RTOL;
    l->dop.max_step = max_step != 0.0 ? max_step : native_drive_ceiling(s, reference_frequency(reference));
    l->dop.step_budget = RULE_MAX_STEPS_PER_DOSTEP;  /* as the plant (issue 25: the loop had no guard) */
    l->rk4.max_step = max_step != 0.0 ? max_step : RULE_RK4_DEFAULT_STEP;
    l->enabled = 1;
    s->model.reference = reference;
    point_reference(s);
    s->model.built = 1;
    double y0[VL_DIM] = {s->value[VR_x_start], s->value[VR_v_start]};
    for (int i = 0; i < VC_N; i++) y0[2 + i] = s->value[ESTIMATE_START_VRS[i]];
    native_log(inst, fmi2OK, "%s; compiled closed loop on the native FMU (no Python)", PACKED_REFERENCES[reference].note);
    if (vk_loop_init(l, s->start_time, y0) != VL_OK) {
        report_pending(inst, s, "initialisation failed", NULL);
        return;
    }
    for (int i = 0; i < VL_OUTPUTS; i++)
        if (!isfinite(l->out[i])) {
            char value[64];
            native_repr(l->out[i], value, sizeof value);
            native_halt(inst, "initialisation failed: NonFiniteOutput('output %s = %s is not finite; the parameters "
                        "are beyond the model's numerical range')", VARIABLES[OUTPUT_VRS[i]].name, value);
            return;
        }
    publish(s);
}

void model_do_step(Instance *inst, State *s, double t, double h)
{
    VlLoop *l = &s->model.loop;
    point_reference(s);
    char a[64], b[64];
    const int code = vk_loop_do_step(l, t, h);
    if (code == VL_OK) {
        if (native_step_outputs_finite(inst, l->out, OUTPUT_VRS, VL_OUTPUTS, t)) publish(s);
        return;
    }
    if (code == VL_BAD_STEP) {
        native_repr(h, a, sizeof a);
        native_error(inst, "doStep refused: parameter communicationStepSize = %s: %s", a, RULE_STEP_SIZE);
        return;
    }
    if (code == VL_TOO_MANY_STEPS) {  /* the plant's words (HertzEAOscillator/native_model.c) */
        native_repr(h, a, sizeof a);
        native_error(inst, "doStep refused: parameter communicationStepSize = %s: needs more than %.0f steps of %g "
                     "(max_step); make smaller communication steps or raise max_step", a,
                     RULE_MAX_STEPS_PER_DOSTEP, l->solver == VL_RK4 ? l->rk4.max_step : l->dop.max_step);
        return;
    }
    if (code == VL_BAD_TIME) {
        native_repr(t, a, sizeof a);
        native_repr(l->t, b, sizeof b);
        native_error(inst, "doStep refused: parameter currentCommunicationPoint = %s: the closed loop is at tau = %s",
                     a, b);
        return;
    }
    native_repr(t, a, sizeof a);
    char what[96];
    snprintf(what, sizeof what, "doStep failed at tau = %s", a);
    report_pending(inst, s, what, a);
}

/* Outputs in Initialization Mode: their start values (StatusSlave._initial_output). */
int model_initial_output(const State *s, fmi2ValueReference vr, double *value, char *why, size_t size)
{
    (void)why; (void)size;
    *value = s->value[vr];
    return 1;
}

/* ---- Model Exchange (me_model.h): states (x, v, theta^), derivatives vk_loop_rhs, the solvers' events as indicators ---- */

void model_me_start(Instance *inst, State *s)
{
    (void)inst;
    MeData *me = &s->model.me;
    me->t = s->model.loop.t;
    state_of_outputs(&s->model.loop, me->x);
}

int model_me_derivatives(Instance *inst, State *s, double *dx)
{
    const MeData *me = &s->model.me;
    point_reference(s);
    int fault = vk_loop_rhs(&s->model.loop, me->t, me->x, dx);
    for (int i = 0; !fault && i < VL_DIM; i++)
        if (!isfinite(dx[i])) fault = FAULT_OVERFLOW;
    if (!fault) return 0;
    char text[128], tt[64], xt[64];
    py_fault_text(fault, text, sizeof text);
    native_repr(me->t, tt, sizeof tt);
    native_repr(me->x[0], xt, sizeof xt);
    native_error(inst, "fmi2GetDerivatives: at tau = %s, x = %s: %s; the state is beyond the model's numerical "
                 "range", tt, xt, text);
    return 1;
}

void model_me_indicators(const State *s, double *z)
{
    if (!s->model.built) { /* as the plant's: an unbuilt model's bytes mean nothing, a fresh one's indicators */
        z[0] = vm_contact_indentation(0.0);
        z[1] = z[2] = 1.0;
        return;
    }
    const VlLoop *l = &s->model.loop;
    double y[VL_DIM];
    if (s->model.me.mode != ME_OFF) memcpy(y, s->model.me.x, sizeof y);
    else state_of_outputs(l, y);
    z[0] = vm_contact_indentation(y[0]);
    z[1] = z[2] = 1.0; /* the polynomial models have no pull-in events (none in co-simulation either) */
    for (int i = 1; i < l->dop.n_events && i < ME_N_INDICATORS; i++) z[i] = dop_event_g(&l->dop, i, y);
}

int model_me_outputs(Instance *inst, State *s)
{
    (void)inst;
    VlLoop *l = &s->model.loop;
    const MeData *me = &s->model.me;
    double out[VL_OUTPUTS];
    point_reference(s);
    if (vk_loop_outputs_at(l, me->t, me->x, out) != 0)
        for (int i = 0; i < VL_OUTPUTS; i++) out[i] = NAN; /* a getter refuses them (fmi2Error naming one) */
    for (int i = 0; i < VL_OUTPUTS; i++) s->value[OUTPUT_VRS[i]] = out[i];
    s->model.me.locals_stale = 1; /* der(...) when read: model_lazy_locals */
    return 0;
}

/* The contact changes are events for the host's solver only (the force has a kink there; nothing discrete
   changes); pull-in stops the simulation (terminateSimulation, logged as the co-simulation's message). */
int model_me_event(Instance *inst, State *s, int *terminate)
{
    const MeData *me = &s->model.me;
    double z[ME_N_INDICATORS];
    model_me_indicators(s, z);
    me_stop_at_pull_in(inst, &s->model.loop.model, me, z, terminate);
    return 0;
}
