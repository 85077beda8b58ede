/*
 * plant.c -- the plant's step logic (plant.h): Plant.do_step, state and outputs of vibromodel/plant.py on the
 * model (model.c) and the solver of the settings, called through the solver interface (solver.h).
 */
#include "plant.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "pyfloat.h"
#include "solver.h"

enum { CONTACT = 0, UPPER_GAP = 1, LOWER_GAP = 2 };  /* ExactModel.events, in order */
enum { POLY_UPPER_GAP = 0, POLY_LOWER_GAP = 1 };      /* PolynomialModel.events: the pull-in events only */

/* Leave error `code` pending with (t, x, v) and the formatted message; the fast path stops. */
static int set_error(VkPlant *p, int code, double t, double x, double v, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(p->message, VK_MESSAGE, format, args);
    va_end(args);
    p->error = code;
    p->error_t = t;
    p->error_x = x;
    p->error_v = v;
    p->enabled = 0;
    return code;
}

void vk_solver_message(const VkModel *m, int code, const DopReport *r, char *buf, size_t size)
{
    if (code == DOP_TERMINAL) {
        number_text t_text, x_text, gap_text;
        int upper = r->event == (m->polynomial ? POLY_UPPER_GAP : UPPER_GAP);  /* models.pull_in_events' names */
        snprintf(buf, size, "pull-in: %s gap 1 %s 2x/(3R) below %s at tau = %s, x = %s", upper ? "upper" : "lower",
                 upper ? "-" : "+", g_number_text(gap_text, m->pull_in_gap, 6), g_number_text(t_text, r->t, 10),
                 g_number_text(x_text, r->y[0], 10));
        return;
    }
    snprintf(buf, size, "%s", r->message);
}

/* A solver's report as the pending error (vk_solver_message). */
static int solver_error(VkPlant *p, int code, const DopReport *r)
{
    char text[VK_MESSAGE];
    vk_solver_message(&p->model, code, r, text, sizeof text);
    return set_error(p, code, r->t, r->y[0], r->y[1], "%s", text);
}

/* The states the solvers may use */
static inline VkSolverSlots slots_of(VkPlant *p)
{
    VkSolverSlots slots = {&p->dop, &p->rk4};
    return slots;
}

/* The context the plant hands its solver for one call (restart, advance, value_at): the plant, and the drive's time
   functions at the last time its right-hand side saw, keyed by that time's bits. A DOP853 step evaluates the
   right-hand side twice at t + h (its last stage, and the first-same-as-last stage that starts the next step): the
   drive's sines and cosines -- most of a call's work -- are computed once for both, the same bits (vm_drive_at). */
typedef struct {
    const VkPlant *p;
    uint64_t t_bits;  /* the time of `drive` */
    int has_drive;    /* drive holds the time functions at t_bits (computed without a fault) */
    VmDrive drive;
} PlantCall;

static inline PlantCall plant_call(const VkPlant *p)
{
    PlantCall call;  /* t_bits and drive are read only once has_drive is set */
    call.p = p;
    call.has_drive = 0;
    return call;
}

static void plant_frequencies_of(void *context, double *freq);
static int plant_rhs(void *context, double t, const double *y, double *f);
static int plant_rhs_phased(void *context, double t, const double *phases, const double *y, double *f);
/* The plant's right-hand side for the solvers (context: a PlantCall): plain, and with the drive's phasors */
static const VkRhs PLANT_RHS = {plant_rhs, plant_rhs_phased, 3, plant_frequencies_of};

/* The solver of the settings */
static inline const VkSolverOps *ops_of(const VkPlant *p) { return vk_solvers[p->solver]; }

/* The exception a fault raises in Python, at the solver's state. */
static int raise_fault(VkPlant *p, int fault)
{
    char text[VK_MESSAGE];
    py_fault_text(fault, text, sizeof text);
    double t;
    const double *y = ops_of(p)->state(slots_of(p), &t);
    return set_error(p, VK_RAISED, t, y[0], y[1], "%s", text);
}

