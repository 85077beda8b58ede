/*
 * plant.h -- the plant FMU's step logic in C (fidelities 0, 1, 2 with DOP853 or RK4): the twin of
 * vibromodel/plant.py's Plant.do_step, operation for operation, so that both give the same bits.
 *
 * One VkPlant holds everything: the model's constants, the solver's state, the plant's time and input, the
 * outputs and a pending error.  It contains no pointers, so its bytes are the plant's FMU state.
 * vibromodel/core_layouts.py, generated from this header, gives ctypes the layout; vk_layout() checks it against
 * the compiled library at load time.  The library built from fmu_src/core (every .c file) is vibrokernel.so
 * (harness/vibrofmu/fmus/kernel.py).
 */
#ifndef VIBRO_PLANT_H
#define VIBRO_PLANT_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "dop853.h"
#include "model.h"
#include "rk4.h"

enum {
    VK_OK = 0,
    /* do_step pre-checks (nothing changed; vibromodel raises the matching ParameterError): */
    VK_BAD_STEP = 1,      /* communicationStepSize not finite or <= 0 */
    VK_BAD_INPUT = 2,     /* U not finite */
    VK_TOO_MANY_STEPS = 3,/* h / max_step > MAX_STEPS_PER_DOSTEP */
    VK_BAD_TIME = 4,      /* currentCommunicationPoint not the plant's time */
    /* integration (message, error_t/x/v set; the plant keeps the state it reached): */
    VK_TERMINAL = DOP_TERMINAL,  /* terminal event (pull-in): vibromodel.integrate.TerminalEvent */
    VK_FAILED = DOP_FAILED,      /* step collapse, step budget spent, non-finite state: IntegrationError */
    /* where the Python code raises a plain exception that nothing catches: message "<type>: <text>" */
    VK_RAISED = DOP_RAISED
};

#define VK_MESSAGE DOP_MESSAGE
enum { VK_DOP853 = 0, VK_RK4 = 1 };  /* plant.Solver */

/* VK_TOO_MANY_STEPS (and the closed loop's VL_TOO_MANY_STEPS): a doStep of h with steps of at most `ceiling` needs
   more than `budget` steps -- the count RK4 takes, ceil(h / ceiling * (1 - 1e-12)), is over the budget, so that a
   ratio equal to the budget but for rounding (0.1 / 1e-7 = 1000000.0000000001) is accepted
   (vibromodel.settings.too_many_steps, the same expression). */
static inline int vk_too_many_steps(double h, double ceiling, double budget)
{
    return h / ceiling * (1.0 - 1e-12) > budget;
}

/* VK_BAD_TIME (and VL_BAD_TIME): a host's communication point t not within `tolerance` relative of the time `at`
   the solver is at, or so far from it that the span the solver covers, at .. t + h, needs more than `budget` steps
   of `ceiling` (vibromodel.settings.check_step, the same expression) */
static inline int vk_time_refused(double t, double h, double at, double tolerance, double ceiling, double budget)
{
    return !(isfinite(t) && fabs(t - at) <= tolerance * (fabs(t) > 1.0 ? fabs(t) : 1.0)) ||
           vk_too_many_steps((t + h) - at, ceiling, budget);
}

typedef struct {
    /* ---- model and settings (set once by vibromodel.compiled) ---- */
    VkModel model;
    double time_tolerance, max_steps_per_dostep;
    int64_t solver;                     /* VK_DOP853 or VK_RK4 */
    /* ---- the solver in use (its configuration first, then its state) ---- */
    Dop853 dop;
    Rk4 rk4;
    double U;                           /* the input the solver holds (Dop853.U) */
    /* ---- plant ---- */
    double plant_t, U_input;            /* Plant.t; the input held over the next doStep */
    double out[5];                      /* x, v, a, F_contact, F_electrostatic */
    int64_t in_contact;                 /* 0/1 (an FMI Boolean reads it as int32: little-endian low word) */
    int64_t enabled;                    /* the FMU's C fast path may step this plant */
    /* ---- pending error (code != 0 until vibromodel reads it) ---- */
    int64_t error;
    double error_t, error_x, error_v;
    char message[VK_MESSAGE];
} VkPlant;

/* sizeof(VkPlant) and the offsets of its top-level fields in declaration order into offsets[0..n_fields-1];
   0 (and nothing written) when n_fields is not the number of fields. */
size_t vk_layout(size_t *offsets, size_t n_fields);
/* sizeof(Dop853), sizeof(Rk4), sizeof(VkModel) and offsetof(Dop853, t), offsetof(Rk4, t) into sizes[0..4] */
void vk_sizes(size_t *sizes);

/* Functions returning int give VK_OK or an error code. Integration errors (VK_TERMINAL, VK_FAILED, VK_RAISED)
   are also left pending in p->error (with message, error_t/x/v; enabled = 0) until vibromodel reads them;
   while one is pending, vk_plant_advance, vk_do_step and vk_run return it and change nothing. */

