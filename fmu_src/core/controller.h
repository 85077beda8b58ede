/*
 * controller.h -- the adaptive Lyapunov tracking controller (vibromodel/control.py), compiled.
 *
 * Plant (Eq. 73): x1' = x2, x2' = phi^T theta + U, theta = (mu, a1..a5, Delta, beta, gamma), regressor
 * phi = (-x2, -x1, -x1^2, ..., -x1^5, cos w t, G3(x1) sin W t, 1 - G3(x1) cos 2W t) (corrected, not Eq. 81).
 * Errors (Eq. 74): e1 = x1 - x~, e2 = x2 - x~' + c e1, c = sqrt(lambda1/lambda2) (Eq. 84).
 * Lyapunov function (Eq. 76 with the gamma term): V = (lambda1 e1^2 + lambda2 e2^2 + sum Lambda_i theta~_i^2)/2.
 * Control (Eq. 78 corrected): U = -phi^T theta^ + x~'' - c e2 (- k e2 for the damped law).
 * Update law (Eq. 81 corrected): theta^' = lambda2 Lambda^-1 phi e2, so that V' = -lambda1^(3/2) lambda2^(-1/2)
 * e1^2 (Eq. 85), or -lambda1 c e1^2 - lambda2 k e2^2 for the damped law.
 * The paper-literal law (Eqs 78, 81 as printed) uses the true Delta in U and its own update regressor.
 *
 * The same operations in the same order as control.py (sums left to right from 0), so that both give the same
 * bits. Every constant (true theta, gains, frequencies) is computed once, by vk_controller_constants (below) from the
 * parameters, a0..a5 and G3, and stored here. VcController holds no pointers: its bytes are the controller FMU's
 * model state.
 */
#ifndef VIBRO_CONTROLLER_H
#define VIBRO_CONTROLLER_H

#include <stddef.h>
#include <stdint.h>

#define VC_N 9           /* estimates theta^ */
#define VC_INPUTS 5      /* x, v, x_ref, v_ref, a_ref */
#define VC_OUTPUTS 13    /* U, e1, e2, V, theta^[9] */

enum {
    VC_OK = 0,
    VC_BAD_STEP = 1,     /* communicationStepSize not finite or <= 0 (nothing changed) */
    VC_BAD_INPUT = 2,    /* an input is not finite (nothing changed) */
    VC_BAD_TIME = 4,     /* currentCommunicationPoint is not the controller's time (nothing changed) */
    VC_RAISED = 7        /* a trigonometric function of an infinite argument (Python: ValueError; nothing changed) */,
    VC_NON_FINITE = 8    /* an output would not be finite (Python: NonFiniteOutput; nothing changed) */
};

/* The regressor's time functions: cos(w_delta t) * delta_sign, sin(w_beta t), cos(w_gamma t) (control.Regressor). */
typedef struct {
    double w_delta, delta_sign, w_beta, w_gamma;
} VcRegressor;

typedef struct {
    /* ---- constants (control.Controller) ---- */
    double g3[6];                    /* series G3 of docs/model.md, Series and polynomial model */
    VcRegressor phi, phi_update;     /* the control's regressor and the update law's */
    double theta[VC_N];              /* true theta (for V) */
    double l1, l2, Lambda[VC_N], adaptation[VC_N], c, k_damping;
    double promised_e1;              /* -lambda1^(3/2) / sqrt(lambda2), Eq. 85 */
    double true_delta;               /* paper-literal: Delta used in U */
    int64_t law;                     /* 0 paper-corrected, 1 damped, 2 paper-literal */
    double time_tolerance;
    /* ---- state (HeldInputEstimator) ---- */
    double t, theta_hat[VC_N];
    /* ---- the FMU's inputs, held over a step, and outputs ---- */
    double in[VC_INPUTS];            /* x, v, x_ref, v_ref, a_ref */
    double out[VC_OUTPUTS];          /* U, e1, e2, V, theta^ */
    int64_t enabled;                 /* the FMU's C fast path may step this controller */
} VcController;