/* plant_rhs where the drive faults: vm_accel, which raises the fault it meets first, as without the cache (apart:
   noinline, off the common path) */
static __attribute__((noinline)) int plant_rhs_faulting(const VkPlant *p, double t, const double *y, double *f)
{
    int fault;
    f[0] = y[1];
    f[1] = vm_accel(&p->model, t, y[0], y[1], p->U, &fault);
    return fault;
}

/* The solvers' right-hand side: (x, v)' = (v, x'') at the held input U */
static int plant_rhs(void *context, double t, const double *y, double *f)
{
    PlantCall *call = context;
    const VkPlant *p = call->p;
    uint64_t bits;
    memcpy(&bits, &t, sizeof bits);
    if (!call->has_drive || bits != call->t_bits) {
        call->t_bits = bits;
        call->has_drive = vm_drive_at(&p->model, t, &call->drive);
        if (!call->has_drive) return plant_rhs_faulting(p, t, y, f);
    }
    int fault;
    f[0] = y[1];
    f[1] = vm_accel_driven(&p->model, t, &call->drive, y[0], y[1], p->U, &fault);
    return fault;
}

/* plant_rhs with the drive's phasors given: (cos, sin) of omega t, Omega t, 2 Omega t (plant_frequencies) */
static int plant_rhs_phased(void *context, double t, const double *phases, const double *y, double *f)
{
    const VkPlant *p = ((const PlantCall *)context)->p;
    const VmDrive drive = {phases[0], phases[3], phases[4]};
    int fault;
    f[0] = y[1];
    f[1] = vm_accel_driven(&p->model, t, &drive, y[0], y[1], p->U, &fault);
    return fault;
}


/* The drive's frequencies omega, Omega, 2 Omega (0 for a term the model leaves out: its phasor stays (1, 0)),
   as plant.drive_frequencies */
static void plant_frequencies(const VkModel *m, double *freq)
{
    freq[0] = m->load_forcing ? m->omega : 0.0;
    freq[1] = m->ac ? m->Omega : 0.0;
    freq[2] = m->ac ? 2.0 * m->Omega : 0.0;
}

static void plant_frequencies_of(void *context, double *freq)
{
    plant_frequencies(&((const PlantCall *)context)->p->model, freq);
}

double vk_accel(const VkPlant *p, double t, double x, double v, double U)
{
    int fault;
    double a = vm_accel(&p->model, t, x, v, U, &fault);
    return fault ? NAN : a;
}

/* The model's events as the solvers take them (ExactModel.events: contact, upper gap, lower gap;
   PolynomialModel.events: upper gap, lower gap -- the same pull-in rule, no contact kink in Eq. 7) */
void vk_set_events(int64_t *n_events, DopEvent *events, const VkModel *m)
{
    memset(events, 0, sizeof(DopEvent) * DOP_MAX_EVENTS);
    if (m->polynomial) {
        *n_events = 2;
        events[POLY_UPPER_GAP].c0 = 1.0 - m->pull_in_gap;
        events[POLY_UPPER_GAP].c[0] = -m->pull_in_c;
        events[POLY_UPPER_GAP].terminal = 1;
        events[POLY_LOWER_GAP].c0 = 1.0 - m->pull_in_gap;
        events[POLY_LOWER_GAP].c[0] = m->pull_in_c;
        events[POLY_LOWER_GAP].terminal = 1;
        return;
    }
    *n_events = 3;
    events[CONTACT].c0 = 1.0;  /* models.CONTACT_EVENT: 1 + (2/3) x */
    events[CONTACT].c[0] = 2.0 / 3.0;
    events[UPPER_GAP].c0 = 1.0 - m->pull_in_gap;  /* models.pull_in_events */
    events[UPPER_GAP].c[0] = -m->pull_in_c;
    events[UPPER_GAP].terminal = 1;
    events[LOWER_GAP].c0 = 1.0 - m->pull_in_gap;
    events[LOWER_GAP].c[0] = m->pull_in_c;
    events[LOWER_GAP].terminal = 1;
}