/* The model's events as the solvers take them (ExactModel.events: contact, upper gap, lower gap; none for Eq. 7);
   also the closed loop's (closedloop.c) */
void vk_set_events(int64_t *n_events, DopEvent *events, const VkModel *m);
/* The message of a solver's report: TerminalEvent(f"{name} at tau = {t:.10g}, x = {x:.10g}") for a stop, else the
   solver's own message; also the closed loop's */
void vk_solver_message(const VkModel *m, int code, const DopReport *r, char *buf, size_t size);

/* Configure both solvers from the model (n = 2, the model's events; the first DOP853 step not chosen) and
   restart at (t0, x0, v0) with U = 0.  The caller has set model, settings, solver, dop.rtol/atol/max_step/
   step_budget, rk4.max_step. */
int vk_init(VkPlant *p, double t0, double x0, double v0);
/* Solver restart at (t, x, v) with input U (Dop853._restart; RK4: the state is set). */
int vk_restart(VkPlant *p, double t, double x, double v, double U);
/* integrator.set_input: if U changed, restart at t from the dense output (RK4: U is taken). */
int vk_set_input(VkPlant *p, double t, double U);
/* integrator.advance(t_target). */
int vk_advance(VkPlant *p, double t_target);
/* integrator.value_at(t); VK_RAISED (ValueError) if t is outside the last step (RK4: t is not its time). */
int vk_value_at(VkPlant *p, double t, double *x, double *v);
/* the model's x'' (NaN where the Python model raises) */
double vk_accel(const VkPlant *p, double t, double x, double v, double U);
/* Plant.outputs_at(t, x, v, a): fills out[] and in_contact; a == NULL: the model's x'' at U_input. */
int vk_outputs_at(VkPlant *p, double t, double x, double v, const double *a);
/* Plant.state(): (x, x', x'') at plant_t into xva[0..2]. */
int vk_plant_state(VkPlant *p, double *xva);
/* Plant.advance(t_end, U_input): set_input at plant_t, advance, plant_t = t_end, state into xva[0..2]. */
int vk_plant_advance(VkPlant *p, double t_end, double *xva);
/* integrator.max_step of the solver in use: its step ceiling (inf: none) */
double vk_step_ceiling(VkPlant *p);
/* Plant.do_step(t, h, U_input): pre-checks, Plant.advance(t + h), outputs at t + h, plant_t = t + h. */
int vk_do_step(VkPlant *p, double t, double h);
/* vk_do_step without x'' and the forces: out[0], out[1] and in_contact at t + h; out[2..4] keep their old values
   until vk_step_outputs (a host that reads x alone skips them) */
int vk_do_step_state(VkPlant *p, double t, double h);
/* out[2..4] after vk_do_step_state: x'' at U_input and the forces at (plant_t, out[0], out[1]), vk_do_step's bits
   (and its error if the model raises there) */
int vk_step_outputs(VkPlant *p);
/* 1 when every output at (plant_t, out[0], out[1]) is finite and fault-free by a bound on the values (the exact
   model only; plant.c gives the proof), else 0: a host may then leave them to vk_step_outputs until read */
int vk_outputs_bounded(const VkPlant *p);
/* The compiled floor: n do_steps of dt, each from plant_t, x after each into x_out; stops at the first error. */
int vk_run(VkPlant *p, double dt, size_t n, double *x_out);
/* The Python API's runs (vibrofmu.api), outputs into columns: output j of point k goes to
   out[j * output_stride + k], j = 0..6: time, x, v, a, F_contact, F_electrostatic, in_contact (0/1).
   vk_run_from: n do_steps of dt from the host's times t0 + (k0 + k) dt, k = 0..n-1 (as a host computes them), the
   outputs after step k into point k; returns the points written (n unless an error stopped it: it is then left
   pending in p, or a pre-check's code is in *code). */
size_t vk_run_from(VkPlant *p, double t0, size_t k0, double dt, size_t n, double *out, size_t output_stride,
                   int *code);
/* vk_run_from with the time, x and v only (outputs 0..2; a, the forces, in_contact and out[] are not computed): the
   same steps and the same bits of x and v, without the model's x'' and forces at each point. */
size_t vk_run_xv(VkPlant *p, double t0, size_t k0, double dt, size_t n, double *out, size_t output_stride,
                 int *code);
/* m scenes one after another: plants[i] set as vibromodel.compiled sets a plant, vk_init at (t0, x0[i], v0[i]), its
   outputs there as point 0, then vk_run_from(t0, 0, dt, n) into points 1..n; scene i's rows start at
   out + i * (n + 1).  n_done[i]: the points written (n + 1 unless scene i stopped: its error is then pending in
   plants[i], or a pre-check's code in codes[i]); a scene's error does not stop the others.  all_outputs = 0: the
   time, x and v only (vk_run_xv; out holds 3 outputs). */
void vk_run_batch(VkPlant *plants, size_t m, double t0, const double *x0, const double *v0, double dt, size_t n,
                  double *out, size_t output_stride, int64_t *n_done, int64_t *codes, int64_t all_outputs);

#endif
