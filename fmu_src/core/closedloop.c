/*
 * closedloop.c -- the closed loop of closedloop.h: vibromodel/closedloop.py's ClosedLoop on the model of model.c,
 * the controller of controller.c, the reference of oafm_eval.c and the solver of the settings, called through the
 * solver interface (solver.h).
 */
#include "closedloop.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "plant.h"
#include "pyfloat.h"
#include "solver.h"

/* The reference x~ at t into ref[0..2] and, where the reference computes it too, the control regressor's
   cos(w_delta t) into *cos_delta (then returned non-NULL): when x~ is one piece from 0 with a frequency base equal
   to w_delta (the corrected reference: its forced response at omega), its cos(b (t - 0)) is the same angle. */
static const double *reference_at(const VlLoop *l, double t, double *ref, double *cos_delta)
{
    const OeSolution *S = &l->reference;
    if (S->n_pieces == 1 && S->pieces[0].start == 0.0) {
        const OePiece *P = &S->pieces[0];
        for (int64_t j = 0; j < P->n_freq_bases; j++) {
            if (P->freq_base[j] == l->controller.phi.w_delta) {
                vk_oafm_state_cos(S, t, ref, j, cos_delta);
                return cos_delta;
            }
        }
    }
    vk_oafm_state(S, t, ref);
    return NULL;
}

/* ClosedLoop._rates then ClosedLoop._accel at one stage: f = (v, x'', theta^'), U computed once for both;
   a fault (pyfloat.h) where Python raises. */
static int loop_rhs(void *context, double t, const double *y, double *f)
{
    const VlLoop *l = context;
    double ref[3], U, time[3], cos_delta;
    int fault = FAULT_NONE;
    const double *shared = reference_at(l, t, ref, &cos_delta);
    if (vk_controller_control_rates(&l->controller, t, y[0], y[1], ref, y + 2, &U, f + 2, time, shared))
        return FAULT_MATH_DOMAIN;  /* math.cos/sin of an infinity */
    /* the model's drive terms have the regressor's cos(omega t) and sin(Omega t) (the same products of the same
       frequencies and t): evaluated once; its cos 2 Omega t from sin Omega t, as the model computes it */
    VmDrive drive = {time[0], time[1], vm_cos_double_angle(time[1])};
    f[0] = y[1];
    f[1] = vm_accel_driven(&l->model, t, &drive, y[0], y[1], U, &fault);
    return fault;
}

/* The solver of the settings, the states it may use, the loop's right-hand side (no phasors: the controller's
   regressor shares the drive's time functions already) */

static inline VkSolverSlots slots_of(VlLoop *l)
{
    VkSolverSlots slots = {&l->dop, &l->rk4};
    return slots;
}

static const VkRhs LOOP_RHS = {loop_rhs, NULL, 0, NULL};
static inline const VkSolverOps *ops_of(const VlLoop *l) { return vk_solvers[l->solver]; }

int vk_loop_rhs(const VlLoop *l, double t, const double *y, double *f) { return loop_rhs((void *)l, t, y, f); }

int vk_loop_outputs_at(const VlLoop *l, double t, const double *y, double *out)
{
    const VcController *c = &l->controller;
    double ref[3], U, e1, e2, rates[VC_N], time[3], cos_delta;
    int fault = FAULT_NONE;
    const double *shared = reference_at(l, t, ref, &cos_delta);
    if (vk_controller_control_rates(c, t, y[0], y[1], ref, y + 2, &U, rates, time, shared)) return FAULT_MATH_DOMAIN;
    vk_controller_errors(c, y[0], y[1], ref, &e1, &e2);
    VmDrive drive = {time[0], time[1], vm_cos_double_angle(time[1])};  /* as in loop_rhs */
    double a = vm_accel_driven(&l->model, t, &drive, y[0], y[1], U, &fault);
    if (fault) return fault;
    out[0] = y[0];
    out[1] = y[1];
    out[2] = ref[0];
    out[3] = U;
    out[4] = e1;
    out[5] = e2;
    out[6] = vk_controller_lyapunov(c, e1, e2, y + 2);
    out[7] = vk_controller_lyapunov_rate(c, y[0], y[1], a, ref, y + 2, rates);
    out[8] = vk_controller_promised_rate(c, e1, e2);
    memcpy(out + 9, y + 2, VC_N * sizeof(double));
    return FAULT_NONE;
}

/* Leave error `code` pending at (t, x, v) with `text`; the fast path stops. */
static int set_error(VlLoop *l, int code, double t, const double *y, const char *text)
{
    snprintf(l->message, VL_MESSAGE, "%s", text);
    l->error = code;
    l->error_t = t;
    l->error_x = y[0];
    l->error_v = y[1];
    l->enabled = 0;
    return code;
}