int vk_init(VkPlant *p, double t0, double x0, double v0)
{
    p->dop.n = p->rk4.n = 2;
    vk_set_events(&p->dop.n_events, p->dop.events, &p->model);
    vk_set_events(&p->rk4.n_events, p->rk4.events, &p->model);
    p->dop.h = 0.0;
    return vk_restart(p, t0, x0, v0, 0.0);
}

/* Plant.outputs_at */
int vk_outputs_at(VkPlant *p, double t, double x, double v, const double *a)
{
    double f_contact, f_electrostatic, a_model = 0.0;
    int fault = vm_forces(&p->model, t, x, &f_contact, &f_electrostatic);
    if (!fault && a == NULL) a_model = vm_accel(&p->model, t, x, v, p->U_input, &fault);
    if (fault) return raise_fault(p, fault);
    p->out[0] = x;
    p->out[1] = v;
    p->out[2] = a == NULL ? a_model : *a;
    p->out[3] = f_contact;
    p->out[4] = f_electrostatic;
    p->in_contact = vm_in_contact(x, v, p->out[2]);
    return VK_OK;
}

/* ---- the step, written once on a solver's ops ----
 * Each *_with function below takes the solver's ops as an argument and is inlined (always_inline) into its callers:
 * into the public vk_* functions with ops_of(p), the solver of the settings (an indirect call per operation), and
 * into one do-step per solver (DO_STEP, below) with that solver's ops (solver.h's VK_OPS_<name>), a constant there:
 * the compiler resolves and inlines every op, so a doStep costs one indirect call (DO_STEP[p->solver]) whatever
 * the solver.  No branch on the solver either way. */

static inline __attribute__((always_inline)) int restart_with(VkPlant *p, const VkSolverOps *ops, double t, double x,
                                                              double v, double U)
{
    double y[2] = {x, v};
    DopReport r;
    p->U = U;
    PlantCall call = plant_call(p);
    int code = ops->restart(slots_of(p), &PLANT_RHS, &call, t, y, &r);
    return code ? solver_error(p, code, &r) : VK_OK;
}

static inline __attribute__((always_inline)) int value_at_with(VkPlant *p, const VkSolverOps *ops, double t,
                                                               double *x, double *v)
{
    double y[DOP_MAX_DIM];
    DopReport r;
    PlantCall call = plant_call(p);
    int code = ops->value_at(slots_of(p), &PLANT_RHS, &call, t, y, &r);
    if (code) {  /* solver_error returns code: said here, so the compiler sees *x and *v written when 0 is returned */
        solver_error(p, code, &r);
        return code;
    }
    *x = y[0];
    *v = y[1];
    return VK_OK;
}

static inline __attribute__((always_inline)) int set_input_with(VkPlant *p, const VkSolverOps *ops, double t,
                                                                double U)
{
    double x, v;
    if (!ops->restart_on_input) {  /* Rk4.set_input */
        p->U = U;
        return VK_OK;
    }
    if (U == p->U) return VK_OK;  /* Dop853.set_input */
    int code = value_at_with(p, ops, t, &x, &v);
    if (code) return code;
    p->U = U;
    return restart_with(p, ops, t, x, v, U);
}

static inline __attribute__((always_inline)) int advance_with(VkPlant *p, const VkSolverOps *ops, double t_target)
{
    DopReport r;
    PlantCall call = plant_call(p);
    int code = ops->advance(slots_of(p), &PLANT_RHS, &call, t_target, &r);
    return code ? solver_error(p, code, &r) : VK_OK;
}

/* Plant.state */
static inline __attribute__((always_inline)) int plant_state_with(VkPlant *p, const VkSolverOps *ops, double *xva)
{
    int fault, code = value_at_with(p, ops, p->plant_t, &xva[0], &xva[1]);
    if (code) return code;
    xva[2] = vm_accel(&p->model, p->plant_t, xva[0], xva[1], p->U_input, &fault);
    return fault ? raise_fault(p, fault) : VK_OK;
}

