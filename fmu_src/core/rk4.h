/*
 * rk4.h -- classic fixed-step Runge-Kutta 4 on a state y[0..n-1] (n <= DOP_MAX_DIM), the C twin of
 * vibromodel/integrate.py's Rk4: each advance splits [t, t_target] into equal steps no longer than max_step,
 * refuses a step size outside RK4's stability region on the local linearisation of (y[0], y[1]) = (x, v), and
 * stops at a terminal event located on each step's cubic Hermite interpolant of y[0] (excursions that begin and
 * end inside a step included).  Events: DopEvent of dop853.h, only terminal ones are checked; g's affine form
 * may involve y[0] only.  Pointer-free struct; the right-hand side (DopRhs) is passed to each call.
 */
#ifndef VIBRO_RK4_H
#define VIBRO_RK4_H

#include "dop853.h"

typedef struct {
    /* ---- configuration ---- */
    int64_t n, n_events;
    double max_step;
    DopEvent events[DOP_MAX_EVENTS];
    /* ---- state ---- */
    double t, y[DOP_MAX_DIM];
    int64_t nfev, n_steps;
} Rk4;

/* Integrate to exactly t_target (nothing if t_target <= t).  DOP_TERMINAL (report->event, t, y: the located
   event), DOP_FAILED (unstable step size, non-finite state, a stage outside the model's domain). */
int rk4_advance(Rk4 *s, DopRhs rhs, void *context, double t_target, DopReport *report);

/* A right-hand side that takes the drive's phasors at t: phases[2k], phases[2k+1] = cos, sin of freq[k] t */
typedef int (*Rk4PhasedRhs)(void *context, double t, const double *phases, const double *y, double *f);
#define RK4_MAX_PHASES 3
/* Steps between two direct evaluations of the phasors (integrate.PHASE_RESYNC) */
#define RK4_PHASE_RESYNC 16
/* rk4_advance for a right-hand side whose time dependence is cos and sin of freq[0..n_freq-1] t (the twin of
   integrate.Rk4 with `phased`): the phasors are evaluated directly (cos, sin of freq[k] t) at the advance's
   start (also for the stability check) and every RK4_PHASE_RESYNC steps; in between, each stage's from the
   previous by one rotation through freq[k] h/2 (its cos and sin once per advance).  Stages 2 and 3 share
   t + h/2. */
int rk4_advance_phased(Rk4 *s, Rk4PhasedRhs rhs, void *context, int n_freq, const double *freq, double t_target,
                       DopReport *report);

/* Rk4._require_current: y[0..n-1] if t is the solver's time, else DOP_RAISED (ValueError) */
int rk4_value_at(const Rk4 *s, double t, double *y, DopReport *report);

/* Rk4._finish's event check of one fixed step from (t, y) over h to y_new, for any fixed-step solver: the first
   terminal event reached on the step's cubic Hermite interpolant of y[0] (integrate._hermite_event: roots.c's
   search, then brentq): DOP_TERMINAL with report->event, t and y there; DOP_OK if none; DOP_RAISED where Python's
   brentq raises.  Only the events' y[0] coefficient is read. */
int rk4_step_events(int n, int n_events, const DopEvent *events, double t, const double *y, double h,
                    const double *y_new, DopReport *report);

/* integrate.rk4_drive_gains(theta)[0]: G_x, RK4's ripple of x under a drive e^(i nu t) over the true one (theta =
   nu h), the same operations (the settings' drive warnings of the native FMUs read it; tests/core/test_plant_kernel.py
   compares the bits) */
double vk_rk4_drive_gain_x(double theta);

#endif
