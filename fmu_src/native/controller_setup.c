/* controller_setup.c -- see controller_setup.h. */
#include <math.h>
#include <string.h>

#include "controller_setup.h"
#include "rules.h"
#include "series.h"

static const fmi2ValueReference ESTIMATE_START_VRS[VC_N] = {
    VR_mu_hat_start, VR_a1_hat_start, VR_a2_hat_start, VR_a3_hat_start, VR_a4_hat_start, VR_a5_hat_start,
    VR_Delta_hat_start, VR_beta_hat_start, VR_gamma_hat_start};
static const fmi2ValueReference GAIN_VRS[11] = {VR_lambda1, VR_lambda2, VR_lambda3, VR_lambda4, VR_lambda5,
                                                VR_lambda6, VR_lambda7, VR_lambda8, VR_lambda9, VR_lambda10,
                                                VR_lambda11};

void native_controller_constants(VcController *c, const State *s)
{
    memset(c, 0, sizeof *c);
    const double mu = s->value[VR_mu], Delta = s->value[VR_Delta], omega = s->value[VR_omega],
                 Omega = s->value[VR_Omega], alpha = s->value[VR_alpha], beta = s->value[VR_beta],
                 gamma = s->value[VR_gamma], R = s->value[VR_R];
    double poly[6], g1[6], g2[6];
    vibro_series(0, alpha, gamma, R, poly, g1, g2, c->g3);  /* forces.coefficients, series_g3 */
    const double theta[VC_N] = {mu, poly[1], poly[2], poly[3], poly[4], poly[5], Delta, beta, gamma};
    memcpy(c->theta, theta, sizeof theta);                /* control.true_theta */
    c->phi.w_delta = omega; c->phi.delta_sign = 1.0; c->phi.w_beta = Omega; c->phi.w_gamma = 2.0 * Omega;
    const int law = (int)s->value[VR_law];
    if (law == 2) { /* Eq. 81 as printed: -cos tau for Delta^, cos Omega tau for gamma^ */
        c->phi_update.w_delta = 1.0; c->phi_update.delta_sign = -1.0;
        c->phi_update.w_beta = Omega; c->phi_update.w_gamma = Omega;
    } else {
        c->phi_update = c->phi;
    }
    c->l1 = s->value[VR_lambda1];
    c->l2 = s->value[VR_lambda2];
    for (int i = 0; i < VC_N; i++) {
        c->Lambda[i] = s->value[GAIN_VRS[i + 2]];
        c->adaptation[i] = c->l2 / c->Lambda[i];          /* lambda2 Lambda^-1 */
    }
    c->c = sqrt(c->l1 / c->l2);                           /* Eq. 84 */
    c->k_damping = s->value[VR_k_damping];
    c->promised_e1 = -pow(c->l1, 1.5) / sqrt(c->l2);      /* Eq. 85 */
    c->true_delta = Delta;
    c->law = law;
    c->time_tolerance = RULE_TIME_TOLERANCE;
    c->t = s->start_time;
    for (int i = 0; i < VC_N; i++) c->theta_hat[i] = s->value[ESTIMATE_START_VRS[i]];
    c->enabled = 1;
}