/* Plant.advance(t_end, U_input) */
static inline __attribute__((always_inline)) int plant_advance_with(VkPlant *p, const VkSolverOps *ops, double t_end,
                                                                    double *xva)
{
    if (p->error) return (int)p->error;
    int code = set_input_with(p, ops, p->plant_t, p->U_input);  /* at the old time: U changes there */
    if (!code) code = advance_with(p, ops, t_end);
    if (code) return code;
    p->plant_t = t_end;
    return plant_state_with(p, ops, xva);
}

/* Plant.do_step's checks (plant.check_step), without messages: vibromodel raises the ParameterError */
static inline __attribute__((always_inline)) int check_step_with(VkPlant *p, const VkSolverOps *ops, double t,
                                                                 double h)
{
    double ceiling = ops->max_step(slots_of(p));
    if (!(isfinite(h) && h > 0.0)) return VK_BAD_STEP;
    if (!isfinite(p->U_input)) return VK_BAD_INPUT;
    if (vk_too_many_steps(h, ceiling, p->max_steps_per_dostep)) return VK_TOO_MANY_STEPS;
    if (vk_time_refused(t, h, p->plant_t, p->time_tolerance, ceiling, p->max_steps_per_dostep)) return VK_BAD_TIME;
    return VK_OK;
}

int vk_restart(VkPlant *p, double t, double x, double v, double U) { return restart_with(p, ops_of(p), t, x, v, U); }

int vk_value_at(VkPlant *p, double t, double *x, double *v) { return value_at_with(p, ops_of(p), t, x, v); }

int vk_set_input(VkPlant *p, double t, double U) { return set_input_with(p, ops_of(p), t, U); }

int vk_advance(VkPlant *p, double t_target) { return advance_with(p, ops_of(p), t_target); }

int vk_plant_state(VkPlant *p, double *xva) { return plant_state_with(p, ops_of(p), xva); }

int vk_plant_advance(VkPlant *p, double t_end, double *xva) { return plant_advance_with(p, ops_of(p), t_end, xva); }

double vk_step_ceiling(VkPlant *p)
{
    return ops_of(p)->max_step(slots_of(p));
}

/* Plant.do_step's steps (check_step_with, plant_advance_with) up to the state at t + h, without x'' and the
   outputs */
static inline __attribute__((always_inline)) int step_xv_with(VkPlant *p, const VkSolverOps *ops, double t, double h,
                                                              double *x, double *v)
{
    if (p->error) return (int)p->error;
    int code = check_step_with(p, ops, t, h);
    if (code) return code;
    code = set_input_with(p, ops, p->plant_t, p->U_input);  /* at the old time: U changes there */
    if (!code) code = advance_with(p, ops, t + h);
    if (code) return code;
    p->plant_t = t + h;
    return value_at_with(p, ops, p->plant_t, x, v);
}

/* The state after a do-step as out[0], out[1] and in_contact (x'' and the forces, out[2..4], not computed) */
static inline __attribute__((always_inline)) int step_state_with(VkPlant *p, const VkSolverOps *ops, double t,
                                                                 double h)
{
    double x = 0.0, v = 0.0;  /* written by step_xv_with when it returns VK_OK */
    int code = step_xv_with(p, ops, t, h, &x, &v);
    if (code) return code;
    p->out[0] = x;
    p->out[1] = v;
    /* vm_in_contact; x'' only where it decides: at rest exactly on the contact surface */
    int fault = 0;
    const int on_surface_at_rest = vm_contact_indentation(x) == 0.0 && v == 0.0;
    p->in_contact = vm_in_contact(x, v, on_surface_at_rest ? vm_accel(&p->model, p->plant_t, x, v, p->U_input, &fault)
                                                           : 0.0);
    return VK_OK;
}