#define VC_GAINS 11      /* lambda1 .. lambda11 */

/* The constants of control.Controller into c (g3 .. time_tolerance; the state, inputs and outputs untouched): the
   one C derivation of them, used by the native FMUs (native/controller_setup.c) and by the pythonfmu FMUs'
   compiled models (vibromodel/compiled_loop.fill_controller). poly = a0..a5 (forces.coefficients, corrected),
   g3 = series G3 (forces.series_g3), law 0/1/2 (control.Law), lambdas = lambda1..lambda11 (control.Gains). The
   same operations as control.Controller, so the same bits (tests/core/test_controller_constants.py). */
void vk_controller_constants(VcController *c, double mu, double Delta, double omega, double Omega, double beta, double gamma,
                  const double *poly, const double *g3, int64_t law, const double *lambdas, double k_damping,
                  double time_tolerance);

/* sizeof(VcController) and its fields' offsets in declaration order (0 if n_fields is not their number). */
size_t vk_controller_layout(size_t *offsets, size_t n_fields);

/* e1, e2 of Eq. 74; ref = (x~, x~', x~''). */
void vk_controller_errors(const VcController *c, double x, double v, const double *ref, double *e1, double *e2);
/* U (Controller.control); 0 or VC_RAISED. */
int vk_controller_control(const VcController *c, double t, double x, double v, const double *ref, const double *theta_hat,
               double *U);
/* theta^' (Controller.rates); 0 or VC_RAISED. */
int vk_controller_rates(const VcController *c, double t, double x, double v, const double *ref, double *rates);
/* vk_controller_control and vk_controller_rates in one call (the regressor evaluated once where the laws share it); time != NULL: the
   control regressor's time functions cos(omega t), sin(Omega t), cos(2 Omega t) into time[0..2]; cos_delta != NULL:
   the control regressor's cos(w_delta t), already computed by the caller from the same angle. 0 or VC_RAISED. */
int vk_controller_control_rates(const VcController *c, double t, double x, double v, const double *ref, const double *theta_hat,
                     double *U, double *rates, double *time, const double *cos_delta);
/* theta^(t + h) - theta^(t) with x, v, ref held (Controller.increment, exact integral); 0 or VC_RAISED. */
int vk_controller_increment(const VcController *c, double t, double h, double x, double v, const double *ref, double *inc);
/* V of Eq. 76. */
double vk_controller_lyapunov(const VcController *c, double e1, double e2, const double *theta_hat);
/* dV/dt by the chain rule (Controller.lyapunov_rate). */
double vk_controller_lyapunov_rate(const VcController *c, double x, double v, double accel, const double *ref,
                        const double *theta_hat, const double *theta_hat_rate);
/* The V' the law promises (Controller.promised_rate). */
double vk_controller_promised_rate(const VcController *c, double e1, double e2);

/* The controller FMU's outputs U, e1, e2, V, theta^ at t with estimates theta_hat and the inputs in[] into out[]
   (AdaptiveLyapunovController._publish); 0 or VC_RAISED. */
int vk_controller_outputs(const VcController *c, double t, const double *theta_hat, double *out);
/* Index of the first non-finite of out[0..VC_OUTPUTS-1], or -1. */
int vk_controller_non_finite(const double *out);
/* The controller FMU: out[] from the inputs and estimates at t (AdaptiveLyapunovController._publish), written only
   when all are finite; 0, VC_RAISED or VC_NON_FINITE (nothing written). */
int vk_controller_publish(VcController *c);
/* HeldInputEstimator.advance: theta^ += the exact increment with x, v, ref held, t = t + h; 0 or VC_RAISED
   (nothing changed). */
int vk_controller_advance(VcController *c, double t, double h, double x, double v, const double *ref);
/* One doStep: pre-checks, theta^ += the exact increment with the inputs held, t += h, publish. 0 or a code
   (VC_NON_FINITE: an output would not be finite; nothing changed). */
int vk_controller_do_step(VcController *c, double t, double h);

#endif
