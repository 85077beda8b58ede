/*
 * closedloop.h -- plant + adaptive controller + reference as one system (vibromodel/closedloop.py), compiled.
 *
 * State y = (x, v, theta^[9]): x' = v, v' = the plant model's x'' (Eq. 3 or Eq. 7) with U the control law
 * (Eq. 78 corrected), theta^' = the update law (Eq. 81 corrected) -- both controller.c's; the reference x~ is the
 * OAFM closed form evaluated by oafm_eval.c at every stage. Per stage: reference, U and theta^', then x''.
 * do_step: pre-checks, the integrator to t + h, then the outputs at t + h: x, v, x~, U, e1, e2, V (Eq. 76),
 * V' by the chain rule, the V' the law promises (Eq. 85), theta^.
 *
 * Layout: the constants (model, controller, reference, settings) come first and are rebuilt from the FMU's
 * parameters; everything from `t` on is the state: those bytes are the closed-loop FMU's model state.
 */
#ifndef VIBRO_CLOSEDLOOP_H
#define VIBRO_CLOSEDLOOP_H

#include <stddef.h>
#include <stdint.h>

#include "controller.h"
#include "dop853.h"
#include "model.h"
#include "oafm_eval.h"
#include "rk4.h"

#define VL_DIM 11        /* x, v, theta^[9] */
#define VL_OUTPUTS 18    /* x, v, x_ref, U, e1, e2, V, V_rate, V_rate_promised, theta^[9] */
#define VL_MESSAGE DOP_MESSAGE

enum {
    VL_OK = 0,
    VL_BAD_STEP = 1,     /* communicationStepSize not finite or <= 0 (nothing changed) */
    VL_TOO_MANY_STEPS = 3,  /* h / max_step > VL_MAX_STEPS_PER_DOSTEP (nothing changed), as the plant's */
    VL_BAD_TIME = 4,     /* currentCommunicationPoint is not the loop's time (nothing changed) */
    VL_TERMINAL = DOP_TERMINAL,  /* terminal event (pull-in): TerminalEvent */
    VL_FAILED = DOP_FAILED,      /* the solver cannot continue: IntegrationError */
    VL_RAISED = DOP_RAISED       /* where the Python loop raises a plain exception: message "<type>: <text>" */
};
enum { VL_DOP853 = 0, VL_RK4 = 1 };  /* plant.Solver */
/* settings.MAX_STEPS_PER_DOSTEP: a doStep needing more steps of the solver's ceiling is refused up front (the
   closed loop with max_step = 1e-308 ran > 150 s in one doStep, issue 25); the adaptive solver's step budget too */
#define VL_MAX_STEPS_PER_DOSTEP 1000000.0

typedef struct {
    /* ---- constants, set once from the parameters by vibromodel.compiled_loop ---- */
    VkModel model;                   /* the plant model (fidelity 0, 1 or 2) */
    VcController controller;         /* the controller's constants (its own state fields unused) */
    int64_t solver;                  /* VL_DOP853 or VL_RK4 */
    double time_tolerance;
    /* ---- the solver in use (configured by vk_loop_init), the loop, the outputs: the FMU state's bytes ---- */
    Dop853 dop;
    Rk4 rk4;
    double t;                        /* ClosedLoop.t */
    double out[VL_OUTPUTS];          /* the outputs after the last step */
    int64_t enabled;                 /* the FMU's C fast path may step this loop */
    int64_t error;                   /* pending error (VL_TERMINAL, VL_FAILED, VL_RAISED) until vibromodel reads it */
    double error_t, error_x, error_v;
    char message[VL_MESSAGE];
    /* ---- the reference x~ (points into arrays the Python front end keeps): rebuilt, not state ---- */
    OeSolution reference;
} VlLoop;

/* sizeof(VlLoop), offsetof(VlLoop, dop), offsetof(VlLoop, t), offsetof(VlLoop, out), offsetof(VlLoop, enabled),
   offsetof(VlLoop, error), offsetof(VlLoop, message), offsetof(VlLoop, reference) into sizes[0..7]. */
void vk_loop_layout(size_t *sizes);
/* Configure the solver of `solver` (n = 11, the model's events; the caller has set dop.rtol/atol/max_step/
   step_budget or rk4.max_step) and start at t0 from y0 = (x, v, theta^); outputs at t0. 0 or a pending code. */
int vk_loop_init(VlLoop *l, double t0, const double *y0);
/* ClosedLoop.do_step(t, h): pre-checks (VL_BAD_STEP, VL_BAD_TIME: nothing changed), the solver to t + h, t = t + h,
   the outputs at t (written only when all are finite). Integration errors and faults stay pending in `error`
   (enabled = 0; the solver keeps the state it reached); while one is pending, vk_loop_do_step returns it. */
int vk_loop_do_step(VlLoop *l, double t, double h);
/* ClosedLoop.outputs: the state at t (dense output or RK4's state), its outputs into out[] when all are finite;
   0 or a pending code. */
int vk_loop_publish(VlLoop *l);
/* The loop's right-hand side f = (v, x'', theta^') at (t, y) (what the solvers integrate; the native FMU's Model
   Exchange derivatives): 0 or the fault Python raises. */
int vk_loop_rhs(const VlLoop *l, double t, const double *y, double *f);
/* ClosedLoop.outputs_at(t, x, v, theta^) into out[0..VL_OUTPUTS-1]: 0 or the fault Python raises (nothing pending). */
int vk_loop_outputs_at(const VlLoop *l, double t, const double *y, double *out);

#endif