/* Every output at the plant's time from (x, v) there: x'' at U_input and the forces in one pass (vm_outputs: the bits
   of Plant.state's x'' and of outputs_at's forces, x'' first); nothing written on a fault */
static inline __attribute__((always_inline)) int outputs_with(VkPlant *p, double x, double v)
{
    double a, f_contact, f_electrostatic;
    int fault = vm_outputs(&p->model, p->plant_t, x, v, p->U_input, &a, &f_contact, &f_electrostatic);
    if (fault) return raise_fault(p, fault);
    p->out[0] = x;
    p->out[1] = v;
    p->out[2] = a;
    p->out[3] = f_contact;
    p->out[4] = f_electrostatic;
    p->in_contact = vm_in_contact(x, v, a);
    return VK_OK;
}

int vk_step_outputs(VkPlant *p) { return outputs_with(p, p->out[0], p->out[1]); }

/* Plant.do_step(t, h, U_input): Plant.advance's steps, then every output at the new point t + h */
static inline __attribute__((always_inline)) int do_step_with(VkPlant *p, const VkSolverOps *ops, double t, double h)
{
    double x = 0.0, v = 0.0;  /* written by step_xv_with when it returns VK_OK */
    int code = step_xv_with(p, ops, t, h, &x, &v);
    return code ? code : outputs_with(p, x, v);
}

/* One do-step per solver of VK_SOLVER_LIST, on its ops VK_OPS_<name> (a constant: resolved and inlined), in the
   list's order */
typedef int (*PlantDoStep)(VkPlant *p, double t, double h);
#define VK_DO_STEP_CONTAINER VkPlant
#define VK_DO_STEP_GENERIC do_step_with
VK_DO_STEP_TABLE(DO_STEP)

int vk_do_step(VkPlant *p, double t, double h) { return DO_STEP[p->solver](p, t, h); }

/* the same per solver for the state alone (the native FMU's doStep when its outputs are read lazily) */
#undef VK_DO_STEP_GENERIC
#define VK_DO_STEP_GENERIC step_state_with
VK_DO_STEP_TABLE(STEP_STATE)

int vk_do_step_state(VkPlant *p, double t, double h) { return STEP_STATE[p->solver](p, t, h); }

/* Why these bounds make every output finite and fault-free (the exact model, Eq. 3; B = 1e100, all values finite):
   u = 2x/(3R) with |u| < B and |1 -+ u| > 1e-50 gives (1 -+ u)^2 in (1e-100, 1e200], so both divisions of
   electrostatic() are by a nonzero number and F3, F2's terms lie in [5e-201, 1e100); the drive's arguments
   omega t, Omega t, 2 Omega t are below 2e200 (finite: cos and sin have no domain error); then |F_electrostatic| <=
   |alpha| 2e100 + (|beta| + 2 |gamma|) 1e100 < 1e201, H = s sqrt(s) with |s| = |1 + 2x/3| < 1e100 is below 1e150,
   and x'' = 1 + U - mu v - H + Delta cos(omega t) + F_electrostatic is a sum of six terms each below 1e201. */
int vk_outputs_bounded(const VkPlant *p)
{
    const VkModel *m = &p->model;
    const double B = 1e100;
    if (m->polynomial) return 0;
    const double constants[] = {m->mu, m->Delta, m->omega, m->Omega, m->alpha, m->beta, m->gamma, m->R};
    for (size_t i = 0; i < sizeof constants / sizeof constants[0]; i++)
        if (!(fabs(constants[i]) < B)) return 0;
    const double x = p->out[0], u = 2.0 * x / (3.0 * m->R);  /* electrostatic()'s u */
    return fabs(x) < B && fabs(p->out[1]) < B && fabs(p->plant_t) < B && fabs(p->U_input) < B && fabs(u) < B &&
           fabs(1.0 - u) > 1e-50 && fabs(1.0 + u) > 1e-50;
}

int vk_run(VkPlant *p, double dt, size_t n, double *x_out)
{
    PlantDoStep do_step = DO_STEP[p->solver];
    for (size_t i = 0; i < n; i++) {
        int code = do_step(p, p->plant_t, dt);
        if (code) return code;
        x_out[i] = p->out[0];
    }
    return VK_OK;
}

