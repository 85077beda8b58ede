/* controller_setup.c -- see controller_setup.h. */
#include <string.h>

#include "controller_setup.h"
#include "rules.h"
#include "series.h"

static const fmi2ValueReference ESTIMATE_START_VRS[VC_N] = {
    VR_mu_hat_start, VR_a1_hat_start, VR_a2_hat_start, VR_a3_hat_start, VR_a4_hat_start, VR_a5_hat_start,
    VR_Delta_hat_start, VR_beta_hat_start, VR_gamma_hat_start};
static const fmi2ValueReference GAIN_VRS[VC_GAINS] = {VR_lambda1, VR_lambda2, VR_lambda3, VR_lambda4, VR_lambda5,
                                                      VR_lambda6, VR_lambda7, VR_lambda8, VR_lambda9, VR_lambda10,
                                                      VR_lambda11};

void native_controller_constants(VcController *c, const State *s)
{
    memset(c, 0, sizeof *c);
    const double alpha = s->value[VR_alpha], gamma = s->value[VR_gamma], R = s->value[VR_R];
    double poly[6], g1[6], g2[6], g3[6], lambdas[VC_GAINS];
    vibro_series(0, alpha, gamma, R, poly, g1, g2, g3);  /* forces.coefficients, series_g3 */
    for (int i = 0; i < VC_GAINS; i++) lambdas[i] = s->value[GAIN_VRS[i]];
    vk_controller_constants(c, s->value[VR_mu], s->value[VR_Delta], s->value[VR_omega], s->value[VR_Omega], s->value[VR_beta],
                 gamma, poly, g3, (int64_t)s->value[VR_law], lambdas, s->value[VR_k_damping], RULE_TIME_TOLERANCE);
    c->t = s->start_time;
    for (int i = 0; i < VC_N; i++) c->theta_hat[i] = s->value[ESTIMATE_START_VRS[i]];
    c->enabled = 1;
}