static int solver_error(VlLoop *l, int code, const DopReport *r)
{
    char text[VL_MESSAGE];
    vk_solver_message(&l->model, code, r, text, sizeof text);
    return set_error(l, code, r->t, r->y, text);
}

static int raise_fault(VlLoop *l, int fault, double t, const double *y)
{
    char text[VL_MESSAGE];
    py_fault_text(fault, text, sizeof text);
    return set_error(l, VL_RAISED, t, y, text);
}

/* vk_loop_publish's part after the solver: the outputs at l->t from the state y there, written when all are finite.  One
   function whatever the solver (each publish_with calls it): the outputs are inlined into it once. */
static int publish_state(VlLoop *l, const double *y)
{
    double out[VL_OUTPUTS];
    int fault = vk_loop_outputs_at(l, l->t, y, out);
    if (fault) return raise_fault(l, fault, l->t, y);
    static const char *const names[VL_OUTPUTS] = {"x", "v", "x_ref", "U", "e1", "e2", "V", "V_rate",
        "V_rate_promised", "mu_hat", "a1_hat", "a2_hat", "a3_hat", "a4_hat", "a5_hat", "Delta_hat", "beta_hat",
        "gamma_hat"};  /* LOOP_OUTPUTS */
    for (int i = 0; i < VL_OUTPUTS; i++) {  /* StatusSlave._set_finite: NonFiniteOutput, the outputs kept */
        if (isfinite(out[i])) continue;
        char text[VL_MESSAGE];
        snprintf(text, sizeof text, "NonFiniteOutput: output %s = %s is not finite; the parameters are beyond the "
                 "model's numerical range", names[i], isnan(out[i]) ? "nan" : out[i] > 0 ? "inf" : "-inf");
        return set_error(l, VL_RAISED, l->t, y, text);
    }
    memcpy(l->out, out, sizeof out);
    return VL_OK;
}

/* vk_loop_publish on the given ops (always_inline: written once, instantiated per solver below; solver.h) */
static inline __attribute__((always_inline)) int publish_with(VlLoop *l, const VkSolverOps *ops)
{
    double y[DOP_MAX_DIM];
    DopReport r;
    int code = ops->value_at(slots_of(l), &LOOP_RHS, l, l->t, y, &r);  /* RK4 ends every advance on its target: t */
    if (code) return solver_error(l, code, &r);
    return publish_state(l, y);
}

int vk_loop_publish(VlLoop *l) { return publish_with(l, ops_of(l)); }

int vk_loop_init(VlLoop *l, double t0, const double *y0)
{
    DopReport r;
    l->dop.n = l->rk4.n = VL_DIM;
    vk_set_events(&l->dop.n_events, l->dop.events, &l->model);
    vk_set_events(&l->rk4.n_events, l->rk4.events, &l->model);
    l->dop.h = 0.0;
    l->t = t0;
    int code = ops_of(l)->restart(slots_of(l), &LOOP_RHS, l, t0, y0, &r);
    if (code) return solver_error(l, code, &r);
    return vk_loop_publish(l);
}

/* ClosedLoop.do_step on the given ops (always_inline), instantiated per solver of VK_SOLVER_LIST on its ops
   VK_OPS_<name> (a constant: every op resolved and inlined; solver.h): one indirect call per doStep, no branch on the
   solver */
static inline __attribute__((always_inline)) int do_step_with(VlLoop *l, const VkSolverOps *ops, double t, double h)
{
    DopReport r;
    if (l->error) return (int)l->error;
    if (!(isfinite(h) && h > 0.0)) return VL_BAD_STEP;
    const double ceiling = ops->max_step(slots_of(l));
    if (vk_too_many_steps(h, ceiling, VL_MAX_STEPS_PER_DOSTEP)) return VL_TOO_MANY_STEPS;
    if (vk_time_refused(t, h, l->t, l->time_tolerance, ceiling, VL_MAX_STEPS_PER_DOSTEP)) return VL_BAD_TIME;
    int code = ops->advance(slots_of(l), &LOOP_RHS, l, t + h, &r);
    if (code) return solver_error(l, code, &r);
    l->t = t + h;
    return publish_with(l, ops);
}

#define VK_DO_STEP_CONTAINER VlLoop
#define VK_DO_STEP_GENERIC do_step_with
VK_DO_STEP_TABLE(DO_STEP)

int vk_loop_do_step(VlLoop *l, double t, double h) { return DO_STEP[l->solver](l, t, h); }

void vk_loop_layout(size_t *sizes)
{
    sizes[0] = sizeof(VlLoop);
    sizes[1] = offsetof(VlLoop, dop);
    sizes[2] = offsetof(VlLoop, t);
    sizes[3] = offsetof(VlLoop, out);
    sizes[4] = offsetof(VlLoop, enabled);
    sizes[5] = offsetof(VlLoop, error);
    sizes[6] = offsetof(VlLoop, message);
    sizes[7] = offsetof(VlLoop, reference);
}