/* The outputs of point k (time, out[0..4], in_contact) into its columns (vk_run_from) */
static inline void put_outputs(const VkPlant *p, double *out, size_t output_stride, size_t k)
{
    out[k] = p->plant_t;
    for (size_t j = 0; j < 5; j++) out[(j + 1) * output_stride + k] = p->out[j];
    out[6 * output_stride + k] = (double)p->in_contact;
}

size_t vk_run_from(VkPlant *p, double t0, size_t k0, double dt, size_t n, double *out, size_t output_stride,
                   int *code)
{
    PlantDoStep do_step = DO_STEP[p->solver];
    *code = VK_OK;
    for (size_t k = 0; k < n; k++) {
        *code = do_step(p, t0 + (double)(k0 + k) * dt, dt);
        if (*code) return k;
        put_outputs(p, out, output_stride, k);
    }
    return n;
}

size_t vk_run_xv(VkPlant *p, double t0, size_t k0, double dt, size_t n, double *out, size_t output_stride,
                 int *code)
{
    const VkSolverOps *ops = ops_of(p);
    *code = VK_OK;
    for (size_t k = 0; k < n; k++) {
        double x = 0.0, v = 0.0;  /* written by step_xv_with when it returns VK_OK */
        *code = step_xv_with(p, ops, t0 + (double)(k0 + k) * dt, dt, &x, &v);
        if (*code) return k;
        out[k] = p->plant_t;
        out[output_stride + k] = x;
        out[2 * output_stride + k] = v;
    }
    return n;
}

void vk_run_batch(VkPlant *plants, size_t m, double t0, const double *x0, const double *v0, double dt, size_t n,
                  double *out, size_t output_stride, int64_t *n_done, int64_t *codes, int64_t all_outputs)
{
    for (size_t i = 0; i < m; i++) {
        VkPlant *p = &plants[i];
        double *rows = out + i * (n + 1), xva[3];
        int code = vk_init(p, t0, x0[i], v0[i]);
        if (!code) code = vk_plant_state(p, xva);
        if (!code) code = vk_outputs_at(p, p->plant_t, xva[0], xva[1], &xva[2]);
        n_done[i] = 0;
        if (!code && all_outputs) {
            put_outputs(p, rows, output_stride, 0);
            n_done[i] = 1 + (int64_t)vk_run_from(p, t0, 0, dt, n, rows + 1, output_stride, &code);
        } else if (!code) {
            rows[0] = p->plant_t;
            rows[output_stride] = xva[0];
            rows[2 * output_stride] = xva[1];
            n_done[i] = 1 + (int64_t)vk_run_xv(p, t0, 0, dt, n, rows + 1, output_stride, &code);
        }
        codes[i] = code;
    }
}

#define FIELD(name) offsetof(VkPlant, name)
size_t vk_layout(size_t *offsets, size_t n_fields)
{
    static const size_t fields[] = {
        FIELD(model), FIELD(time_tolerance), FIELD(max_steps_per_dostep), FIELD(solver), FIELD(dop), FIELD(rk4),
        FIELD(U), FIELD(plant_t), FIELD(U_input), FIELD(out), FIELD(in_contact), FIELD(enabled),
        FIELD(error), FIELD(error_t), FIELD(error_x), FIELD(error_v), FIELD(message),
    };
    size_t n = sizeof fields / sizeof fields[0];
    if (n_fields != n) return 0;
    memcpy(offsets, fields, sizeof fields);
    return sizeof(VkPlant);
}
#undef FIELD

void vk_sizes(size_t *sizes)
{
    sizes[0] = sizeof(Dop853);
    sizes[1] = sizeof(Rk4);
    sizes[2] = sizeof(VkModel);
    sizes[3] = offsetof(Dop853, t);
    sizes[4] = offsetof(Rk4, t);
}
