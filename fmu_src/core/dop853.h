/*
 * dop853.h -- adaptive DOP853 (Hairer, Norsett, Wanner; scipy's coefficients) with 7th-order dense output and
 * event location, on a state y[0..n-1] of at most DOP_MAX_DIM components.
 *
 * The C twin of vibromodel/integrate.py's Dop853: the same operations in the same order, so that the two give
 * the same bits (component order: y[0] = x, y[1] = v, y[2..] = the extra states that integrate.py carries in
 * its U slot with `rates`).  All sums are plain left-to-right loops.
 *
 * The solver's whole state is the pointer-free struct Dop853, so its bytes can be an FMU state.  The right-hand
 * side is passed to each call as a function pointer and a context; so is nothing else.
 *
 * Events are affine in the state, g(y) = c0 + c[0] y[0] + ... + c[n-1] y[n-1] (evaluated left to right,
 * skipping zero coefficients), kept in the struct.  Affine events let the solver bound g on a step's dense
 * output (Bernstein coefficients of a degree-7 polynomial), so an excursion across g = 0 and back inside one
 * step is found, not only a sign change at step ends (docs/events.md states the guarantee).
 *   - terminal events (pull-in): the run stops at the first t where g <= 0;
 *   - other events (contact): each step is cut at the first zero; afterwards the state lies on the new side
 *     (g > 0 or g <= 0: side[i]), moved there by at most the step's error if the cut step ends a rounding
 *     short, and side[i] flips.
 *
 * Use:
 *   Dop853 s = {0};  s.n = 2; s.rtol = ...; s.atol = ...; s.max_step = INFINITY; s.step_budget = INFINITY;
 *   s.n_events = 1; s.events[0] = (DopEvent){.c0 = 1.0, .c = {2.0 / 3.0}, .terminal = 0};
 *   dop_restart(&s, rhs, ctx, t0, y0, &report);    -- also after an input the rhs reads changed
 *   dop_advance(&s, rhs, ctx, t_end, &report);     -- steps until s.t >= t_end (maybe beyond)
 *   dop_value_at(&s, rhs, ctx, t, y, &report);     -- y at t in [t_old, t] (dense output, built lazily)
 * The first step's size is chosen on the first advance (s.h <= 0: not chosen yet).
 */
#ifndef VIBRO_DOP853_H
#define VIBRO_DOP853_H

#include <stddef.h>
#include <stdint.h>

#define DOP_MAX_DIM 16
#define DOP_MAX_EVENTS 4
#define DOP_STAGES 16    /* 12 stages + FSAL + 3 dense-output stages */
#define DOP_DENSE 7      /* dense-output coefficients per component */
#define DOP_MESSAGE 480

/* Return codes */
enum {
    DOP_OK = 0,
    DOP_TERMINAL = 5,  /* a terminal event was reached at or before the target: report->event, t, y */
    DOP_FAILED = 6,    /* step size collapsed, step budget spent, a cut step failed: message */
    DOP_RAISED = 7     /* where the Python twin raises an exception nothing catches: "<type>: <text>" */
};

/* The right-hand side f = y'(t, y).  Returns 0, or a fault (pyfloat.h: FAULT_ZERO_DIVISION, FAULT_MATH_DOMAIN,
   FAULT_OVERFLOW) where the Python model raises.  A fault inside a step's stages fails that step (smaller step);
   anywhere else the call returns DOP_RAISED with the fault's Python text. */
typedef int (*DopRhs)(void *context, double t, const double *y, double *f);

typedef struct {
    double c0;
    double c[DOP_MAX_DIM];
    int64_t terminal;
} DopEvent;

typedef struct {
    /* ---- configuration (set by the caller before dop_restart) ---- */
    int64_t n, n_events;
    double rtol, atol, max_step, step_budget;  /* step_budget: most steps one dop_advance may take */
    DopEvent events[DOP_MAX_EVENTS];
    /* ---- state ---- */
    double t, h;                               /* h <= 0: first step not chosen yet */
    double err_old;                            /* the last accepted step's error norm (PI controller; 0: none) */
    double y[DOP_MAX_DIM], f[DOP_MAX_DIM];
    double t_old, y_old[DOP_MAX_DIM], f_old[DOP_MAX_DIM];  /* the last step, valid when has_old */
    double k[DOP_STAGES][DOP_MAX_DIM];         /* the last step's stages: k[stage][component], n_stages */
    double dense[DOP_DENSE][DOP_MAX_DIM];      /* its dense output, dense[coefficient][component], valid when
                                                  dense_ready */
    double stop_t, stop_y[DOP_MAX_DIM];        /* the terminal event reached (stopped = its index + 1) */
    int64_t has_old, n_stages, dense_ready, stopped;
    int64_t side[DOP_MAX_EVENTS];              /* non-terminal events: 1 while g > 0 */
    int64_t nfev, n_steps;
} Dop853;

/* What went wrong (a return code other than DOP_OK): where, and the message (Python's text). */
typedef struct {
    double t;
    double y[DOP_MAX_DIM];
    int64_t event;                             /* DOP_TERMINAL: the event's index */
    char message[DOP_MESSAGE];
} DopReport;

/* Start afresh at (t, y): derivative, sides of the non-terminal events; no dense output, no stop. */
/* Leave code with (t, y[0..n-1]) and the formatted message in the report (the solvers' one way to fail). */
int dop_report(DopReport *r, int n, int code, double t, const double *y, const char *format, ...);

int dop_restart(Dop853 *s, DopRhs rhs, void *context, double t, const double *y, DopReport *report);
/* Step until s->t >= t_target.  DOP_TERMINAL if a terminal event lies at or before t_target. */
int dop_advance(Dop853 *s, DopRhs rhs, void *context, double t_target, DopReport *report);
/* y at t in [t_old, t] of the last step (t == s->t: the state itself); DOP_RAISED (ValueError) outside. */
int dop_value_at(Dop853 *s, DopRhs rhs, void *context, double t, double *y, DopReport *report);
/* g of event i at y */
double dop_event_g(const Dop853 *s, int i, const double *y);

#endif
