/*
 * periodmap.h -- the n-period map of the shooting formulation (harness/vibrofmu/analyses/shooting.py) in C: the
 * state of x'' + mu x' + g(x) = Delta cos(omega tau), g(x) = H(x) - 1 - F_em,mean(x) (Eq. 3 with the AC drive at its
 * mean), in rescaled time s = omega tau, integrated together with its fundamental matrix Phi and its sensitivity
 * to one parameter, by the core's DOP853 (dop853.h) at the caller's rtol and atol:
 *     y = (x, v, Phi11, Phi21, Phi12, Phi22, x_p, v_p),
 *     x' = v / omega,  v' = (Delta cos s - mu v - g(x)) / omega,
 *     Phi' = J Phi,  z_p' = J z_p + df/dp,  J = [[0, 1/omega], [-g'(x)/omega, -mu/omega]],
 * operation for operation shooting.variational_rhs (the scipy twin the Python period map integrates).
 *
 * Events (affine in the state, dop853.h): contact 1 + 2x/3 = 0 (the step is cut there: H'' is singular at the
 * contact edge, H and H' are continuous, so Phi needs no saltation), the turning points v = 0 (cut there: x at
 * each is an extremum of the orbit), and the electrode gaps 1 -+ 2x/(3R) = PULL_IN_GAP (terminal: pull-in).
 * The last step is clipped to end at s = 2 pi periods exactly (no interpolation of the end state).
 */
#ifndef VIBRO_PERIODMAP_H
#define VIBRO_PERIODMAP_H

#include <stdint.h>

/* the parameter of the sensitivity z_p: shooting.PARAMETERS' order */
enum { PM_OMEGA = 0, PM_DELTA = 1, PM_MU = 2, PM_ALPHA = 3, PM_GAMMA = 4 };
/* return codes */
enum { PM_OK = 0, PM_PULL_IN = 1, PM_FAILED = 2, PM_BAD_ARGUMENT = 3 };
/* extrema kept at most (turning points; more are counted into the extremes only) */
#define PM_MAX_EXTREMA 4096

/*
 * scene: mu, Delta, omega, alpha, gamma, R, rtol, atol, pull_in_gap (9 doubles);
 * z0: (x0, v0); out: end x, end v, Phi11, Phi21, Phi12, Phi22, x_p, v_p, x_min, x_max (10 doubles; x_min/x_max over
 * the turning points and both ends), counts: contact crossings, turning points, accepted steps (3 int64);
 * message: on PM_FAILED / PM_PULL_IN, what happened (size bytes).
 */
int vk_period_map(const double *scene, int64_t param, int64_t periods, const double *z0, double *out,
                  int64_t *counts, char *message, int64_t size);

#endif
